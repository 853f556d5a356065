// The operator's panel: the predicted preform, which line moves next, why the machine
// stopped, and the PackML commands to start, hold and stop it.
//
// Data flow. The page fetches the state and the whole skeleton once, then follows the
// daemon's event stream. Each instruction event carries a skeleton delta; deltas are
// queued and applied in batches, once per animation frame, to the yarns they touch only.
// `done` is the number of instructions the skeleton shown holds: a delta that starts
// there is applied, one that starts before it is already shown, one that starts after it
// means events were missed, and the whole skeleton is fetched again. Events that arrive
// while a fetch is under way wait, then go through the same rule.

import { EventLink, errorText, getToken, request, setToken, takeTokenFromFragment } from './api.js';
import { Palette, css } from './colours.js';
import { MatrixGrid, signed } from './grid.js';
import { ProgramPanel } from './program.js';
import { PreformView } from './skeleton.js';

const $ = (id) => document.getElementById(id);
const COLOUR_KEY = 'bwsd.colourBy';
const WITH_REASON = new Set(['stop', 'hold', 'abort']); // commands that send the reason field
const KEEP = 1000; // samples kept in window.bwsd.latencies, .frames and .work
const FLOW_MS = 1000; // updates "flow" while the last instruction event is younger than this
const STATE_EVERY_MS = 2000; // while a program runs, the state (bus health…) is read this often

// ----- test and diagnostics hooks -----
const hooks = {
  ready: false, // the first state and skeleton are on screen
  done: 0, // instructions applied to the 3D view
  nodes: 0,
  yarns: 0,
  contacts: 0,
  state: null, // PackML state name
  latencies: [], // ms from an instruction's time to the frame that drew it
  frames: [], // ms between consecutive frames while updates flow
  work: [], // per frame that applied instructions: {ms: applying and drawing, nodes: shown}
  dump: () => view.dump(), // every yarn shown: [{id, node_ids, nodes}], as the skeleton JSON
};
window.bwsd = hooks;

function keep(samples, value) {
  samples.push(value);
  if (samples.length > KEEP) samples.splice(0, samples.length - KEEP);
}

// ----- what the page knows -----
const live = {
  state: null, // the last GET state answer
  programId: null, // the program whose skeleton is shown
  loaded: false, // a skeleton is shown
  noProgram: false, // the daemon has no program loaded
  done: 0, // instructions in the skeleton shown
  eventIndex: 0, // the newest instruction index seen in an event (for this program)
  eventNext: null, // and the "next" it announced
  fetchedOnce: false,
};

let inbox = []; // instruction events to apply at the next frame
let waiting = []; // instruction events that arrived while the skeleton was being fetched

let frameRequested = false;
let lastTick = 0; // time of the previous frame while updates flow (0: none)
let flowingUntil = 0;
let gridDirty = false;
let statusDirty = false;

// ----- the parts of the page -----
let colourMode = 'family';
try {
  colourMode = localStorage.getItem(COLOUR_KEY) === 'yarn' ? 'yarn' : 'family';
} catch {
  // storage disabled
}
const palette = new Palette(colourMode);
const view = new PreformView($('view'), palette, scheduleFrame);
const grid = new MatrixGrid($('grid'), palette);
const programs = new ProgramPanel({
  onLoaded: () => refetch(),
  onUnauthorized: () => loggedOut(true),
  onForbidden: (answer) => forbidden(answer, 'program'),
});
const link = new EventLink({ onEvent, onLink });
$('colour-by').value = colourMode;

// ----- the animation frame: every change reaches the screen here, once per frame -----

function scheduleFrame() {
  if (frameRequested) return;
  frameRequested = true;
  requestAnimationFrame(frame);
}

