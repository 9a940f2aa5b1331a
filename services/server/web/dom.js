// Small helpers for building the page's elements and running its forms.

import { showError } from './api.js';

/** A new element with attributes and, optionally, text. */
export function element(tag, attributes = {}, text) {
  const e = document.createElement(tag);
  for (const [k, v] of Object.entries(attributes)) e.setAttribute(k, v);
  if (text !== undefined) e.textContent = text;
  return e;
}

/**
 * Runs a form's submissions. `build` makes the request body; an Error it throws is shown in
 * the form and nothing is sent. `send` sends the body, shows the answer and returns the status
 * line; its errors (the API's own messages) are shown in the form too. While a request runs, the
 * submit button is disabled and the form is marked busy.
 */
export function onSubmit(form, { busy, build, send }) {
  const error = form.querySelector('.error');
  const status = form.querySelector('.status');
  const button = form.querySelector('button[type="submit"]');
  form.addEventListener('submit', async (event) => {
    event.preventDefault();
    showError(error, null);
    let body;
    try {
      body = build();
    } catch (e) {
      showError(error, e);
      return;
    }
    button.disabled = true;
    form.setAttribute('aria-busy', 'true');
    status.textContent = busy;
    try {
      status.textContent = await send(body);
    } catch (e) {
      status.textContent = '';
      showError(error, e);
    } finally {
      button.disabled = false;
      form.removeAttribute('aria-busy');
    }
  });
}
