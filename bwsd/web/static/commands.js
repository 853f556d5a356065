// @ts-check
// The PackML commands and the unit mode: buttons enabled only for what the daemon accepts
// now, a question before Stop and Abort, the reason sent with Stop, Hold and Abort, and the
// daemon's answer or refusal said as it is.

import { errorText, request } from './api.js';
import { confirmCommand } from './confirm.js';
import { describeRun } from './describe.js';
import { byId as $ } from './dom.js';
import { messageOf, say } from './message.js';

/** @import { CommandAnswer, State } from '../types/daemon' */
/** @import { Answer } from './api.js' */

/**
 * What the commands need of the page.
 * @typedef {object} CommandsPage
 * @property {() => State | null} state the last /state, or null
 * @property {() => number} index instructions done, as shown
 * @property {() => boolean} may the token may command and the daemon answers
 * @property {() => boolean} mayMode the token may change the unit mode (admin)
 * @property {(answer: CommandAnswer) => void} answered a command's answer, to show at once
 * @property {() => Promise<void>} refreshState
 * @property {() => void} heard
 * @property {(error: unknown) => void} unreachable
 * @property {() => void} loggedOut
 * @property {(answer: Answer, what: string) => void} forbidden
 */
const WITH_REASON = new Set(['stop', 'hold', 'abort']); // commands that send the reason field
const CONFIRMED = new Set(['stop', 'abort']); // commands asked about first
// Where PackML takes a unit mode change (docs/packml.md): the switch is open only there.
const MODE_STATES = new Set(['Stopped', 'Idle', 'Aborted']);

export class Commands {
  /**
   * @param page what the commands need of the page: `state()` (the last /state, or null),
   *   `index()` (instructions done, as shown), `may()` (the token may command and the
   *   daemon answers), `mayMode()` (the token may change the unit mode: admin),
   *   `answered(answer)` (a command's answer, to show at once),
   *   `refreshState()`, `heard()`, `unreachable(error)`, `loggedOut()`,
   *   `forbidden(answer, what)`
   * @param {CommandsPage} page
   */
  constructor(page) {
    this.page = page;
    this.modeBusy = false;
    for (const button of commandButtons()) {
      button.addEventListener('click', () => this.ask(button.dataset.command ?? ''));
    }
    const select = $('mode-select', HTMLSelectElement);
    select.addEventListener('change', () => this.changeMode(select.value));
  }

  /**
   * Enable the buttons of `allowed` (none when the page may not command); those enabled.
   * @param {string[] | undefined} allowed
   * @param {boolean} may
   */
  drawButtons(allowed, may) {
    const open = new Set(may ? allowed ?? [] : []);
    const enabled = [];
    for (const button of commandButtons()) {
      const command = button.dataset.command ?? '';
      button.disabled = !open.has(command);
      if (!button.disabled) enabled.push(command);
    }
    return enabled;
  }

  /**
   * The mode in force; the switch open to an admin where PackML allows a change.
   * @param {State | null} state
   * @param {boolean} may
   */
  drawMode(state, may) {
    const select = $('mode-select', HTMLSelectElement);
    if (!this.modeBusy) select.value = String(state?.mode_name ?? 'production').toLowerCase();
    select.disabled = this.modeBusy || !may || !state || !MODE_STATES.has(state.name);
  }

  /**
   * A button was pressed: ask first for Stop and Abort, then send it if still accepted.
   * @param {string} name
   */
  async ask(name) {
    let reason = $('reason-input', HTMLInputElement).value.trim();
    if (CONFIRMED.has(name)) {
      const answer = await confirmCommand(name, describeRun(this.page.state(), this.page.index()), reason);
      if (!answer) {
        say(`${name}: cancelled, nothing sent`, '');
        return;
      }
      reason = answer.reason;
    }
    const state = this.page.state();
    if (!this.page.may() || !(state?.allowed ?? []).includes(name)) {
      say(`${name}: no longer accepted (now ${state?.name ?? 'unknown'}), nothing sent`, 'error');
      return;
    }
    await this.send(name, reason);
  }

  /**
   * @param {string} name
   * @param {string} reason
   */
  async send(name, reason) {
    const page = this.page;
    const body = WITH_REASON.has(name) && reason ? { reason } : {};
    say(`${name}…`, 'pending');
    let answer;
    try {
      answer = await request(`api/v1/commands/${name}`, { method: 'POST', body, timeoutMs: 0 }); // a stop waits for the move
    } catch (error) {
      page.unreachable(error);
      say(`${name}: the daemon cannot be reached (${messageOf(error)})`, 'error');
      return;
    }
    page.heard();
    if (answer.ok) {
      say(`${name}: now ${answer.body.name}`, 'ok');
      if (WITH_REASON.has(name)) $('reason-input', HTMLInputElement).value = '';
      page.answered(answer.body);
    } else if (answer.status === 401) {
      page.loggedOut();
    } else if (answer.status === 403) {
      page.forbidden(answer, name);
    } else {
      const allowed = answer.body?.allowed;
      const hint = Array.isArray(allowed) ? ` (accepted now: ${allowed.join(', ') || 'none'})` : '';
      say(`${name} refused: ${errorText(answer)}${answer.status === 409 ? hint : ''}`, 'error');
    }
    page.refreshState();
  }

  /**
   * PUT the unit mode; say what the daemon answered, then show the mode it has.
   * @param {string} mode
   */
  async changeMode(mode) {
    const page = this.page;
    const message = $('mode-message');
    this.modeBusy = true;
    this.drawMode(page.state(), page.mayMode());
    message.textContent = `asking for ${mode}…`;
    message.dataset.kind = 'pending';
    try {
      const answer = await request('api/v1/mode', { method: 'PUT', body: { mode } });
      page.heard();
      if (answer.ok) {
        message.textContent = `now ${answer.body.mode_name}`;
        message.dataset.kind = 'ok';
      } else {
        if (answer.status === 401) page.loggedOut();
        message.textContent = `refused: ${errorText(answer)}`;
        message.dataset.kind = 'error';
      }
    } catch (error) {
      page.unreachable(error);
      message.textContent = `the daemon cannot be reached (${messageOf(error)})`;
      message.dataset.kind = 'error';
    } finally {
      this.modeBusy = false;
      await page.refreshState(); // the mode the daemon has, whatever it answered
      this.drawMode(page.state(), page.mayMode());
    }
  }
}

/** The PackML command buttons (`data-command` names the command). */
function commandButtons() {
  const found = [...document.querySelectorAll('button[data-command]')];
  return found.filter((button) => button instanceof HTMLButtonElement);
}
