// The anymo REST API as the page uses it. Every failure becomes an ApiError whose message is the
// server's own (it says what to change), so views can show it where the user acted.

const KEY = 'anymo.apiKey';

/** A refused or failed request, with the server's error code and message. */
export class ApiError extends Error {
  constructor(status, code, message) {
    super(message);
    this.status = status;
    this.code = code;
  }
}

/** The API key sent with every request (kept for this tab only), or ''. */
export function apiKey() {
  return sessionStorage.getItem(KEY) || '';
}

/** Sets (or, with '', forgets) the API key. */
export function setApiKey(key) {
  if (key) sessionStorage.setItem(KEY, key);
  else sessionStorage.removeItem(KEY);
}

async function request(path, { method = 'GET', body, json = true } = {}) {
  const headers = { Accept: json ? 'application/json' : 'text/plain, */*' };
  const key = apiKey();
  if (key) headers['X-Api-Key'] = key;
  let response;
  try {
    response = await fetch(path, { method, body, headers });
  } catch (e) {
    throw new ApiError(0, 'network', `The server could not be reached (${e.message}). Is anymo serve still running?`);
  }
  if (!response.ok) {
    let code = 'http';
    let message = `The server answered ${response.status} ${response.statusText}.`;
    try {
      const answer = await response.json();
      if (answer && answer.error) ({ code, message } = answer.error);
    } catch {
      // Not a JSON error body: the status line is all there is to say.
    }
    const retry = response.headers.get('Retry-After');
    if (retry) message += ` Try again in ${retry} s.`;
    throw new ApiError(response.status, code, message);
  }
  return json ? response.json() : response.text();
}

/** GET a JSON document. */
export const getJson = (path) => request(path);

/** GET a text document (a BVH). */
export const getText = (path) => request(path, { json: false });

/** POST a multipart form and read the JSON answer. */
export const postForm = (path, form) => request(path, { method: 'POST', body: form });

/** A query string from the fields that are set. */
export function query(params) {
  const q = new URLSearchParams();
  for (const [k, v] of Object.entries(params)) {
    if (v !== undefined && v !== null && v !== '') q.set(k, String(v));
  }
  const s = q.toString();
  return s ? `?${s}` : '';
}

/** Shows an error in the element given (or hides it with null). */
export function showError(element, error) {
  if (!element) return;
  element.hidden = !error;
  element.textContent = error ? error.message : '';
}
