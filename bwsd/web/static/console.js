// @ts-check
// The console: the daemon's log lines (`GET /api/v1/log`, then the `log` events) and its
// notifications (state, fault, mode, program, manual, bus events) in one list, newest at
// the bottom, filterable by kind and by text. A refusal (the daemon's own mark on the line,
// `refusal`) and a fault (a fault event, a line at WARNING or above) are highlighted.
// Lines are numbered by the daemon: a gap (events dropped) is read again from `after`; a
// new start of the daemon numbers from 1 again.

import { request } from './api.js';
import { byId as $ } from './dom.js';
import { clock } from './eta.js';

/** @import { DaemonEvent, LogLine } from '../types/daemon' */
/** @import { Answer } from './api.js' */

const KEPT = 500; // entries on screen (the oldest go)
const ATTENTION = new Set(['WARNING', 'ERROR', 'CRITICAL']);

/**
 * What the console needs of the page.
 * @typedef {object} ConsolePage
 * @property {(answer: Answer) => void} answered a refused answer (a 401 logs out)
 * @property {(error: unknown) => void} unreachable
 */

/**
 * One entry: `mark` 'refusal', 'fault' or ''.
 * @typedef {{at: number, kind: 'log' | 'event', level: string, text: string, mark: string}} Entry
 */

/**
 * An event as a line of the console, or null for one it does not show.
 * @param {DaemonEvent & Record<string, any>} event
 * @returns {Entry | null}
 */
export function eventEntry(event) {
  const at = typeof event.at === 'number' ? event.at : Date.now() / 1000;
  /** @param {string} text @param {string} [mark] @returns {Entry} */
  const entry = (text, mark = '') => ({ at, kind: 'event', level: 'event', text, mark });
  switch (event.event) {
    case 'state':
      return entry(`state ${event.from} → ${event.to} (${event.cause})${event.reason ? `: ${event.reason}` : ''}`);
    case 'fault':
      return entry(`fault (${event.cause}): ${event.reason}`, 'fault');
    case 'mode':
      return entry(`unit mode ${event.from} → ${event.to}`);
    case 'program':
      return entry(`program ${event.program_id} ${event.name} loaded: ${event.count} instructions`);
    case 'manual':
      return entry(`manual ${event.what} by ${event.by}`);
    case 'bus':
      return entry(busText(event), event.connected === false || event.estop || (event.faulted ?? []).length ? 'fault' : '');
    case 'dropped':
      return entry(`${event.count} events missed (a slow link)`, 'fault');
    default:
      return null;
  }
}

/** @param {Record<string, any>} bus */
function busText(bus) {
  if (bus.connected === false) return `bus lost: ${bus.last_error ?? ''}`;
  const parts = bus.estop ? ['e-stop pressed'] : [];
  if ((bus.faulted ?? []).length) parts.push(`faulted: ${bus.faulted.join(', ')}`);
  if ((bus.differs ?? []).length) parts.push(`sensors differ at ${bus.differs.length} cells`);
  return `bus: ${parts.join('; ') || 'connected, no fault'}`;
}

/**
 * @param {LogLine} line
 * @returns {Entry}
 */
export function logEntry(line) {
  const mark = line.refusal ? 'refusal' : ATTENTION.has(line.level) ? 'fault' : '';
  return { at: line.at, kind: 'log', level: line.level, text: `${line.logger}: ${line.message}`, mark };
}

export class ConsolePanel {
  /** @param {ConsolePage} page */
  constructor(page) {
    this.page = page;
    this.last = 0; // the newest log line shown
    /** @type {string | null} */
    this.boot = null;
    this.generation = 0;
    this.fetching = false;
    $('console-show', HTMLSelectElement).addEventListener('change', () => this.filter());
    $('console-search', HTMLInputElement).addEventListener('input', () => this.filter());
  }

  /**
   * An event of the stream: a log line, a notification, or a hello (another start of the
   * daemon numbers its lines from 1 again).
   * @param {DaemonEvent & Record<string, any>} event
   */
  event(event) {
    if (event.event === 'hello') {
      if (this.boot !== null && event.boot !== this.boot) this.last = 0;
      this.boot = event.boot;
      this.fetch();
      return;
    }
    if (event.event === 'log') {
      const line = /** @type {LogLine} */ (/** @type {unknown} */ (event));
      if (line.seq === this.last + 1) this.logLines([line]);
      else if (line.seq > this.last) this.fetch(); // some were missed: read them in order
      return;
    }
    const entry = eventEntry(event);
    if (entry) this.add([entry]);
    if (event.event === 'dropped') this.fetch();
  }

  /** Read the log lines after the last one shown. */
  async fetch() {
    if (this.fetching) return;
    this.fetching = true;
    const asked = this.generation;
    try {
      const answer = await request(`api/v1/log?after=${this.last}&limit=1000`);
      if (asked !== this.generation) return;
      if (!answer.ok) {
        this.page.answered(answer);
        return;
      }
      if (answer.body.last < this.last) this.last = 0; // numbered again: the daemon restarted
      this.logLines(answer.body.lines.filter((/** @type {LogLine} */ line) => line.seq > this.last));
    } catch (error) {
      if (asked === this.generation) this.page.unreachable(error);
    } finally {
      this.fetching = false;
    }
  }

  /** @param {LogLine[]} lines */
  logLines(lines) {
    if (lines.length === 0) return;
    this.last = lines[lines.length - 1].seq;
    this.add(lines.map(logEntry));
  }

  /** @param {Entry[]} entries */
  add(entries) {
    const list = $('console-lines');
    const follow = list.scrollTop + list.clientHeight >= list.scrollHeight - 4;
    for (const entry of entries) list.append(this.item(entry));
    while (list.children.length > KEPT) list.firstElementChild?.remove();
    if (follow) list.scrollTop = list.scrollHeight;
  }

  /** @param {Entry} entry */
  item(entry) {
    const li = document.createElement('li');
    li.dataset.kind = entry.kind;
    li.dataset.mark = entry.mark;
    const time = document.createElement('time');
    time.textContent = clock(new Date(entry.at * 1000));
    const level = document.createElement('span');
    level.className = 'console-level';
    level.textContent = entry.mark === 'refusal' ? 'REFUSED' : entry.level;
    const text = document.createElement('span');
    text.textContent = entry.text;
    li.append(time, ' ', level, ' ', text);
    li.hidden = !this.shows(li);
    return li;
  }

  /** @param {HTMLElement} li */
  shows(li) {
    const show = $('console-show', HTMLSelectElement).value;
    const words = $('console-search', HTMLInputElement).value.trim().toLowerCase();
    if (show === 'attention' && !li.dataset.mark) return false;
    if ((show === 'log' || show === 'event') && li.dataset.kind !== show) return false;
    return !words || (li.textContent ?? '').toLowerCase().includes(words);
  }

  filter() {
    for (const li of $('console-lines').children) {
      if (li instanceof HTMLElement) li.hidden = !this.shows(li);
    }
  }

  /** The entries shown (for tests and diagnostics): `{kind, mark, text}`. */
  shown() {
    return [...$('console-lines').children]
      .filter((li) => li instanceof HTMLElement && !li.hidden)
      .map((li) => ({ kind: (li instanceof HTMLElement && li.dataset.kind) || '', mark: (li instanceof HTMLElement && li.dataset.mark) || '', text: li.textContent ?? '' }));
  }

  clear() {
    this.generation += 1;
    this.last = 0;
    this.boot = null;
    $('console-lines').replaceChildren();
  }
}
