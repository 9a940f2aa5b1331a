// The page: reads what the server offers (limits, skeletons, library facets), sets up the three
// views and switches between them by the address's #fragment, so links and Back work.

import { apiKey, getJson, setApiKey } from './api.js';
import { setUpGenerate } from './generate.js';
import { setUpLibrary } from './library.js';
import { setUpTransfer } from './transfer.js';

const VIEWS = ['generate', 'library', 'transfer'];

function setUpKey() {
  const form = document.getElementById('key-form');
  const input = document.getElementById('api-key');
  input.value = apiKey();
  form.addEventListener('submit', (event) => {
    event.preventDefault();
    setApiKey(input.value.trim());
    form.closest('details').open = false;
  });
}

function show(name, views, focus) {
  const view = VIEWS.includes(name) ? name : 'generate';
  for (const v of VIEWS) {
    document.getElementById(`view-${v}`).hidden = v !== view;
    const link = document.querySelector(`nav a[data-view="${v}"]`);
    if (v === view) link.setAttribute('aria-current', 'page');
    else link.removeAttribute('aria-current');
  }
  if (view === 'library') views.library.browse();
  if (view === 'transfer') views.transfer.open();
  if (focus) document.getElementById(`${view}-title`).focus();
}

async function main() {
  setUpKey();
  const status = document.getElementById('server-status');
  let health;
  let skeletons;
  let stats;
  try {
    [health, skeletons, stats] = await Promise.all([getJson('/v1/health'), getJson('/v1/skeletons'), getJson('/v1/stats')]);
  } catch (e) {
    status.classList.add('error');
    status.textContent = `The page could not start: ${e.message}`;
    return;
  }
  status.textContent = `anymo ${health.version} · ${health.clips} clips on ${skeletons.length} skeletons`;
  const views = {};
  views.transfer = setUpTransfer(skeletons);
  views.library = setUpLibrary(stats, (clip) => {
    views.transfer.choose(clip);
    window.location.hash = '#transfer';
  });
  setUpGenerate(skeletons, health.limits);
  const route = (focus) => show(window.location.hash.slice(1), views, focus);
  window.addEventListener('hashchange', () => route(true));
  route(false);
  document.body.dataset.ready = 'true';
}

main();
