// @ts-check
// The job: the loaded program's text with the line that runs next marked, how far the run
// is with the time left, and the skeleton's exports as downloads.
//
// The line comes from `next.line` of `/state` and of each instruction event; `next` is
// null once all is done or the run has ended (Stop, Abort), and then no line is marked.

import { download, errorText, request } from './api.js';
import { byId as $ } from './dom.js';
import { RateWindow, clock, duration } from './eta.js';
import { messageOf } from './message.js';
import { showRun } from './run-summary.js';

/** @import { InstructionEvent, Next, State } from '../types/daemon' */
/** @import { Answer } from './api.js' */

const RUNNING = new Set(['Starting', 'Execute', 'Unholding', 'Unsuspending']);
/** @type {Record<string, string>} */
const EXTENSIONS = { json: 'json', tg3: 'tg3', vtp: 'vtp' };

/**
 * "braid-2x2" of "braid-2x2.bws": a file name's stem, safe for a download's name.
 * @param {string | null} name
 */
function stem(name) {
  const base = String(name ?? 'skeleton').replace(/\.[^.]*$/, '');
  return base.replace(/[^A-Za-z0-9._-]+/g, '_').slice(0, 80) || 'skeleton';
}

export class JobPanel {
  /**
   * @param {object} callbacks
   * @param {(answer: Answer) => void} callbacks.onAnswer called with every refused answer (a
   *   401 logs out)
   * @param {(error: unknown) => void} callbacks.onUnreachable called when the daemon does not answer
   */
  constructor({ onAnswer, onUnreachable }) {
    this.onAnswer = onAnswer;
    this.onUnreachable = onUnreachable;
    this.rate = new RateWindow();
    /** @type {number | null} the program whose text is shown */
    this.programId = null;
    /** @type {string | null} */
    this.programName = null;
    /** @type {HTMLElement[]} the text's line elements, 0-based */
    this.lines = [];
    /** @type {HTMLElement | null} the marked line element */
    this.current = null;
    /** @type {State | null} */
    this.state = null;
    /** @type {number | null} the line marked (1-based) */
    this.markedLine = null;
    /** @type {number | undefined} instructions done, as last drawn */
    this.index = undefined;
    for (const button of formatButtons()) {
      button.addEventListener('click', () => this.save(button.dataset.format ?? ''));
    }
  }

  /** Nothing loaded, or logged out: an empty job. */
  clear() {
    this.rate.clear();
    this.programId = this.programName = this.state = null;
    this.lines = [];
    this.current = null;
    this.markedLine = null;
    $('job-text').replaceChildren();
    $('download-message').textContent = '';
    this.drawEmpty();
  }

  drawEmpty() {
    $('progress', HTMLProgressElement).max = 1;
    $('progress', HTMLProgressElement).value = 0;
    $('progress-text').textContent = '0 / 0';
    $('job-note').textContent = 'no program loaded';
    $('eta').textContent = '';
    showRun(0, 0, '');
    for (const button of formatButtons()) button.disabled = true;
  }

  /**
   * An instruction event of the program shown: a sample of the run's rate.
   * @param {InstructionEvent} event
   */
  noteInstruction(event) {
    if (event.program_id === this.programId && typeof event.at === 'number') this.rate.add(event.index, event.at);
  }

  /**
   * Draw the job as `/state` (with the instruction events after it) says: `index` done,
   * `next` the instruction to run next (or null); `online`: the daemon answers.
   * @param {State | null} state
   * @param {number} index
   * @param {Next | null} next
   * @param {boolean} online
   */
  draw(state, index, next, online) {
    if (!state || state.program_id === null || state.program_id === undefined) {
      if (this.programId !== null) this.clear();
      this.state = state;
      this.drawEmpty();
      return;
    }
    if (state.program_id !== this.programId) this.loadText(state.program_id, state.program_name ?? null);
    if (!RUNNING.has(state.name) || (this.state && this.state.program_id !== state.program_id)) this.rate.clear();
    this.state = state;
    this.index = index;
    const count = state.count;
    $('progress', HTMLProgressElement).max = Math.max(count, 1);
    $('progress', HTMLProgressElement).value = Math.min(index, count);
    $('progress-text').textContent = `${index} / ${count}`;
    $('job-note').textContent = this.note(state, index, next);
    const left = this.timeLeft(state, index);
    $('eta').textContent = left?.text ?? '';
    showRun(index, count, left?.short ?? '');
    this.mark(next?.line ?? null);
    for (const button of formatButtons()) button.disabled = !online;
  }

