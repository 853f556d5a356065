// @ts-check
// The program panel: pick a .bws file (or type it), check it with a dry run, load it.
//
// A dry run answers the totals the twin predicts (instructions, contacts, yarns, nodes,
// take-up); a refused program answers the error with its line and column, shown here
// under the offending line of the text with a caret at the column.

import { errorText, request } from './api.js';
import { byId as $ } from './dom.js';
import { messageOf } from './message.js';

/** @import { Answer } from './api.js' */

/**
 * The totals the twin predicts for a program (a dry run's or a load's answer; a load's has
 * the program's id and name).
 * @typedef {{id?: number, name?: string, instructions: number, contacts: number, yarns: number, nodes: number, takeup: number}} Totals
 */

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
 * Millimetres for a person: 3, 22.5, 0.125.
 * @param {unknown} value
 */
function mm(value) {
  return `${Number(Number(value).toFixed(3))} mm`;
}

export class ProgramPanel {
  /**
   * @param {object} callbacks
   * @param {(totals: Totals) => void} callbacks.onLoaded called after a program was loaded
   *   (the page refetches everything)
   * @param {() => void} callbacks.onUnauthorized called on a 401 (the page shows the login form)
   * @param {(answer: Answer) => void} callbacks.onForbidden called with the answer of a 403
   *   (a token whose role is too low)
   */
  constructor({ onLoaded, onUnauthorized, onForbidden }) {
    this.onLoaded = onLoaded;
    this.onUnauthorized = onUnauthorized;
    this.onForbidden = onForbidden;
    this.file = $('program-file', HTMLInputElement);
    this.text = $('program-text', HTMLTextAreaElement);
    this.name = $('program-name', HTMLInputElement);
    this.checkButton = $('check', HTMLButtonElement);
    this.loadButton = $('load', HTMLButtonElement);
    this.result = $('dry-run');
    this.busy = false;
    this.checkAllowed = false;
    this.loadAllowed = false;

    this.file.addEventListener('change', () => this.readFile());
    this.checkButton.addEventListener('click', () => this.submit(true));
    this.loadButton.addEventListener('click', () => this.submit(false));
    this.text.addEventListener('input', () => this.update());
  }

  /**
   * Which of Check and Load the page offers: `check` (a dry run, in any state) and `load`
   * (only where the daemon takes a program), each for a token that may change things;
   * `loadWhy` says why Load is not offered.
   * @param {{check: boolean, load: boolean, loadWhy?: string}} allowed
   */
  setAllowed({ check, load, loadWhy = '' }) {
    this.checkAllowed = check;
    this.loadAllowed = load;
    this.loadButton.title = load ? 'make it the program to run' : loadWhy;
    this.update();
  }

  update() {
    const usable = !this.busy && this.text.value.trim() !== '';
    this.checkButton.disabled = !(usable && this.checkAllowed);
    this.loadButton.disabled = !(usable && this.loadAllowed);
  }

  /**
   * Put a program's text in the panel (from the history), to check or load it again.
   * @param {string} name
   * @param {string} text
   */
  open(name, text) {
    this.text.value = text;
    this.name.value = name;
    this.file.value = '';
    this.result.replaceChildren();
    this.update();
  }

  /** Forget the text and the last answer (logged out). */
  clear() {
    this.open('', '');
  }

  async readFile() {
    const file = this.file.files && this.file.files[0];
    if (!file) return;
    this.text.value = await file.text();
    this.name.value = file.name;
    this.result.replaceChildren();
    this.update();
  }

  /** The program's name: the field, else "program.bws". */
  programName() {
    const name = this.name.value.trim();
    return name || 'program.bws';
  }

  /**
   * POST the program: a dry run (`check`) or a load.
   * @param {boolean} dryRun
   */
  async submit(dryRun) {
    const text = this.text.value;
    const name = this.programName();
    this.busy = true;
    this.update();
    this.result.replaceChildren(element('p', 'pending', dryRun ? 'checking…' : 'loading…'));
    try {
      const answer = await request(`api/v1/programs${dryRun ? '?dry_run=true' : ''}`, {
        method: 'POST',
        body: { name, text },
        timeoutMs: 0, // a large program's dry run takes its time
      });
      if (answer.ok) {
        this.showTotals(answer.body, dryRun);
        if (!dryRun) this.onLoaded(answer.body);
      } else if (answer.status === 422 && answer.body && 'line' in answer.body) {
        this.showProgramError(answer.body, text);
      } else if (answer.status === 422 && answer.body && Array.isArray(answer.body.details)) {
        this.showInvalid(answer.body);
      } else {
        if (answer.status === 401) this.onUnauthorized();
        if (answer.status === 403) this.onForbidden(answer);
        this.result.replaceChildren(element('p', 'error', errorText(answer)));
      }
    } catch (error) {
      this.result.replaceChildren(element('p', 'error', `the daemon cannot be reached (${messageOf(error)})`));
    } finally {
      this.busy = false;
      this.update();
    }
  }

