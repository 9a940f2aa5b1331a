// The transfer view: a library clip moved onto another skeleton, the source and the result
// playing side by side in step.

import { getJson, getText, postForm, query, showError } from './api.js';
import { element, onSubmit } from './dom.js';
import { skeletonPicker } from './skeletons.js';
import { Viewer } from './viewer.js';

const option = (value, text) => element('option', { value: String(value) }, text);

const clipLabel = (c) => `${c.caption ?? c.captions?.[0] ?? c.path} · ${c.subject} · clip ${c.id}`;

/** Wires the transfer form to `/v1/transfer`; returns how to preselect a clip. */
export function setUpTransfer(skeletons) {
  const form = document.getElementById('transfer-form');
  const error = form.querySelector('.error');
  const status = form.querySelector('.status');
  const clipSelect = document.getElementById('transfer-clip');
  const find = document.getElementById('transfer-find');
  const results = document.getElementById('transfer-results');
  const picker = skeletonPicker(document.getElementById('transfer-skeleton'), skeletons, 'transfer');
  let viewers = [];
  let loaded = false;

  function fill(clips) {
    clipSelect.replaceChildren(...clips.map((c) => option(c.id, clipLabel(c))));
  }

  async function findClips() {
    showError(error, null);
    const q = find.value.trim();
    try {
      if (q) fill((await getJson(`/v1/search${query({ q, limit: 30 })}`)).hits);
      else fill(await getJson('/v1/clips?limit=50'));
      status.textContent = `${clipSelect.options.length} clips to choose from.`;
    } catch (e) {
      showError(error, e);
    }
  }

  document.getElementById('transfer-find-button').addEventListener('click', findClips);
  find.addEventListener('keydown', (e) => {
    if (e.key === 'Enter') {
      e.preventDefault();
      findClips();
    }
  });

  onSubmit(form, {
    busy: 'Transferring…',
    build() {
      const body = new FormData();
      if (!clipSelect.value) throw new Error('Choose the clip to move: find one above.');
      body.append('clip_id', clipSelect.value);
      body.append('cleanup', form.cleanup.checked ? 'true' : 'false');
      picker.addTo(body);
      return body;
    },
    async send(body) {
      const clipId = body.get('clip_id');
      const [answer, source] = await Promise.all([postForm('/v1/transfer', body), getText(`/v1/clips/${clipId}/bvh`)]);
      for (const v of viewers) v.remove();
      const target = picker.label();
      const [result] = answer;
      viewers = [
        new Viewer(results, source, { title: `Clip ${clipId} (source)`, download: `/v1/clips/${clipId}/bvh`, filename: `clip-${clipId}.bvh` }),
        new Viewer(results, result.bvh, {
          title: `Clip ${clipId} on ${target}`, download: result.url, filename: `anymo-transfer-${result.generation_id}.bvh`,
          quality: result.quality,
        }),
      ];
      for (const v of viewers) v.restart();
      return `Moved clip ${clipId} onto ${target}: ${result.frames} frames (result ${result.generation_id}).`;
    },
  });

  return {
    /** Fills the clip list once, when the view is first opened. */
    open() {
      if (!loaded) {
        loaded = true;
        if (!clipSelect.options.length) findClips();
      }
    },
    /** Preselects a clip (from the library). */
    choose(clip) {
      if (![...clipSelect.options].some((o) => o.value === String(clip.id))) {
        clipSelect.prepend(option(clip.id, clipLabel(clip)));
      }
      clipSelect.value = String(clip.id);
      loaded = true;
    },
  };
}