  /**
   * Where the run is, in words.
   * @param {State} state
   * @param {number} index
   * @param {Next | null} next
   */
  note(state, index, next) {
    const count = state.count;
    const at = next ? `instruction ${next.index}, line ${next.line}` : '';
    if (!next && index >= count) return `done: all ${count} instructions`;
    if (!next) return `ended after instruction ${index} of ${count} (${state.name}): load a program to run again`;
    if (RUNNING.has(state.name)) return `running: ${at} next`;
    if (state.name === 'Held' || state.name === 'Suspended') return `${state.name.toLowerCase()}: ${at} runs next`;
    return `${at} runs next`;
  }

  /**
   * The time left, from the recent rate (eta.js), while the machine runs: `text` for the
   * job, `short` for the bar; null while the machine stands.
   * @param {State} state
   * @param {number} index
   */
  timeLeft(state, index) {
    if (!RUNNING.has(state.name) || index >= state.count) return null;
    const estimate = this.rate.estimate(state.count - index);
    if (!estimate) return { text: 'time left: estimating…', short: 'time left: estimating…' };
    const end = new Date(Date.now() + estimate.seconds * 1000);
    const rate = estimate.rate >= 10 ? estimate.rate.toFixed(0) : estimate.rate.toPrecision(2);
    const short = `time left: about ${duration(estimate.seconds)}`;
    return { text: `${short}, done at about ${clock(end)} (${rate} instructions/s over the last ${estimate.over})`, short };
  }

  /**
   * Fetch and show a program's text (the lines numbered as the program's errors are).
   * @param {number} id
   * @param {string | null} name
   */
  async loadText(id, name) {
    this.programId = id;
    this.programName = name;
    this.lines = [];
    this.current = null;
    const box = $('job-text');
    box.replaceChildren(Object.assign(document.createElement('p'), { className: 'minor', textContent: 'reading the program…' }));
    let answer;
    try {
      answer = await request(`api/v1/programs/${id}`);
    } catch (error) {
      this.onUnreachable(error);
      if (this.programId === id) this.programId = null; // asked again at the next draw
      return;
    }
    if (this.programId !== id) return; // another program meanwhile
    if (!answer.ok) {
      this.onAnswer(answer);
      box.replaceChildren(Object.assign(document.createElement('p'), { className: 'error', textContent: errorText(answer) }));
      return;
    }
    this.showText(answer.body.text ?? '');
    if (this.state) this.mark(this.markedLine ?? null, true);
  }

  /** @param {string} text */
  showText(text) {
    const lines = text.split('\n');
    if (lines.length > 1 && lines[lines.length - 1] === '') lines.pop();
    const width = String(lines.length).length;
    const fragment = document.createDocumentFragment();
    this.lines = lines.map((line, i) => {
      const row = document.createElement('div');
      row.className = 'src';
      row.dataset.line = String(i + 1);
      const number = document.createElement('span');
      number.className = 'ln';
      number.textContent = String(i + 1).padStart(width, ' ');
      const code = document.createElement('span');
      code.className = 'code';
      code.textContent = line.replace(/\r$/, '') || ' ';
      row.append(number, code);
      fragment.append(row);
      return row;
    });
    $('job-text').replaceChildren(fragment);
  }

  /**
   * Mark line `line` (1-based; null: none) and scroll the listing to it.
   * @param {number | null} line
   */
  mark(line, force = false) {
    if (line === this.markedLine && !force) return;
    this.markedLine = line;
    if (this.current) {
      this.current.classList.remove('current');
      this.current.removeAttribute('aria-current');
      this.current = null;
    }
    const row = line ? this.lines[line - 1] : null;
    if (!row) return;
    row.classList.add('current');
    row.setAttribute('aria-current', 'step');
    this.current = row;
    const box = $('job-text');
    // Only the listing scrolls (scrollIntoView would move the page as well).
    box.scrollTop = Math.max(0, row.offsetTop - box.offsetTop - box.clientHeight / 3);
  }

  /**
   * Download the skeleton as `format`, with the token, named after the program.
   * @param {string} format
   */
  async save(format) {
    const message = $('download-message');
    const name = `${stem(this.programName)}-${this.index ?? 0}.${EXTENSIONS[format]}`;
    message.textContent = `preparing ${name}…`;
    message.dataset.kind = 'pending';
    try {
      const got = await download(`api/v1/skeleton?format=${format}`, name);
      message.textContent = got.ok ? `saved ${name}` : `${format}: ${got.error}`;
      message.dataset.kind = got.ok ? 'ok' : 'error';
      if (!got.ok) this.onAnswer({ status: got.status, ok: false, body: { error: got.error } });
    } catch (error) {
      message.textContent = `${format}: the daemon cannot be reached (${messageOf(error)})`;
      message.dataset.kind = 'error';
      this.onUnreachable(error);
    }
  }
}

/** The download buttons (`data-format` names the export). */
function formatButtons() {
  const found = [...document.querySelectorAll('button[data-format]')];
  return found.filter((button) => button instanceof HTMLButtonElement);
}