  /**
   * What the twin predicts for the program (and its id once loaded).
   * @param {Totals} totals
   * @param {boolean} dryRun
   */
  showTotals(totals, dryRun) {
    const head = dryRun
      ? 'check passed: the twin runs it to the end'
      : `loaded as program ${totals.id}: ${totals.name}`;
    const list = element('dl', 'totals');
    /** @type {[string, number | string][]} */
    const rows = [
      ['instructions', totals.instructions],
      ['contacts', totals.contacts],
      ['yarns', totals.yarns],
      ['nodes', totals.nodes],
      ['take-up', mm(totals.takeup)],
    ];
    for (const [label, value] of rows) list.append(element('dt', '', label), element('dd', '', String(value)));
    this.result.replaceChildren(element('p', 'ok', head), list);
  }

  /**
   * A refused program: "line N, column M: error" and the line quoted with a caret.
   * @param {{error: string, line: number, column: number}} refusal
   * @param {string} text
   */
  showProgramError({ error, line, column }, text) {
    const box = element('div', 'program-error');
    box.setAttribute('role', 'alert');
    const where = line > 0 ? `line ${line}${column > 0 ? `, column ${column}` : ''}` : 'the whole program';
    const head = element('p', 'error');
    if (line > 0) {
      // The place, as a button that puts the text cursor there.
      const goTo = element('button', 'goto', where);
      goTo.type = 'button';
      goTo.title = 'show it in the program text';
      goTo.addEventListener('click', () => this.select(text, line, column));
      head.append(goTo);
    } else {
      head.append(element('strong', '', where));
    }
    head.append(document.createTextNode(`: ${error}`));
    box.append(head);
    const source = line > 0 ? text.split(/\r\n|\r|\n/)[line - 1] : undefined;
    if (source !== undefined) {
      const gutter = `${line} | `;
      // Keep tabs under tabs so the caret lines up with the column however tabs render.
      const lead = column > 0 ? source.slice(0, column - 1).replace(/[^\t]/g, ' ') : '';
      const quote = element('pre', 'source');
      quote.textContent = `${gutter}${source}\n${' '.repeat(gutter.length)}${lead}${column > 0 ? '^' : ''}`;
      box.append(quote);
    }
    this.result.replaceChildren(box);
  }

  /**
   * Select the character at line, column (1-based) of the text area, scrolled into view.
   * @param {string} text
   * @param {number} line
   * @param {number} column
   */
  select(text, line, column) {
    const lines = text.split(/\r\n|\r|\n/);
    if (this.text.value !== text) return; // edited since: the place is no longer known
    let offset = 0;
    for (let i = 0; i < line - 1; i += 1) offset += lines[i].length + 1;
    offset += Math.max(column - 1, 0);
    this.text.focus();
    this.text.setSelectionRange(offset, offset + (column > 0 ? 1 : lines[line - 1].length));
    const lineHeight = this.text.scrollHeight / Math.max(lines.length, 1);
    this.text.scrollTop = Math.max(0, (line - 3) * lineHeight);
  }

  /**
   * A malformed request (e.g. an empty name): the validator's words.
   * @param {{error: string, details: {loc?: unknown, msg?: string}[]}} refusal
   */
  showInvalid({ error, details }) {
    const box = element('div', 'program-error');
    box.setAttribute('role', 'alert');
    box.append(element('p', 'error', error));
    const list = element('ul');
    for (const detail of details) {
      const field = Array.isArray(detail.loc) ? detail.loc.filter((part) => part !== 'body').join('.') : '';
      list.append(element('li', '', `${field ? `${field}: ` : ''}${detail.msg ?? JSON.stringify(detail)}`));
    }
    box.append(list);
    this.result.replaceChildren(box);
  }
}
