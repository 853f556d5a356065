// @ts-check
// What changed that the page did not ask for, said with its cause until the operator
// dismisses it: the daemon restarted, the program it restored or lost, a recovery, the
// token's role changed or the token was refused.

import { byId as $ } from './dom.js';
import { clock } from './eta.js';

const KEPT = 8; // notes on screen (the oldest go)

/**
 * A note: its cause (`restart`, `program`, `recovery`, `role`, `token`), what it says, when.
 * @typedef {{cause: string, text: string, at: Date}} Notice
 */

export class Notices {
  constructor() {
    /** @type {Notice[]} */
    this.items = [];
    $('notice-dismiss').addEventListener('click', () => this.dismiss());
  }

  /**
   * Say `text`, for `cause`.
   * @param {string} cause
   * @param {string} text
   */
  add(cause, text) {
    this.items.push({ cause, text, at: new Date() });
    if (this.items.length > KEPT) this.items.splice(0, this.items.length - KEPT);
    this.draw();
  }

  /** The operator read them (or logged out). */
  dismiss() {
    this.items = [];
    this.draw();
  }

  draw() {
    $('notice-banner').hidden = this.items.length === 0;
    $('notice-list').replaceChildren(...this.items.map((notice) => {
      const item = document.createElement('li');
      item.dataset.cause = notice.cause;
      const time = document.createElement('time');
      time.textContent = clock(notice.at);
      item.append(time, notice.text);
      return item;
    }));
  }

  /** What the tests read: `{cause, text}` of each note shown. */
  shown() {
    return this.items.map(({ cause, text }) => ({ cause, text }));
  }
}
