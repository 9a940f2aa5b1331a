// A made motion's quality report, as a short list beside its player: what a user checks before
// using a take (feet that slide or float, shaking against real clips of the skeleton, how well
// it matches the prompt).

import { element } from './dom.js';

const fixed = (x, digits = 3) => Number(x).toFixed(digits);

/** The rows shown for a report: [label, value, data key] (figures the report lacks are left out). */
export function qualityRows(q) {
  const rows = [];
  if (q.text_similarity != null) rows.push(['Prompt match', fixed(q.text_similarity, 2), 'text_similarity']);
  if (q.jitter_ratio != null) {
    rows.push(['Jitter', `${fixed(q.jitter_ratio, 2)}× real ${q.real.subject} clips`, 'jitter_ratio']);
  } else {
    rows.push(['Jitter', `${fixed(q.jitter, 1)} diam/s²`, 'jitter']);
  }
  rows.push(['Largest step', `${fixed(q.max_step)} diam/frame`, 'max_step']);
  const real = q.real && q.real.body_height ? ` (real: ${fixed(q.real.body_height, 2)})` : '';
  rows.push(['Body height', `${fixed(q.body_height, 2)} diam${real}`, 'body_height']);
  if (q.foot_skating != null) rows.push(['Foot skating', `${fixed(q.foot_skating)} diam/s`, 'foot_skating']);
  if (q.foot_flight != null) rows.push(['Foot flight', `${fixed(q.foot_flight)} diam`, 'foot_flight']);
  rows.push(['Feet', q.feet ? `${q.feet}, ${q.cleaned_up ? `${Math.round(q.planted * 100)}% planted` : 'not cleaned up'}` : 'none found', 'feet']);
  return rows;
}

/** The report as a definition list (each value carries its figure in data-value). */
export function qualityList(q) {
  const list = element('dl', { class: 'quality', 'aria-label': 'Quality report' });
  for (const [label, text, key] of qualityRows(q)) {
    const value = element('dd', { 'data-key': key, 'data-value': String(q[key]) }, text);
    list.append(element('dt', {}, label), value);
  }
  return list;
}
