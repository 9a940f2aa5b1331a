// The library view: text search with filters, results that play on their own skeletons, a
// clip's captions, licence and skeleton tree, and "find similar" from any clip.

import { getJson, getText, query, showError } from './api.js';
import { element } from './dom.js';
import { Viewer, jointTree } from './viewer.js';

const PAGE = 12;


/** A caption with the matched spans marked (`highlights` are character ranges). */
function marked(caption, highlights) {
  const p = element('span', { class: 'caption' });
  const chars = Array.from(caption);
  let at = 0;
  for (const [start, end] of [...(highlights || [])].sort((a, b) => a[0] - b[0])) {
    if (start < at) continue;
    p.append(chars.slice(at, start).join(''), element('mark', {}, chars.slice(start, end).join('')));
    at = end;
  }
  p.append(chars.slice(at).join(''));
  return p;
}

function treeList(node) {
  const li = element('li', {}, node.name);
  if (node.children.length) {
    const ul = element('ul');
    for (const c of node.children) ul.append(treeList(c));
    li.append(ul);
  }
  return li;
}

/** A search hit or a listed clip, as one shape. */
function entry(c) {
  return {
    id: c.id,
    caption: c.caption ?? c.captions?.[0] ?? c.path,
    highlights: c.highlights,
    subject: c.subject,
    source: c.source,
    licence: c.licence,
    seconds: c.seconds,
  };
}