function frame(now) {
  const started = performance.now();
  frameRequested = false;
  const applied = applyInbox();
  const drawn = applied.length > 0 || view.needsRender;
  if (drawn) view.render();
  if (gridDirty) drawGrid();
  if (statusDirty) drawStatus();
  if (drawn) {
    const shown = Date.now();
    for (const event of applied) keep(hooks.latencies, shown - event.at * 1000);
    drawCounts();
  }
  if (applied.length > 0) keep(hooks.work, { ms: performance.now() - started, nodes: view.nodeCount });
  if (lastTick) keep(hooks.frames, now - lastTick); // every frame while updates flow
  // While instructions keep coming, keep ticking so frame times measure the real pace;
  // otherwise draw only on demand.
  if (performance.now() < flowingUntil) {
    lastTick = now;
    scheduleFrame();
  } else if (lastTick) {
    lastTick = 0;
    view.settleTails(); // the updates paused: draw the grown tails into the settled layer
  }
}

/** Apply the queued instruction events by the delta rule; the events applied. */
function applyInbox() {
  const batch = inbox;
  inbox = [];
  const applied = [];
  for (let i = 0; i < batch.length; i += 1) {
    if (fullFetch.running) {
      waiting.push(...batch.slice(i));
      break;
    }
    const event = batch[i];
    noteProgress(event);
    const verdict = judge(event);
    if (verdict === 'apply') {
      if (view.applyDelta(event.skeleton)) {
        live.done = event.index;
        applied.push(event);
        gridDirty = true;
      } else {
        refetch(); // the delta names a node this page does not have
      }
    } else if (verdict === 'refetch') {
      waiting.push(event); // judged again after the fetch: then it is usually already in
      refetch();
    }
  }
  return applied;
}

/** "apply", "ignore" or "refetch": what to do with an instruction event now. */
function judge(event) {
  const delta = event.skeleton;
  if (!live.loaded || event.program_id !== live.programId) {
    // An event of a program older than the one shown is history; a newer one needs it all.
    const older = live.loaded && event.program_id != null && event.program_id < live.programId;
    return older ? 'ignore' : 'refetch';
  }
  if (!delta || typeof delta.since !== 'number') return 'refetch';
  if (delta.since === live.done) return 'apply';
  if (delta.since < live.done) return event.index <= live.done ? 'ignore' : 'refetch';
  return 'refetch'; // instructions were missed
}

/** The progress and next line an instruction event announces (shown at this frame). */
function noteProgress(event) {
  const state = live.state;
  if (!state || event.program_id !== state.program_id || event.index < live.eventIndex) return;
  live.eventIndex = event.index;
  live.eventNext = event.next ?? null;
  statusDirty = true;
  gridDirty = true;
}

// ----- fetching -----

/** Runs `work` one at a time: asking while it runs asks for one more run after it. */
class Coalesced {
  constructor(work, after = () => {}) {
    this.work = work;
    this.after = after; // once the runs are over, whatever happened
    this.running = null; // the runs under way, if any
    this.again = false;
  }

  run() {
    if (this.running) {
      this.again = true;
      return this.running;
    }
    this.running = (async () => {
      try {
        do {
          this.again = false;
          await this.work();
        } while (this.again);
      } catch (error) {
        say(`the daemon cannot be reached (${error.message})`, 'error');
      } finally {
        this.running = null;
        this.after();
      }
    })();
    return this.running;
  }
}

/** The fetch of the state and the whole skeleton; events wait while it runs. */
const fullFetch = new Coalesced(fetchAll, () => {
  live.fetchedOnce = true;
  inbox = waiting.concat(inbox); // then the same rule, in order
  waiting = [];
  scheduleFrame();
});

/** Fetch the state and the whole skeleton again (one fetch at a time; asks coalesce). */
function refetch() {
  return fullFetch.run();
}

async function fetchAll() {
  const stateAnswer = await request('api/v1/state');
  if (!accept(stateAnswer)) return;
  showState(stateAnswer.body);
  const programId = stateAnswer.body.program_id;
  if (programId === null || programId === undefined) {
    showNoProgram();
    return;
  }
  const skeletonAnswer = await request('api/v1/skeleton');
  if (skeletonAnswer.status === 409) {
    showNoProgram();
    return;
  }
  if (!accept(skeletonAnswer)) return;
  const skeleton = skeletonAnswer.body;
  showSkeleton(skeleton, skeleton.program_id ?? programId);
}

/** GET the state alone (after a state, mode or fault event, or a command). */
const stateFetch = new Coalesced(async () => {
  const answer = await request('api/v1/state');
  if (accept(answer)) showState(answer.body);
});

