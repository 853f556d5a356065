// @ts-check
// The operator's panels beside the preview: the axes, the manual moves, the resume of an
// aborted program, the console and the job history. The page hands them the state, the
// events and its log in and out here; each panel asks the daemon for what it shows.

import { AxesPanel } from './axes-panel.js';
import { ConsolePanel } from './console.js';
import { JobsPanel } from './jobs.js';
import { ManualPanel } from './manual.js';

/** @import { DaemonEvent, State } from '../types/daemon' */

/**
 * What the panels need of the page.
 * @typedef {object} PanelsPage
 * @property {() => State | null} state the last /state
 * @property {() => boolean} active the page follows the daemon and it answers
 * @property {() => boolean} may the token may command and the daemon answers
 * @property {() => boolean} operator the token's role may command
 * @property {() => Promise<void>} refreshState
 * @property {() => void} heard
 * @property {(error: unknown) => void} unreachable
 * @property {() => void} loggedOut
 */

const JOB_EVENTS = new Set(['hello', 'program', 'state', 'dropped']);

export class OperatorPanels {
  /** @param {PanelsPage} page */
  constructor(page) {
    // A refused read says nothing more than the state's read: its 401 logs out, and the
    // stream's refusal is told in the banner (a panel's own 401 would log out first).
    const reads = { answered: () => page.heard(), unreachable: page.unreachable };
    this.manual = new ManualPanel({
      ...page,
      showMachine: (machine) => this.axes.show(machine),
    });
    // A lost bus is said by the status; the axes keep their last reading meanwhile.
    const reading = () => page.active() && page.state()?.bus?.connected !== false;
    this.axes = new AxesPanel({ ...reads, active: reading, onAxes: (axes) => this.manual.setAxes(axes) });
    this.console = new ConsolePanel(reads);
    this.jobs = new JobsPanel(reads);
  }

  /** What may be done now: drawn with the page's own buttons. */
  draw() {
    this.manual.draw();
  }

  /** @param {DaemonEvent} event */
  event(event) {
    this.console.event(/** @type {DaemonEvent & Record<string, any>} */ (event));
    if (JOB_EVENTS.has(event.event)) this.jobs.refresh();
    if (event.event === 'hello' || event.event === 'manual') this.axes.read();
  }

  /** Logged out, or another token: nothing of the old picture stays. */
  clear() {
    this.axes.clear();
    this.manual.clear();
    this.console.clear();
    this.jobs.clear();
  }

  /** For tests and diagnostics: the console's entries shown. */
  consoleShown() {
    return this.console.shown();
  }
}
