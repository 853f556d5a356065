// @ts-check
// The question asked before Stop and Abort: a modal dialog the operator must confirm, with
// the reason that goes with the command. Cancel, Escape or closing it sends nothing.

import { byId as $ } from './dom.js';

/** @type {Record<string, {title: string, effect: string}>} */
const WORDS = {
  stop: {
    title: 'Stop the machine?',
    effect: 'The instruction in progress finishes, then the machine stops. The program ends here: it cannot be resumed, only loaded again.',
  },
  abort: {
    title: 'Abort?',
    effect: 'The machine stops at once (a quick stop). The program ends here: it cannot be resumed, only loaded again.',
  },
};

/**
 * Ask before `command` ("stop" or "abort"); `where` says what runs now. Resolves to
 * `{reason}` when confirmed, null when not. `reason` starts as the one given.
 * @param {string} command
 * @param {string} where
 * @param {string} reason
 * @returns {Promise<{reason: string} | null>}
 */
export function confirmCommand(command, where, reason) {
  const dialog = $('confirm', HTMLDialogElement);
  const reasonInput = $('confirm-reason', HTMLInputElement);
  const words = WORDS[command];
  $('confirm-title').textContent = words.title;
  $('confirm-text').textContent = `${where ? `${where}. ` : ''}${words.effect}`;
  reasonInput.value = reason;
  $('confirm-ok').textContent = command;
  dialog.dataset.command = command;
  dialog.returnValue = '';
  return new Promise((resolve) => {
    dialog.addEventListener('close', () => {
      resolve(dialog.returnValue === 'confirm' ? { reason: reasonInput.value.trim() } : null);
    }, { once: true });
    dialog.showModal();
  });
}

/** Close the question unanswered (the page was logged out, or the command is no longer open). */
export function dismissConfirm() {
  const dialog = $('confirm', HTMLDialogElement);
  if (dialog.open) dialog.close('');
}