function refreshState() {
  return stateFetch.run();
}

/** GET the state at most every STATE_EVERY_MS while instructions flow. */
let stateAsked = 0;
function refreshStateNowAndThen() {
  const now = performance.now();
  if (now - stateAsked < STATE_EVERY_MS) return;
  stateAsked = now;
  refreshState();
}

/** True for an answer to show; a 401 logs out, other refusals are said. */
function accept(answer) {
  if (answer.ok) return true;
  if (answer.status === 401) loggedOut(true);
  else say(errorText(answer), 'error');
  return false;
}

// ----- showing what was fetched -----

function showState(state) {
  const sameProgram = live.state && live.state.program_id === state.program_id;
  if (!sameProgram) {
    live.eventIndex = 0;
    live.eventNext = null;
  }
  live.state = state;
  statusDirty = true;
  gridDirty = true;
  scheduleFrame();
}

function showNoProgram() {
  view.clear();
  live.loaded = false;
  live.programId = null;
  live.noProgram = true;
  live.done = 0;
  gridDirty = true;
  statusDirty = true;
  $('view-note').hidden = false;
  scheduleFrame();
}

function showSkeleton(skeleton, programId) {
  const newProgram = !live.loaded || programId !== live.programId;
  view.load(skeleton);
  live.loaded = true;
  live.noProgram = false;
  live.programId = programId;
  live.done = skeleton.instructions;
  $('view-note').hidden = true;
  if (newProgram) view.fit(); // keep the operator's camera on a refetch of the same program
  drawLegend();
  gridDirty = true;
  statusDirty = true;
  scheduleFrame();
}

/** The matrix grid and the next-instruction line. */
function drawGrid() {
  gridDirty = false;
  if (!live.loaded || !view.occupancy) {
    grid.showEmpty(live.noProgram ? 'no program loaded' : 'waiting for the skeleton…');
    grid.setNext(null);
  } else {
    grid.setOccupancy(view.occupancy);
    grid.setNext(currentNext()?.instruction ?? null);
  }
  $('next').textContent = describeNext(currentNext());
}

/** The next instruction: from the newest of the state and the instruction events. */
function currentNext() {
  const state = live.state;
  if (!state) return null;
  if (live.eventIndex > state.index) return live.eventNext;
  return state.next ?? null;
}

function currentIndex() {
  const state = live.state;
  return state ? Math.max(state.index, live.eventIndex) : 0;
}

/** "next: line 12 — ROW 1:+1 2:-1", "next: line 14 — TAKEUP 3 mm". */
function describeNext(next) {
  const state = live.state;
  if (!state || state.program_id === null || state.program_id === undefined) return 'next: — (no program loaded)';
  if (!next) return currentIndex() >= state.count ? 'next: — (program done)' : 'next: —';
  const where = next.line ? `line ${next.line}` : `instruction ${next.index}`;
  const i = next.instruction ?? {};
  const number = (value) => String(Number(Number(value).toFixed(3)));
  let what;
  if (i.kind === 'shift') {
    // a move is [line, k], or [line, k, first, last] on a segment: "ROW 1:+1 3[0..3]:-1"
    const move = ([line, k, first, last]) =>
      `${line}${first === undefined ? '' : `[${first}..${last}]`}:${signed(k)}`;
    what = `${String(i.axis).toUpperCase()} ${i.moves.map(move).join(' ')}`;
  } else if (i.kind === 'takeup') {
    what = `TAKEUP ${number(i.length)} mm`;
  } else if (i.kind === 'weft') {
    what = `WEFT at x=${number(i.x)} y=${number(i.y)} z=${number(i.z)} mm, angle ${number(i.angle)}°, length ${number(i.length)} mm`;
  } else {
    what = String(i.kind ?? 'unknown');
  }
  return `next: ${where} — ${what}`;
}

