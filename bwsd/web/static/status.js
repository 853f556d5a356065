// @ts-check
// What the daemon says about the machine, drawn as it says it: the header's state badge and
// e-stop badge, the e-stop and disconnected banners, and the Status panel (machine health,
// bus, why it stopped, recovery, unit mode).
//
// Nothing here is guessed: the state, the stop cause and its reason, the bus and the
// machine's faults come from `/state` (and the fault names from `/machine`). While the
// daemon cannot be reached the last picture stays on screen, greyed, with the time it was
// last heard from.

import { request } from './api.js';
import { byId as $ } from './dom.js';
import { clock } from './eta.js';

/** @import { Bus, Cell, State } from '../types/daemon' */

/**
 * Why the machine stopped, as an operator says it (`stop_cause` in docs/api.md).
 * @type {Record<string, string>}
 */
export const CAUSES = {
  refused_move: 'refused move (the twin or a limit)',
  drive_fault: 'drive fault',
  estop: 'emergency stop',
  bus: 'bus lost or timed out',
  mismatch: 'read-back differs from the twin',
  operator: 'operator',
  restart: 'daemon restart',
  internal: 'internal error (see the daemon log)',
};

/** States in which the machine stands for its last stop, hold or suspension. */
const STANDING = new Set(['Stopping', 'Stopped', 'Aborting', 'Aborted', 'Holding', 'Held',
  'Suspending', 'Suspended', 'Clearing']);

/**
 * "(0, 1), (2, 3)"
 * @param {Cell[]} list
 */
function cells(list) {
  return list.map(([r, c]) => `(${r}, ${c})`).join(', ');
}

/**
 * `{text, key}` of the machine's health: e-stop, faulted axes, sensors, or ok.
 * @param {Bus} bus
 * @param {Record<string, string>} [faultNames] axis -> the name of its fault
 */
export function machineHealth(bus, faultNames) {
  if (bus.connected !== true || bus.estop === null || bus.estop === undefined) {
    return { text: bus.connected === false ? 'unknown (the bus is lost)' : 'not seen yet', key: 'unknown' };
  }
  const parts = [];
  if (bus.estop) parts.push('emergency stop pressed');
  const faulted = bus.faulted ?? [];
  if (faulted.length > 0) {
    const named = faulted.map((axis) => (faultNames?.[axis] ? `${axis}: ${faultNames[axis]}` : axis));
    parts.push(`axis fault: ${named.join(', ')}`);
  }
  const differs = bus.differs ?? [];
  if (differs.length > 0) parts.push(`sensors differ from the twin at ${cells(differs)}`);
  if (parts.length === 0) return { text: 'ok', key: 'ok' };
  return { text: parts.join('; '), key: bus.estop ? 'estop' : 'fault' };
}

/**
 * The bus as the daemon last saw it. An error is the bus's only while it is lost: an
 * axis fault or the e-stop answered over a working bus is the machine's (shown there).
 * @param {Bus} bus
 */
export function busHealth(bus) {
  if (bus.connected === true) return { text: 'connected', key: 'up', error: '' };
  if (bus.connected === false) return { text: 'lost', key: 'down', error: bus.last_error ?? '' };
  return { text: 'not seen yet', key: 'unknown', error: '' };
}

/**
 * "operator: yarn break", "drive fault: axis row1: stall"; '' when it is not current.
 * @param {State} state
 */
export function stopText(state) {
  if (!STANDING.has(state.name)) return '';
  const cause = CAUSES[state.stop_cause ?? ''] ?? '';
  const reason = state.reason ?? '';
  if (cause && reason) return `${cause}: ${reason}`;
  return cause || reason;
}

export class StatusPanel {
  constructor() {
    /** @type {Record<string, string>} axis -> fault name, from /machine (while axes report faults) */
    this.faultNames = {};
    this.faultedAsked = ''; // the faulted axes the names were asked for
  }

