// Choosing a skeleton: one of the library's, or a BVH file of the user's own. Generation and
// transfer both ask for one the same way.

import { element } from './dom.js';

/** A readable name for a stored skeleton: what is on it, how many joints, how many clips. */
export function skeletonName(s) {
  const subjects = s.subjects.length ? s.subjects.join(', ') : 'no clips';
  const sources = s.sources.length ? ` (${s.sources.join(', ')})` : '';
  return `${subjects}${sources} · ${s.joints} joints · ${s.clips} clips · #${s.id}`;
}

/** Fills a fieldset with "stored" and "upload" choices; returns a reader of the choice. */
export function skeletonPicker(fieldset, skeletons, prefix) {
  fieldset.insertAdjacentHTML('beforeend', `
    <div class="choice">
      <input type="radio" id="${prefix}-stored" name="${prefix}-kind" value="stored" checked>
      <label for="${prefix}-stored">From the library</label>
      <select id="${prefix}-skeleton-id" aria-label="Stored skeleton"></select>
    </div>
    <div class="choice">
      <input type="radio" id="${prefix}-upload" name="${prefix}-kind" value="upload">
      <label for="${prefix}-upload">My own BVH file</label>
      <input type="file" id="${prefix}-skeleton-file" accept=".bvh,.gz,text/plain" aria-label="BVH file of the skeleton">
    </div>`);
  const select = fieldset.querySelector(`#${prefix}-skeleton-id`);
  const file = fieldset.querySelector(`#${prefix}-skeleton-file`);
  const upload = fieldset.querySelector(`#${prefix}-upload`);
  const stored = fieldset.querySelector(`#${prefix}-stored`);
  for (const s of skeletons) select.append(element('option', { value: String(s.id) }, skeletonName(s)));
  if (!skeletons.length) {
    stored.disabled = true;
    select.disabled = true;
    upload.checked = true;
  }
  file.addEventListener('change', () => { if (file.files.length) upload.checked = true; });
  select.addEventListener('change', () => { stored.checked = true; });

  return {
    /** Adds the chosen skeleton to a form (as `skeleton_id` or a `skeleton` file); throws a
     *  readable error when the choice is incomplete. */
    addTo(form) {
      if (upload.checked) {
        if (!file.files.length) throw new Error('Choose a BVH file for the skeleton, or pick one from the library.');
        form.append('skeleton', file.files[0], file.files[0].name);
      } else {
        if (!select.value) throw new Error('Pick a skeleton from the library, or upload a BVH file.');
        form.append('skeleton_id', select.value);
      }
    },
    /** What the choice is called, for titles. */
    label() {
      return upload.checked && file.files.length ? file.files[0].name : select.selectedOptions[0]?.textContent.split(' · ')[0] || '';
    },
  };
}