/** State, mode, program, progress, reason, fault, bus; and which commands are open. */
function drawStatus() {
  statusDirty = false;
  const state = live.state;
  if (!state) return;
  const stateBox = $('state');
  stateBox.textContent = state.name;
  stateBox.dataset.state = state.name;
  hooks.state = state.name;
  $('mode').textContent = state.mode_name ?? '—';
  const hasProgram = state.program_id !== null && state.program_id !== undefined;
  $('program-label').textContent = hasProgram ? `${state.program_name ?? 'unnamed'} (#${state.program_id})` : 'none loaded';
  const index = currentIndex();
  const progress = $('progress');
  progress.max = Math.max(state.count, 1);
  progress.value = Math.min(index, state.count);
  $('progress-text').textContent = `${index} / ${state.count}`;
  $('reason').textContent = state.reason || '—';
  $('last-fault').textContent = state.last_fault || '—';
  const bus = state.bus ?? {};
  const busBox = $('bus');
  const [busText, busKey] = bus.connected === true ? ['connected', 'up'] : bus.connected === false ? ['lost', 'down'] : ['not seen yet', 'unknown'];
  busBox.textContent = busText;
  busBox.dataset.bus = busKey;
  $('bus-error').textContent = bus.last_error ? `(${bus.last_error})` : '';
  drawButtons();
}

function drawButtons() {
  const allowed = new Set(live.state?.allowed ?? []);
  const may = mayCommand();
  for (const button of document.querySelectorAll('button[data-command]')) {
    button.disabled = !(may && allowed.has(button.dataset.command));
  }
  programs.setAllowed(may);
}

/** Counts under the view, and the test hooks. */
function drawCounts() {
  hooks.done = live.done;
  hooks.nodes = view.nodeCount;
  hooks.yarns = view.yarns.size;
  hooks.contacts = view.contactCount;
  $('view-stats').textContent = live.loaded
    ? `${hooks.yarns} yarns · ${hooks.nodes} nodes · ${hooks.contacts} contacts · instruction ${live.done} · take-up ${Number(view.takeup.toFixed(3))} mm`
    : '';
  if (palette.weftColours.size !== legendFamilies) drawLegend(); // a weft of a new angle
  if (!hooks.ready && live.state && (live.loaded || live.noProgram)) hooks.ready = true;
}

let legendFamilies = -1; // weft families in the legend shown

function drawLegend() {
  const legend = $('legend');
  legendFamilies = palette.weftColours.size;
  if (palette.mode === 'yarn') {
    legend.textContent = 'a hue per yarn id';
    return;
  }
  legend.replaceChildren(
    ...palette.legend().map(([family, colour]) => {
      const chip = document.createElement('span');
      chip.className = 'chip';
      chip.style.setProperty('--chip', css(colour));
      chip.textContent = family;
      return chip;
    }),
  );
}

// ----- events -----

function onEvent(event) {
  switch (event.event) {
    case 'hello':
      if ($('message').textContent.includes('cannot be reached')) say('', ''); // back again
      refetch(); // (re)connected: fetch it all
      break;
    case 'program':
    case 'dropped':
      refetch(); // a new program, or events missed: fetch it all
      break;
    case 'instruction':
      inbox.push(event);
      flowingUntil = performance.now() + FLOW_MS;
      scheduleFrame();
      refreshStateNowAndThen(); // the bus health and the rest of the state, while it runs
      break;
    case 'state':
      if (live.state && event.to) {
        live.state = { ...live.state, name: event.to, allowed: [] }; // until the fetch says
        statusDirty = true;
        scheduleFrame();
      }
      refreshState();
      break;
    default: // fault, mode, ...: the state answer has it all
      refreshState();
  }
}

function onLink(up) {
  const box = $('link');
  const text = up ? 'live' : link.wanted ? 'reconnecting' : 'off';
  box.textContent = text;
  box.dataset.link = text;
  if (up || !link.wanted) return;
  // Lost (or never had) the stream: show what the daemon says now; this also finds a
  // token that was revoked meanwhile (a 401 logs out and stops the retries).
  if (!live.fetchedOnce) refetch();
  else refreshState();
}

// ----- session -----

// The token's role, once a refusal (403) named it: a viewer's token cannot command.
let role = null;
const COMMANDING_ROLES = new Set(['operator', 'admin']);

function mayCommand() {
  return Boolean(getToken()) && (role === null || COMMANDING_ROLES.has(role));
}

