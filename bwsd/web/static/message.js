// @ts-check
// The message line of the Control panel: what the daemon answered or refused, or why
// nothing was sent. A success fades after a while, an error stays.

import { byId } from './dom.js';

/** @type {ReturnType<typeof setTimeout> | undefined} */
let timer;

/**
 * Show `text`; `kind`: 'ok', 'error', 'pending' or '' (plain).
 * @param {string} text
 * @param {string} kind
 */
export function say(text, kind) {
  const message = byId('message');
  message.textContent = text;
  message.dataset.kind = kind;
  clearTimeout(timer);
  if (kind === 'ok') timer = setTimeout(() => say('', ''), 8000);
}

/** True while the line says the daemon cannot be reached (cleared when it answers again). */
export function saysUnreachable() {
  const message = byId('message');
  return message.dataset.kind === 'error' && (message.textContent ?? '').includes('cannot be reached');
}

/**
 * What went wrong, in words: a thrown error's message, or what was thrown as text.
 * @param {unknown} error
 */
export function messageOf(error) {
  if (typeof error === 'object' && error !== null && 'message' in error) {
    const { message } = error;
    if (message !== undefined && message !== null) return String(message);
  }
  return String(error);
}
