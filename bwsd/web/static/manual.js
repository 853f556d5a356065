// @ts-check
// Manual moves and the resume of an aborted program, as the daemon takes them.
//
// Manual: one stroke of a line (a row, a column or a segment), a take-up, a fault reset,
// sent as `POST /api/v1/manual`. They are offered only to a token that may command, while
// the daemon answers and `/state`'s `manual` is empty (it says why not otherwise: the unit
// mode, the state, the e-stop...). The daemon may still refuse one (the twin: a case would
// leave the matrix); its answer or refusal is said as it is, and the axes show the machine
// it read back. Resume: while `/state` says `resumable`, the Control panel says so, and
// "start with resume" is enabled when `resume_allowed` says the daemon takes it now.

import { errorText, request } from './api.js';
import { byId as $ } from './dom.js';
import { messageOf } from './message.js';

/** @import { AxisRead, MachineRead, State } from '../types/daemon' */

/**
 * What the manual moves need of the page.
 * @typedef {object} ManualPage
 * @property {() => State | null} state the last /state
 * @property {() => boolean} may the token may command and the daemon answers
 * @property {() => boolean} operator the token's role may command (whatever the link)
 * @property {() => Promise<void>} refreshState
 * @property {(machine: MachineRead) => void} showMachine the machine read back after a move
 * @property {() => void} heard
 * @property {(error: unknown) => void} unreachable
 * @property {() => void} loggedOut
 */

const STROKES = ['manual-axis', 'manual-minus', 'manual-plus']; // need the axes read first
const OTHERS = ['manual-takeup', 'manual-takeup-go', 'manual-reset'];

export class ManualPanel {
  /** @param {ManualPage} page */
  constructor(page) {
    this.page = page;
    this.busy = false;
    this.resumeBusy = false;
    /** @type {string} the axes offered, joined: the select is rebuilt only when they change */
    this.offered = '';
    $('manual-minus').addEventListener('click', () => this.stroke(-1));
    $('manual-plus').addEventListener('click', () => this.stroke(1));
    $('manual-takeup-go').addEventListener('click', () => {
      const length = Number($('manual-takeup', HTMLInputElement).value);
      this.send({ kind: 'takeup', length }, `take-up ${length > 0 ? '+' : ''}${length} mm`);
    });
    $('manual-reset').addEventListener('click', () => this.send({ kind: 'reset_faults' }, 'fault reset'));
    $('resume-start').addEventListener('click', () => this.resume());
  }

  /**
   * The shift axes (rows, columns, segments) the strokes may name.
   * @param {AxisRead[]} axes
   */
  setAxes(axes) {
    const names = axes.filter((axis) => axis.kind === 'row' || axis.kind === 'col').map((axis) => axis.name);
    const joined = names.join(' ');
    if (joined === this.offered) return;
    this.offered = joined;
    const select = $('manual-axis', HTMLSelectElement);
    const kept = select.value;
    select.replaceChildren(...names.map((name) => new Option(name, name)));
    if (names.includes(kept)) select.value = kept;
  }

  /** Enable what the daemon takes now; say why not otherwise. */
  draw() {
    const state = this.page.state();
    const may = this.page.may();
    const why = state?.manual ?? '';
    const open = may && state !== null && why === '' && !this.busy;
    for (const id of STROKES) enable(id, open && this.offered !== '');
    for (const id of OTHERS) enable(id, open);
    let note = '';
    if (!this.page.operator()) note = 'read only: this token may not move the machine';
    else if (state && why) note = `not now: ${why}`;
    else if (state && !may) note = 'the daemon does not answer';
    $('manual-note').textContent = note;
    this.drawResume(state, may);
  }

  /** @param {number} step */
  stroke(step) {
    const axis = $('manual-axis', HTMLSelectElement).value;
    this.send({ kind: 'stroke', axis, step }, `stroke ${axis} ${step > 0 ? '+' : ''}${step}`);
  }

  /**
   * POST one manual move; say the daemon's answer or refusal as it is.
   * @param {Record<string, unknown>} body
   * @param {string} what
   */
  async send(body, what) {
    const page = this.page;
    this.busy = true;
    this.draw();
    this.say(`${what}…`, 'pending');
    try {
      const answer = await request('api/v1/manual', { method: 'POST', body, timeoutMs: 0 }); // a move takes its time
      page.heard();
      if (answer.ok) {
        this.say(`${answer.body.done}: done`, 'ok');
        page.showMachine(answer.body.machine);
      } else if (answer.status === 401) {
        page.loggedOut();
      } else {
        this.say(`${what} refused: ${errorText(answer)}`, 'error');
      }
    } catch (error) {
      page.unreachable(error);
      this.say(`${what}: the daemon cannot be reached (${messageOf(error)})`, 'error');
    } finally {
      this.busy = false;
      await page.refreshState();
      this.draw();
    }
  }

  /**
   * @param {string} text
   * @param {string} kind
   */
  say(text, kind) {
    const message = $('manual-message');
    message.textContent = text;
    message.dataset.kind = kind;
  }

  // ----- resume -----

  /**
   * @param {State | null} state
   * @param {boolean} may
   */
  drawResume(state, may) {
    const box = $('resume');
    box.hidden = !state?.resumable;
    const button = $('resume-start', HTMLButtonElement);
    button.disabled = !may || !state?.resume_allowed || this.resumeBusy;
    if (!state?.resumable) return;
    const program = `${state.program_name ?? 'unnamed'} (#${state.program_id})`;
    const where = `${state.index} of ${state.count} instructions done`;
    const now = state.resume_allowed
      ? 'Start with resume continues it where it stopped.'
      : `The daemon does not take Start with resume now (${state.name}; accepted now: ${state.allowed.join(', ') || 'none'}).`;
    $('resume-text').textContent = `Program ${program} can be resumed: ${where}. ${now}`;
  }

  /** Start with resume; the daemon's answer or refusal said as it is. */
  async resume() {
    const page = this.page;
    const message = $('resume-message');
    this.resumeBusy = true;
    this.draw();
    message.textContent = 'start with resume…';
    message.dataset.kind = 'pending';
    try {
      const answer = await request('api/v1/commands/start', { method: 'POST', body: { resume: true }, timeoutMs: 0 });
      page.heard();
      if (answer.ok) {
        message.textContent = `start with resume: now ${answer.body.name}`;
        message.dataset.kind = 'ok';
      } else if (answer.status === 401) {
        page.loggedOut();
      } else {
        message.textContent = `start with resume refused: ${errorText(answer)}`;
        message.dataset.kind = 'error';
      }
    } catch (error) {
      page.unreachable(error);
      message.textContent = `start with resume: the daemon cannot be reached (${messageOf(error)})`;
      message.dataset.kind = 'error';
    } finally {
      this.resumeBusy = false;
      await page.refreshState();
      this.draw();
    }
  }

  clear() {
    this.offered = '';
    $('manual-axis', HTMLSelectElement).replaceChildren();
    this.say('', '');
    $('resume-message').textContent = '';
  }
}

/**
 * @param {string} id a button, an input or a select
 * @param {boolean} on
 */
function enable(id, on) {
  const control = $(id);
  if (control instanceof HTMLButtonElement || control instanceof HTMLInputElement || control instanceof HTMLSelectElement) {
    control.disabled = !on;
  }
}