  /**
   * Draw `state` (the last /state answer, or null); `online`: the daemon answers and the
   * event link is up (null: the page does not ask, logged out); `lastSeen`: when the
   * daemon was last heard from (a Date, or null).
   * @param {State | null} state
   * @param {boolean | null} online
   * @param {Date | null} lastSeen
   */
  draw(state, online, lastSeen) {
    document.body.dataset.online = String(online !== false);
    this.drawLink(online, lastSeen);
    const badge = $('state');
    if (!state) {
      badge.textContent = '—';
      badge.dataset.state = '';
      this.drawEmpty();
      return;
    }
    badge.textContent = state.name;
    badge.dataset.state = state.name;
    badge.title = online !== false ? '' : `as last heard from the daemon, at ${lastSeen ? clock(lastSeen) : '?'}`;
    /** @type {Bus} */
    const bus = state.bus ?? {};
    const estop = online !== false && bus.estop === true;
    $('estop-badge').hidden = !estop;
    $('estop-banner').hidden = !estop;
    const machine = online !== false ? machineHealth(bus, this.faultNames) : { text: 'unknown (no answer)', key: 'unknown' };
    $('machine').textContent = machine.text;
    $('machine').dataset.health = machine.key;
    const link = online !== false ? busHealth(bus) : { text: 'unknown (no answer)', key: 'unknown', error: '' };
    $('bus').textContent = link.text;
    $('bus').dataset.bus = link.key;
    $('bus-error').textContent = link.error ? `(${link.error})` : '';
    $('reason').textContent = stopText(state) || '—';
    $('recovering').textContent = state.recovering ?? '';
    $('recovering').hidden = $('recovering-label').hidden = !state.recovering;
  }

  /**
   * @param {boolean | null} online
   * @param {Date | null} lastSeen
   */
  drawLink(online, lastSeen) {
    const box = $('link');
    if (online === null) {
      box.textContent = box.dataset.link = 'off'; // logged out: the page does not ask
      $('offline-banner').hidden = true;
      return;
    }
    const since = lastSeen ? clock(lastSeen) : 'the start';
    box.textContent = online ? 'connected' : `disconnected since ${since}`;
    box.dataset.link = online ? 'live' : 'down';
    const banner = $('offline-banner');
    banner.hidden = online;
    if (!online) {
      banner.textContent = lastSeen
        ? `The daemon does not answer: the page shows the machine as it was at ${since}, greyed. It keeps trying.`
        : 'The daemon does not answer yet. The page keeps trying.';
    }
  }

  /** Nothing known (logged out, or before the first answer). */
  drawEmpty() {
    $('estop-badge').hidden = true;
    $('estop-banner').hidden = true;
    $('machine').textContent = 'not seen yet';
    $('machine').dataset.health = 'unknown';
    $('bus').textContent = 'not seen yet';
    $('bus').dataset.bus = 'unknown';
    $('bus-error').textContent = '';
    $('reason').textContent = '—';
    $('recovering').hidden = $('recovering-label').hidden = true;
  }

  /**
   * The fault names (stall, jam...) of the `faulted` axes, read from `/machine` once per
   * change of the list; `onRead` is called when they are in.
   * @param {string[]} faulted
   * @param {() => void} onRead
   */
  async readFaultNames(faulted, onRead) {
    const key = faulted.join(',');
    if (key === this.faultedAsked) return;
    this.faultedAsked = key;
    if (faulted.length === 0) return;
    try {
      const answer = await request('api/v1/machine');
      if (!answer.ok || key !== this.faultedAsked) return; // refused, or cleared meanwhile
      this.faultNames = {};
      for (const axis of answer.body.axes ?? []) if (axis.fault) this.faultNames[axis.name] = axis.fault_name;
      onRead();
    } catch {
      this.faultedAsked = ''; // asked again with the next state
    }
  }

  /** Forget the fault names (logged out). */
  clear() {
    this.faultNames = {};
    this.faultedAsked = '';
  }
}
