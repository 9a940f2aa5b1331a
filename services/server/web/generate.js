// The generate view: a prompt, a skeleton, seconds / samples / seed and the cleanup; every sample
// plays with its quality report.

import { postForm } from './api.js';
import { onSubmit } from './dom.js';
import { skeletonPicker } from './skeletons.js';
import { Viewer } from './viewer.js';

/** Wires the generate form to `/v1/generate`, within the server's limits. */
export function setUpGenerate(skeletons, limits) {
  const form = document.getElementById('generate-form');
  const results = document.getElementById('generate-results');
  const seconds = document.getElementById('seconds');
  const samples = document.getElementById('samples');
  seconds.max = String(limits.seconds);
  samples.max = String(limits.samples);
  const picker = skeletonPicker(document.getElementById('generate-skeleton'), skeletons, 'generate');
  let viewers = [];

  onSubmit(form, {
    busy: 'Generating…',
    build() {
      const body = new FormData();
      const prompt = form.prompt.value.trim();
      if (!prompt) throw new Error('Write a prompt: what should the skeleton do?');
      body.append('prompt', prompt);
      for (const field of [seconds, samples, form.seed]) {
        if (field.value === '') continue;
        if (!field.checkValidity()) throw new Error(`${field.labels[0].textContent.trim()}: ${field.validationMessage}`);
        body.append(field.name, field.value);
      }
      body.append('cleanup', form.cleanup.checked ? 'true' : 'false');
      picker.addTo(body);
      return body;
    },
    async send(body) {
      const started = performance.now();
      const answer = await postForm('/v1/generate', body);
      for (const v of viewers) v.remove();
      const who = picker.label();
      viewers = answer.map((s) => new Viewer(results, s.bvh, {
        title: `Sample ${s.index + 1} on ${who}`,
        download: s.url,
        filename: `anymo-${s.generation_id}-${s.index + 1}.bvh`,
        quality: s.quality,
      }));
      const took = ((performance.now() - started) / 1000).toFixed(1);
      const [first] = answer;
      return `${answer.length} sample${answer.length === 1 ? '' : 's'} of ${first.frames} frames at ${first.fps} fps, `
        + `in ${took} s (result ${first.generation_id}).`;
    },
  });
}
