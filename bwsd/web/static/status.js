// @ts-check
// What the daemon says about the machine, drawn as it says it: the header's state badge and
// e-stop badge, the e-stop and link banners (the daemon unreachable, too many connections,
// the token refused), and the Status panel (machine health, bus, why it stopped, recovery,
// unit mode).
//
// Nothing here is guessed: the state, the stop cause and its reason, the bus and the
// machine's faults come from `/state` (and the fault names from `/machine`). While the
// daemon cannot be reached the last picture stays on screen, greyed, with the time it was
// last heard from.

import { request } from './api.js';
import { byId as $ } from './dom.js';
import { clock } from './eta.js';

/** @import { Bus, Cell, State } from '../types/daemon' */
/** @import { LinkDown } from './api.js' */

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

/** Commands that leave any state towards an end: never the way on after an e-stop. */
const EXITS = new Set(['stop', 'abort']);

/**
 * "Clear", "Reset and Abort", "Stop, Abort and Clear": command names as the buttons say
 * them, in a sentence.
 * @param {string[]} names
 */
export function commandList(names) {
  const said = names.map((name) => name.charAt(0).toUpperCase() + name.slice(1));
  if (said.length <= 1) return said.join('');
  return `${said.slice(0, -1).join(', ')} and ${said[said.length - 1]}`;
}

/**
 * The e-stop banner: '' when it is not shown. While the e-stop is pressed, it says what the
 * daemon accepts meanwhile; once released, while the machine still stands for it (the stop
 * cause is the e-stop), the next step. Both come from `allowed`, never from a guess of
 * PackML's table: in Aborted the way on is Clear, in Stopped Reset.
 * @param {State} state
 * @param {Bus} bus
 */
export function estopText(state, bus) {
  const allowed = state.allowed ?? [];
  if (bus.estop === true) {
    const meanwhile = allowed.length ? `only ${commandList(allowed)}` : 'no command';
    return `Emergency stop pressed. Nothing moves. Release it on the machine: until then the daemon accepts ${meanwhile}.`;
  }
  if (bus.estop !== false || state.stop_cause !== 'estop' || !STANDING.has(state.name)) return '';
  const onward = allowed.filter((name) => !EXITS.has(name));
  const next = onward.length ? ` Next: ${commandList(onward)}.` : '';
  return `The emergency stop stopped the machine (${state.name}); it is released.${next}`;
}

/**
 * The link banner's text while the page does not follow the daemon: unreachable, too many
 * connections from this address, or the token refused.
 * @param {LinkDown | null} why
 * @param {Date | null} lastSeen
 * @param {number | null} retryAt when the page tries again (ms since the epoch)
 */
export function linkText(why, lastSeen, retryAt) {
  const since = lastSeen ? clock(lastSeen) : '';
  const again = retryAt ? ` It tries again at ${clock(new Date(retryAt))}.` : '';
  if (why?.kind === 'crowded') {
    const limit = why.limit === null ? '' : ` (limit ${why.limit})`;
    const counted = why.open === null ? why.reason : `${why.open} connections from this address`;
    return {
      key: 'crowded',
      short: 'too many connections',
      banner: `Too many tabs/connections open to this daemon${limit}: close some. The daemon refused this page's event stream (${counted}); the page shows the machine as it was at ${since || 'the start'}, greyed.${again}`,
    };
  }
  if (why?.kind === 'denied') {
    return {
      key: 'denied',
      short: 'no permission',
      banner: `No permission: the daemon refused this page's event stream (${why.reason}). Log in with a token that may read.`,
    };
  }
  return {
    key: 'down',
    short: `disconnected since ${since || 'the start'}`,
    banner: lastSeen
      ? `The daemon does not answer: the page shows the machine as it was at ${since}, greyed. It keeps trying.`
      : 'The daemon does not answer yet. The page keeps trying.',
  };
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
   * daemon was last heard from (a Date, or null); `why`: why the link is down, and
   * `retryAt` when the page tries again.
   * @param {State | null} state
   * @param {boolean | null} online
   * @param {Date | null} lastSeen
   * @param {LinkDown | null} [why]
   * @param {number | null} [retryAt]
   */
  draw(state, online, lastSeen, why = null, retryAt = null) {
    document.body.dataset.online = String(online !== false);
    this.drawLink(online, lastSeen, why, retryAt);
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
    const banner = online !== false ? estopText(state, bus) : '';
    $('estop-banner').hidden = !banner;
    $('estop-text').textContent = banner;
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
   * @param {LinkDown | null} why
   * @param {number | null} retryAt
   */
  drawLink(online, lastSeen, why, retryAt) {
    const box = $('link');
    const banner = $('offline-banner');
    if (online === null) {
      box.textContent = box.dataset.link = 'off'; // logged out: the page does not ask
      banner.hidden = true;
      return;
    }
    banner.hidden = online;
    if (online) {
      box.textContent = 'connected';
      box.dataset.link = 'live';
      return;
    }
    const said = linkText(why, lastSeen, retryAt);
    box.textContent = said.short;
    box.dataset.link = said.key;
    banner.dataset.cause = said.key;
    banner.textContent = said.banner;
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
