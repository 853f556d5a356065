// @ts-check
// Whether the daemon answers: up while the event stream is open and the last request was
// answered; `lastSeen` is when it last answered or sent an event (what the page shows as
// "disconnected since"); `why` is what the daemon said when it closed the stream (too many
// connections, a refused token), or that it said nothing.

import { messageOf, say, saysUnreachable } from './message.js';

/** @import { LinkDown } from './api.js' */

export class Connection {
  /** @param {() => void} onChange called when the page must draw the link again */
  constructor(onChange) {
    this.onChange = onChange;
    this.linkUp = false; // the event WebSocket is open
    this.answering = true; // the last request was answered
    /** @type {Date | null} */
    this.lastSeen = null;
    /** @type {LinkDown | null} why the stream is down (null while it is up, or not asked for) */
    this.why = null;
  }

  /** The daemon answered or sent an event. */
  heard() {
    this.lastSeen = new Date();
    if (this.answering) return;
    this.answering = true;
    if (saysUnreachable()) say('', '');
    this.onChange();
  }

  /**
   * A request found no daemon (a network error, or no answer in time).
   * @param {unknown} error
   */
  unreachable(error) {
    if (this.answering) {
      this.answering = false;
      say(`the daemon cannot be reached (${messageOf(error)})`, 'error');
    }
    this.onChange();
  }

  /**
   * The event stream opened or closed (and why, as far as the daemon said).
   * @param {boolean} up
   * @param {LinkDown | null} why
   */
  setLink(up, why) {
    this.linkUp = up;
    this.why = up ? null : why;
    if (up || (why && why.kind !== 'lost')) this.heard(); // a refusal is an answer
    this.onChange();
  }

  /**
   * True when the daemon answers; null when the page does not ask (`wanted` false).
   * @param {boolean} wanted
   * @returns {boolean | null}
   */
  online(wanted) {
    if (!wanted) return null;
    return this.linkUp && this.answering;
  }

  /** Nothing heard yet (after log out). */
  reset() {
    this.answering = true;
    this.lastSeen = null;
    this.why = null;
  }
}
