// @ts-check
// The history: the programs loaded (newest first, paged back with `before`) and the journal's
// PackML states and events (oldest first, paged on with `after_state` / `after_event`),
// brought up to date whenever the daemon announces a change. The loaded program's progress
// is the one the Job panel shows (`/state`'s index and count, set with `setProgress`): the
// journal writes `done` late, and two numbers for one run would disagree.

import { request } from './api.js';
import { byId as $ } from './dom.js';
import { clock } from './eta.js';

/** @import { Answer } from './api.js' */

/**
 * A program of the history (`GET /api/v1/programs`).
 * @typedef {object} ProgramRecord
 * @property {number} id
 * @property {string} name
 * @property {string} outcome
 * @property {number} done
 * @property {number} instructions
 * @property {number} created Unix time
 * @property {number | null} [finished]
 * @property {string | null} [reason]
 */
/**
 * A line of the journal shown: a PackML state or an event.
 * @typedef {{time: number, kind: 'state' | 'event', id: number, text: string, reason: string}} LogEntry
 */
const PROGRAM_PAGE = 10;
const LOG_PAGE = 200; // entries of each kind per request
const LOG_PAGES = 5; // pages read in a row before "more" is offered
const LOG_KEPT = 500; // entries on screen (the oldest go)

/**
 * @template {keyof HTMLElementTagNameMap} K
 * @param {K} tag
 * @param {string} [className]
 * @param {string} [text]
 * @returns {HTMLElementTagNameMap[K]}
 */
function element(tag, className, text) {
  const node = document.createElement(tag);
  if (className) node.className = className;
  if (text !== undefined) node.textContent = text;
  return node;
}

/**
 * "12:01:02", or "2024-06-01 12:01:02" for another day.
 * @param {number} seconds Unix time
 */
export function when(seconds) {
  const date = new Date(seconds * 1000);
  const today = new Date();
  if (date.toDateString() === today.toDateString()) return clock(date);
  /** @param {number} n */
  const two = (n) => String(n).padStart(2, '0');
  return `${date.getFullYear()}-${two(date.getMonth() + 1)}-${two(date.getDate())} ${clock(date)}`;
}

/**
 * An event of the journal in words ("mode Production → Maintenance by alice").
 * @param {string} kind
 * @param {any} data the event's data, as the journal has it (JSON)
 */
function eventText(kind, data) {
  if (kind === 'mode' && data) return `mode ${data.from} → ${data.to}${data.by ? ` by ${data.by}` : ''}`;
  const detail = data && typeof data === 'object' ? JSON.stringify(data) : '';
  return `${kind}${detail && detail !== '{}' ? ` ${detail.slice(0, 200)}` : ''}`;
}

export class HistoryPanel {
  // What `clear` sets (the constructor calls it).
  /** @type {number} answers to an older one are dropped */
  generation;
  /** @type {ProgramRecord[]} records shown, newest first */
  programs;
  /** @type {boolean} */
  olderLeft;
  /** @type {number} the last state id read */
  afterState;
  /** @type {number} the last event id read */
  afterEvent;
  /** @type {LogEntry[]} */
  entries;
  /** @type {{programId: number | null, index: number, count: number}} the loaded program's progress */
  progress = { programId: null, index: 0, count: 0 };

  /**
   * @param {object} callbacks
   * @param {(answer: Answer) => void} callbacks.onAnswer called with a refused answer (a 401
   *   logs out)
   * @param {(error: unknown) => void} callbacks.onUnreachable called when the daemon does not answer
   * @param {(id: number, name: string) => void} callbacks.onOpen called with a program's id
   *   and name to edit its text again
   */
  constructor({ onAnswer, onUnreachable, onOpen }) {
    this.onAnswer = onAnswer;
    this.onUnreachable = onUnreachable;
    this.onOpen = onOpen;
    /** @type {Promise<void> | null} the refresh under way */
    this.busy = null;
    this.again = false;
    /** @type {ReturnType<typeof setTimeout> | undefined} */
    this.timer = undefined;
    this.clear();
    $('history-older').addEventListener('click', () => this.olderPrograms());
    $('history-more').addEventListener('click', () => this.readLog(LOG_PAGES));
  }

  clear() {
    clearTimeout(this.timer);
    this.generation = (this.generation ?? 0) + 1; // answers to an older one are dropped
    this.programs = []; // records shown, newest first
    this.olderLeft = false;
    this.afterState = 0;
    this.afterEvent = 0;
    this.entries = []; // {time, kind: 'state' | 'event', id, text, reason}
    $('history-programs').replaceChildren();
    $('history-log').replaceChildren();
    $('history-older').hidden = true;
    $('history-more').hidden = true;
  }

  /** Refresh shortly: the changes a burst of events announces are read once. */
  refreshSoon() {
    clearTimeout(this.timer);
    this.timer = setTimeout(() => this.refresh(), 200);
  }

  /** Bring both lists up to date (one refresh at a time; asks meanwhile coalesce). */
  refresh() {
    if (this.busy) {
      this.again = true;
      return this.busy;
    }
    this.busy = (async () => {
      try {
        do {
          this.again = false;
          await this.readPrograms(Math.max(PROGRAM_PAGE, this.programs.length), null, true);
          await this.readLog(LOG_PAGES);
        } while (this.again);
      } catch (error) {
        this.onUnreachable(error);
      } finally {
        this.busy = null;
      }
    })();
    return this.busy;
  }

