// @ts-check
// The axes as the bus reports them: every axis with its position, the last set-point the
// daemon wrote and its fault, from the daemon's last read of the machine
// (`GET /api/v1/machine?last=true`: no request on the bus, and an answer while the bus is
// lost) every second while the page is logged in and the daemon answers (and at once after
// a manual move, from its answer).

import { errorText, request } from './api.js';
import { byId as $ } from './dom.js';
import { clock } from './eta.js';

/** @import { AxisRead, MachineRead } from '../types/daemon' */
/** @import { Answer } from './api.js' */

const EVERY_MS = 1000;

/**
 * What the panel needs of the page.
 * @typedef {object} AxesPage
 * @property {() => boolean} active the page follows the daemon and it answers
 * @property {(answer: Answer) => void} answered a refused answer (a 401 logs out)
 * @property {(error: unknown) => void} unreachable
 * @property {(axes: AxisRead[]) => void} onAxes the axes read, for the manual moves
 */

/**
 * A position or set-point in the axis's units: mm (3 decimals), degrees for the weft angle.
 * @param {AxisRead} axis
 * @param {number} value micrometres, or millidegrees
 */
export function amount(axis, value) {
  const unit = axis.kind === 'weft_angle' ? '°' : ' mm';
  return `${(value / 1000).toFixed(3)}${unit}`;
}

/**
 * The set-point as the operator reads it: a stroke (signed) for a relative axis.
 * @param {AxisRead} axis
 */
export function setpointText(axis) {
  if (axis.setpoint === null || axis.setpoint === undefined) return '—';
  const text = amount(axis, axis.setpoint);
  return axis.relative ? `stroke ${axis.setpoint > 0 ? '+' : ''}${text}` : text;
}

export class AxesPanel {
  /** @param {AxesPage} page */
  constructor(page) {
    this.page = page;
    /** @type {AxisRead[]} */
    this.axes = [];
    this.reading = false;
    this.generation = 0;
    setInterval(() => {
      if (this.page.active()) this.read();
    }, EVERY_MS);
  }

  /** Read the machine now (one read at a time). */
  async read() {
    if (this.reading) return;
    this.reading = true;
    const asked = this.generation;
    try {
      const answer = await request('api/v1/machine?last=true');
      if (asked !== this.generation) return;
      if (answer.ok) this.show(answer.body);
      else {
        this.page.answered(answer);
        this.note(`the machine cannot be read: ${errorText(answer)}`, 'error');
      }
    } catch (error) {
      if (asked === this.generation) this.page.unreachable(error);
    } finally {
      this.reading = false;
    }
  }

  /** @param {MachineRead} machine */
  show(machine) {
    this.axes = machine.axes;
    const rows = machine.axes.map((axis) => row(axis));
    $('axes-body').replaceChildren(...rows);
    const faulted = machine.axes.filter((axis) => axis.fault !== 0).length;
    const estop = machine.estop ? '; the e-stop is pressed' : '';
    const faults = faulted ? `; ${faulted} faulted` : '';
    const at = clock(new Date(machine.read_at * 1000));
    const lost = machine.connected ? '' : ' (the bus is lost: its last read)';
    this.note(`${machine.axes.length} axes, read at ${at}${lost}${faults}${estop}`, faulted || machine.estop || lost ? 'error' : '');
    this.page.onAxes(machine.axes);
  }

  /**
   * @param {string} text
   * @param {string} kind
   */
  note(text, kind) {
    const note = $('axes-note');
    note.textContent = text;
    note.dataset.kind = kind;
  }

  clear() {
    this.generation += 1;
    this.axes = [];
    $('axes-body').replaceChildren();
    this.note('not read yet', '');
  }
}

/** @param {AxisRead} axis */
function row(axis) {
  const tr = document.createElement('tr');
  tr.dataset.axis = axis.name;
  const state = axis.fault ? axis.fault_name : axis.busy ? 'moving' : 'ok';
  tr.dataset.state = axis.fault ? 'fault' : axis.busy ? 'busy' : 'ok';
  for (const text of [axis.name, amount(axis, axis.position), setpointText(axis), state]) {
    const td = document.createElement('td');
    td.textContent = text;
    tr.append(td);
  }
  return tr;
}