/** Wires the library view; returns what other views call (to open a clip). */
export function setUpLibrary(stats, onTransfer) {
  const form = document.getElementById('search-form');
  const formError = form.querySelector('.error');
  const list = document.getElementById('results');
  const title = document.getElementById('results-title');
  const status = document.getElementById('results-status');
  const more = document.getElementById('more-results');
  const detail = document.getElementById('clip-detail');
  const detailError = detail.querySelector('.error');
  const filters = { licence: 'filter-licence', subject: 'filter-subject', source: 'filter-source' };
  for (const [group, id] of Object.entries(filters)) {
    const select = document.getElementById(id);
    for (const [g, name, clips] of stats.groups) {
      if (g === group) select.append(element('option', { value: name }, `${name} (${clips})`));
    }
  }
  let current = null;
  let previews = [];
  let detailViewer = null;
  let shown = null;

  const filterValues = () => Object.fromEntries(Object.keys(filters).map((k) => [k, form[k].value]));

  async function run(search, append) {
    showError(formError, null);
    if (!append) {
      for (const v of previews) v.remove();
      previews = [];
      list.replaceChildren();
    }
    status.textContent = 'Searching…';
    more.hidden = true;
    try {
      let items;
      let total = null;
      if (search.q || search.like_clip) {
        const page = await getJson(`/v1/search${query({ ...search.params, limit: PAGE, offset: search.offset })}`);
        items = page.hits.map(entry);
        total = page.candidates;
      } else {
        const page = await getJson(`/v1/clips${query({ after: search.after, limit: PAGE })}`);
        items = page.map(entry);
        if (page.length) search.after = page[page.length - 1].id;
      }
      search.offset += items.length;
      title.textContent = search.heading;
      for (const item of items) list.append(card(item));
      const count = list.children.length;
      const filtered = total === null && Object.values(filterValues()).some(Boolean);
      status.textContent = count
        ? `${count} clip${count === 1 ? '' : 's'} shown${total === null ? '' : ` of ${total} found`}.`
          + (filtered ? ' The filters apply to a search: describe the motion above.' : '')
        : 'No clip matches. Try other words or fewer filters.';
      more.hidden = items.length < PAGE || (total !== null && search.offset >= total);
    } catch (e) {
      status.textContent = '';
      showError(formError, e);
    }
  }

  function start(search) {
    current = { offset: 0, ...search, params: { q: search.q, like_clip: search.like_clip, ...filterValues() } };
    run(current, false);
  }

  function card(item) {
    const li = element('li', { class: 'hit', 'data-clip': String(item.id) });
    const heading = element('h4');
    heading.append(marked(item.caption, item.highlights));
    const facts = element('p', { class: 'meta' },
      `${item.subject} · ${item.source} · ${item.licence} · ${item.seconds.toFixed(1)} s · clip ${item.id}`);
    const stage = element('div', { class: 'preview' });
    const actions = element('div', { class: 'actions' });
    const play = element('button', { type: 'button', class: 'preview-button' }, 'Play preview');
    const open = element('button', { type: 'button', class: 'details-button' }, 'Details');
    const similar = element('button', { type: 'button' }, 'Find similar');
    play.addEventListener('click', async () => {
      play.disabled = true;
      try {
        const text = await getText(`/v1/clips/${item.id}/bvh`);
        const viewer = new Viewer(stage, text, { title: `Clip ${item.id}`, download: `/v1/clips/${item.id}/bvh`, filename: `clip-${item.id}.bvh` });
        previews.push(viewer);
        play.remove();
        viewer.focus();
      } catch (e) {
        play.disabled = false;
        stage.replaceChildren(element('p', { class: 'error', role: 'alert' }, e.message));
      }
    });
    open.addEventListener('click', () => openClip(item.id));
    similar.addEventListener('click', () => findSimilar(item.id));
    actions.append(play, open, similar);
    li.append(heading, facts, stage, actions);
    return li;
  }

  function findSimilar(id) {
    form.q.value = '';
    start({ like_clip: id, heading: `Clips like clip ${id}` });
  }

  async function openClip(id) {
    showError(detailError, null);
    detail.hidden = false;
    const heading = document.getElementById('detail-title');
    heading.textContent = `Clip ${id}`;
    try {
      const [clip, text] = await Promise.all([getJson(`/v1/clips/${id}`), getText(`/v1/clips/${id}/bvh`)]);
      shown = clip;
      detailViewer?.remove();
      detailViewer = new Viewer(detail.querySelector('.detail-viewer'), text, {
        title: `Clip ${id}`, download: clip.bvh_url, filename: `clip-${id}.bvh`,
      });
      heading.textContent = `Clip ${id}: ${clip.captions[0] ?? clip.path}`;
      const facts = detail.querySelector('.facts');
      facts.replaceChildren();
      for (const [k, v] of [
        ['Licence', clip.licence], ['Source', clip.source], ['Subject', clip.subject], ['File', clip.path],
        ['Length', `${clip.frames} frames at ${Number(clip.fps.toFixed(2))} fps (${clip.seconds.toFixed(2)} s)`], ['Split', clip.split],
        ['Skeleton', `#${clip.skeleton_id}`],
      ]) facts.append(element('dt', {}, k), element('dd', {}, v));
      const captions = detail.querySelector('.captions');
      captions.replaceChildren(...clip.captions.map((c) => element('li', {}, c)));
      if (!clip.captions.length) captions.append(element('li', {}, 'No captions.'));
      detail.querySelector('.tree').replaceChildren(treeList(jointTree(detailViewer.motion.root)));
      heading.focus();
    } catch (e) {
      showError(detailError, e);
    }
  }

  detail.querySelector('.find-similar').addEventListener('click', () => shown && findSimilar(shown.id));
  detail.querySelector('.to-transfer').addEventListener('click', () => shown && onTransfer(shown));
  more.addEventListener('click', () => current && run(current, true));
  form.addEventListener('submit', (event) => {
    event.preventDefault();
    const q = form.q.value.trim();
    if (!q) {
      start({ heading: 'Clips' });
      return;
    }
    start({ q, heading: `Clips for “${q}”` });
  });
  for (const id of Object.values(filters)) {
    document.getElementById(id).addEventListener('change', () => form.requestSubmit());
  }
  return {
    /** Shows the first clips, once, when the view is first opened. */
    browse() {
      if (!current) start({ heading: 'Clips' });
    },
  };
}