/** A 403: remember the role it names, and say what is needed. */
function forbidden(answer, what) {
  if (typeof answer.body?.role === 'string') role = answer.body.role;
  const needs = answer.body?.needs ? ` (needs ${answer.body.needs})` : '';
  say(`${what}: your token's role is ${role ?? 'too low'}${needs}`, 'error');
  drawSession();
  drawButtons();
}

/** Show the login form (the token was refused, or the operator logged out). */
function loggedOut(refused) {
  if (refused && getToken()) say('the token was refused: log in again', 'error');
  setToken(null);
  link.stop();
  drawSession();
  drawButtons();
}

function drawSession() {
  const token = getToken();
  $('login').hidden = Boolean(token);
  $('session').hidden = !token;
  $('session-role').textContent = role ? `logged in (${role})` : 'logged in';
}

/**
 * Start (again): without a token, ask the daemon whether reads are open (else only the
 * login form shows, and nothing is asked that would be refused); then read the state and
 * follow the events.
 */
async function start() {
  drawSession();
  drawButtons();
  let answer;
  try {
    if (!getToken()) {
      const health = await request('healthz');
      if (!(health.ok && health.body?.open_reads)) return; // the login form is showing
    }
    answer = await request('api/v1/state');
  } catch (error) {
    say(`the daemon cannot be reached (${error.message})`, 'error');
    link.start(); // keeps trying; the first "hello" fetches everything
    return;
  }
  if (answer.status === 401) {
    loggedOut(Boolean(getToken()));
    return;
  }
  if (!accept(answer)) return;
  showState(answer.body);
  link.start(); // its "hello" fetches the skeleton
}

$('login').addEventListener('submit', (event) => {
  event.preventDefault();
  const input = $('token-input');
  const token = input.value.trim();
  if (!token) return;
  setToken(token);
  role = null;
  input.value = '';
  say('', '');
  start();
});

$('logout').addEventListener('click', () => {
  setToken(null);
  role = null;
  link.stop();
  say('logged out', '');
  start();
});

// ----- commands -----

/** A line in the message area; a success fades after a while, an error stays. */
let sayTimer = null;
function say(text, kind) {
  const message = $('message');
  message.textContent = text;
  message.dataset.kind = kind;
  clearTimeout(sayTimer);
  if (kind === 'ok') sayTimer = setTimeout(() => say('', ''), 8000);
}

async function sendCommand(name) {
  const reason = $('reason-input').value.trim();
  const body = WITH_REASON.has(name) && reason ? { reason } : {};
  say(`${name}…`, 'pending');
  let answer;
  try {
    answer = await request(`api/v1/commands/${name}`, { method: 'POST', body });
  } catch (error) {
    say(`${name}: the daemon cannot be reached (${error.message})`, 'error');
    return;
  }
  if (answer.ok) {
    say(`${name}: now ${answer.body.name}`, 'ok');
    if (WITH_REASON.has(name)) $('reason-input').value = '';
    if (live.state) showState({ ...live.state, name: answer.body.name, reason: answer.body.reason, allowed: answer.body.allowed });
  } else if (answer.status === 401) {
    loggedOut(true);
  } else if (answer.status === 403) {
    forbidden(answer, name);
  } else {
    const allowed = answer.body?.allowed;
    const hint = Array.isArray(allowed) ? ` (accepted now: ${allowed.join(', ') || 'none'})` : '';
    say(`${name} refused: ${errorText(answer)}${answer.status === 409 ? hint : ''}`, 'error');
  }
  refreshState();
}

for (const button of document.querySelectorAll('button[data-command]')) {
  button.addEventListener('click', () => sendCommand(button.dataset.command));
}

// ----- view tools -----

$('colour-by').addEventListener('change', (event) => {
  const mode = event.target.value === 'yarn' ? 'yarn' : 'family';
  try {
    localStorage.setItem(COLOUR_KEY, mode);
  } catch {
    // storage disabled
  }
  view.setColourMode(mode);
  grid.repaint();
  drawLegend();
});

$('show-contacts').addEventListener('change', (event) => view.setContactsVisible(event.target.checked));
$('fit').addEventListener('click', () => view.fit());

// ----- go -----
takeTokenFromFragment();
drawLegend();
start();