  /**
   * The body of a GET's answer; null when it was refused or the panel was cleared meanwhile.
   * @param {string} path
   * @returns {Promise<any>}
   */
  async get(path) {
    const asked = this.generation;
    const answer = await request(path);
    if (asked !== this.generation) return null; // cleared meanwhile
    if (!answer.ok) {
      this.onAnswer(answer);
      return null;
    }
    return answer.body;
  }

  /**
   * Programs older than `before` (null: the newest); `replace` the list with them.
   * @param {number} limit
   * @param {number | null} before
   * @param {boolean} replace
   */
  async readPrograms(limit, before, replace) {
    const query = new URLSearchParams({ limit: String(Math.min(limit, 1000)) });
    if (before !== null) query.set('before', String(before));
    /** @type {ProgramRecord[] | null} */
    const page = await this.get(`api/v1/programs?${query}`);
    if (!page) return;
    this.programs = replace ? page : this.programs.concat(page);
    this.olderLeft = page.length === limit;
    this.drawPrograms();
  }

  async olderPrograms() {
    const last = this.programs[this.programs.length - 1];
    if (!last) return;
    try {
      await this.readPrograms(PROGRAM_PAGE, last.id, false);
    } catch (error) {
      this.onUnreachable(error);
    }
  }

  drawPrograms() {
    const list = $('history-programs');
    if (this.programs.length === 0) {
      list.replaceChildren(element('li', 'minor', 'none loaded yet'));
    } else {
      list.replaceChildren(...this.programs.map((record) => this.programItem(record)));
    }
    $('history-older').hidden = !this.olderLeft;
  }

  /**
   * The loaded program (null: none) and how far it is, as `/state` says: its record shows
   * these, whatever the journal's `done` says yet.
   * @param {number | null} programId
   * @param {number} index
   * @param {number} count
   */
  setProgress(programId, index, count) {
    const was = this.progress;
    if (was.programId === programId && was.index === index && was.count === count) return;
    this.progress = { programId, index, count };
    for (const id of new Set([was.programId, programId])) {
      const record = this.programs.find((r) => r.id === id);
      const shown = $('history-programs').querySelector(`li[data-program="${id}"] .record-progress`);
      if (record && shown) shown.textContent = this.done(record);
    }
  }

  /**
   * "27 / 50": the instructions done of a program's count; the loaded program's from `/state`.
   * @param {ProgramRecord} record
   */
  done(record) {
    const now = this.progress;
    if (record.id === now.programId) return `${now.index} / ${now.count}`;
    return `${record.done} / ${record.instructions}`;
  }

  /** @param {ProgramRecord} record */
  programItem(record) {
    const item = element('li', 'record');
    item.dataset.program = String(record.id);
    const head = element('span', 'record-head', `#${record.id} ${record.name}`);
    const outcome = element('span', `outcome outcome-${record.outcome}`, record.outcome);
    const facts = element('span', 'minor');
    facts.append(' ', element('span', 'record-progress', this.done(record)),
      ` · loaded ${when(record.created)}` + (record.finished ? ` · ended ${when(record.finished)}` : ''));
    const edit = element('button', 'link-button', 'edit');
    edit.type = 'button';
    edit.title = 'put this program\'s text in the Program panel, to check or load it again';
    edit.addEventListener('click', () => this.onOpen(record.id, record.name));
    item.append(head, ' ', outcome, facts, ' ', edit);
    if (record.reason) item.append(element('span', 'record-reason', record.reason));
    return item;
  }

  /**
   * Read the journal on from the last ids seen, up to `pages` pages of each kind.
   * @param {number} pages
   */
  async readLog(pages) {
    let full = false;
    for (let page = 0; page < pages; page += 1) {
      const query = new URLSearchParams({ after_state: String(this.afterState), after_event: String(this.afterEvent), limit: String(LOG_PAGE) });
      /**
       * @type {{
       *   states: {id: number, time: number, name: string, reason: string}[],
       *   events: {id: number, time: number, kind: string, data: unknown}[],
       * } | null}
       */
      const body = await this.get(`api/v1/history?${query}`);
      if (!body) return;
      for (const s of body.states) this.entries.push({ time: s.time, kind: 'state', id: s.id, text: s.name, reason: s.reason });
      for (const e of body.events) this.entries.push({ time: e.time, kind: 'event', id: e.id, text: eventText(e.kind, e.data), reason: '' });
      if (body.states.length) this.afterState = body.states[body.states.length - 1].id;
      if (body.events.length) this.afterEvent = body.events[body.events.length - 1].id;
      full = body.states.length === LOG_PAGE || body.events.length === LOG_PAGE;
      if (!full) break;
    }
    this.entries.sort((a, b) => a.time - b.time || (a.kind === b.kind ? a.id - b.id : 0));
    if (this.entries.length > LOG_KEPT) this.entries.splice(0, this.entries.length - LOG_KEPT);
    this.drawLog(full);
  }

  /** @param {boolean} more */
  drawLog(more) {
    const list = $('history-log');
    if (this.entries.length === 0) {
      list.replaceChildren(element('li', 'minor', 'nothing recorded yet'));
    } else {
      list.replaceChildren(...this.entries.map((entry) => {
        const item = element('li', `record entry-${entry.kind}`);
        item.append(element('time', 'minor', when(entry.time)), ' ', element('span', 'record-head', entry.text));
        if (entry.reason) item.append(element('span', 'record-reason', entry.reason));
        return item;
      }));
      list.scrollTop = list.scrollHeight; // the newest at the bottom, in view
    }
    $('history-more').hidden = !more;
  }
}
