// @ts-check
// The operator's panel: the predicted preform, which line moves next, why the machine
// stopped, and the PackML commands to start, hold and stop it.
//
// The page shows what the daemon says and offers only what it would accept: a command's
// button is enabled only when `/state`'s `allowed` has it, the token's role may command
// (`/whoami`, asked at log in) and the daemon answers. While the daemon does not answer,
// the last picture stays, greyed, with the time it was last heard from, or with what the
// daemon said when it refused the event stream (too many connections, the token).
// What changes without the page asking (a restart, the program it restored, a recovery,
// the token's role) is said in a banner with its cause until the operator dismisses it.
//
// Data flow. The page fetches the state and the whole skeleton once, then follows the
// daemon's event stream. Each instruction event carries a skeleton delta; deltas are
// queued and applied in batches, once per animation frame, to the yarns they touch only.
// `done` is the number of instructions the skeleton shown holds: a delta that starts
// there is applied, one that starts before it is already shown, one that starts after it
// means events were missed, and the whole skeleton is fetched again. Events that arrive
// while a fetch is under way wait, then go through the same rule.

import { EventLink, crowdedAnswer, errorText, getToken, request, takeTokenFromFragment } from './api.js';
import * as colours from './colours.js';
import { Coalesced } from './coalesced.js';
import { Commands } from './commands.js';
import { dismissConfirm } from './confirm.js';
import { Connection } from './connection.js';
import { describeNext } from './describe.js';
import { byId as $, optionalById } from './dom.js';
import { clock } from './eta.js';
import { MatrixGrid } from './grid.js';
import { HistoryPanel } from './history.js';
import { JobPanel } from './job.js';
import { say } from './message.js';
import { Notices } from './notices.js';
import { OperatorPanels } from './panels.js';
import { ProgramPanel } from './program.js';
import { Selection } from './selection.js';
import { Session } from './session.js';
import { PreformView } from './skeleton.js';
import { StatusPanel } from './status.js';

const NO_PROGRAM = 'no program loaded'; // what the views say with no program loaded

/** @import { AuthEvent, CommandAnswer, DaemonEvent, HelloEvent, InstructionEvent, Next, Skeleton, State } from '../types/daemon' */
/** @import { Answer, LinkDown } from './api.js' */

const { Palette, css } = colours;
const COLOUR_KEY = 'bwsd.colourBy';
const COLOUR_MODES = colours.COLOUR_MODES ?? ['family', 'yarn'];
const KEEP = 1000; // samples kept in window.bwsd.latencies, .frames and .work
const FLOW_MS = 1000; // updates "flow" while the last instruction event is younger than this
const STATE_EVERY_MS = 2000; // while a program runs, the state (bus health…) is read this often
const WATCH_EVERY_MS = 5000; // at rest, the state is read this often: a silent daemon is seen
// Where the daemon takes a program (docs/api.md): Load is offered only there.
const LOADABLE = new Set(['Stopped', 'Idle', 'Complete', 'Aborted']);
const RUNNING_STATES = new Set(['Starting', 'Execute', 'Unholding', 'Unsuspending']);

// ----- test and diagnostics hooks -----
/**
 * @typedef {object} Hooks
 * @property {boolean} ready
 * @property {number} done
 * @property {number} nodes
 * @property {number} yarns
 * @property {number} contacts
 * @property {string | null} state
 * @property {string[]} allowed
 * @property {boolean} online
 * @property {string | null} role
 * @property {number | null} selected
 * @property {number[]} latencies
 * @property {number[]} frames
 * @property {number[]} drawn
 * @property {{ms: number, nodes: number}[]} work
 * @property {() => ReturnType<PreformView['dump']>} dump
 * @property {() => ReturnType<Notices['shown']>} notices
 * @property {() => ReturnType<OperatorPanels['consoleShown']>} console
 */
/** @type {Hooks} */
const hooks = {
  ready: false, // the first state and skeleton are on screen
  done: 0, // instructions applied to the 3D view
  nodes: 0,
  yarns: 0,
  contacts: 0,
  state: null, // PackML state name
  allowed: [], // the commands whose buttons are enabled
  online: false, // the daemon answers and the event link is up
  role: null, // the token's role, from /whoami
  selected: null, // the yarn picked in the view or the matrix
  latencies: [], // ms from an instruction's time to the frame that drew it
  frames: [], // ms between consecutive frames while updates flow
  drawn: [], // ms between consecutive drawings of the 3D view while updates flow
  work: [], // per frame that applied instructions: {ms: applying and drawing, nodes: shown}
  dump: () => view.dump(), // every yarn shown: [{id, node_ids, nodes}], as the skeleton JSON
  notices: () => notices.shown(), // the notes of the banner: [{cause, text}]
  console: () => panels.consoleShown(), // the console's entries shown: [{kind, mark, text}]
};
window.bwsd = hooks;

/**
 * @template T
 * @param {T[]} samples
 * @param {T} value
 */
function keep(samples, value) {
  samples.push(value);
  if (samples.length > KEEP) samples.splice(0, samples.length - KEEP);
}

// ----- what the page knows -----
let live = fresh();

/**
 * What the page knows of the daemon and shows.
 * @typedef {object} Live
 * @property {State | null} state the last GET state answer
 * @property {number | null} programId the program whose skeleton is shown
 * @property {boolean} loaded a skeleton is shown
 * @property {boolean} noProgram the daemon has no skeleton to show: no program, or no twin yet
 * @property {string} emptyNote what the views say instead of a skeleton
 * @property {number} done instructions in the skeleton shown
 * @property {number} eventIndex the newest instruction index seen in an event since the last state
 * @property {Next | null} eventNext and the "next" it announced
 * @property {boolean} fetchedOnce
 */

/** @returns {Live} */
function fresh() {
  return {
    state: null, // the last GET state answer
    programId: null, // the program whose skeleton is shown
    loaded: false, // a skeleton is shown
    noProgram: false, // the daemon has no skeleton to show: no program, or no twin yet
    emptyNote: NO_PROGRAM, // what the views say instead of a skeleton
    done: 0, // instructions in the skeleton shown
    eventIndex: 0, // the newest instruction index seen in an event since the last state
    eventNext: null, // and the "next" it announced
    fetchedOnce: false,
  };
}

/**
 * A program as the page names it, and the state it was in.
 * @typedef {{id: number | null, name: string | null, state: string}} ProgramShown
 */

/** @type {string | null} the start of the daemon the last hello came from */
let daemonBoot = null;
/** @type {ProgramShown | null} the program shown when the event stream last went down */
let programBefore = null;
/** @type {ProgramShown | null} set by a hello from another start: said with the next state */
let restartedFrom = null;

// The link to the daemon: up while the event stream is open and the last request was
// answered; `lastSeen` is when it last answered or sent an event.
const connection = new Connection(() => {
  statusDirty = true;
  gridDirty = true; // the machine's marks on the matrix are known only while it answers
  scheduleFrame();
});
let generation = 0; // counts logins and logouts: an answer asked for before one is dropped

/** @type {InstructionEvent[]} instruction events to apply at the next frame */
let inbox = [];
/** @type {InstructionEvent[]} instruction events that arrived while the skeleton was being fetched */
let waiting = [];

let frameRequested = false;
let lastTick = 0; // time of the previous frame while updates flow (0: none)
let flowingUntil = 0;
let gridDirty = false;
let statusDirty = false;
const SLOW_FRAME_MS = 20; // a drawing that takes longer than this leaves time free after it
let renderedAt = 0; // time of the frame that last drew the 3D view
let renderCost = 0; // ms from that frame to the next one: what drawing the view costs
let measured = true; // renderCost measured since the last drawing
/** @type {InstructionEvent[]} instruction events applied but not drawn yet */
let unshown = [];
let panelsDrawn = 0; // time the matrix and the status were last drawn while updates flow
// While instructions flow, the matrix, the status and the job are drawn at most this often:
// repainting hundreds of SVG cells at every frame (a 24x24 braid moves half of them at each
// instruction) costs the browser more than the 3D view, and no one reads 20 matrices a second.
const PANEL_MS = 200;

// ----- the parts of the page -----
let colourMode = 'yarn'; // neighbours apart; a choice kept in the browser wins
try {
  const kept = localStorage.getItem(COLOUR_KEY);
  if (kept !== null && COLOUR_MODES.includes(kept)) colourMode = kept;
} catch {
  // storage disabled
}
const palette = new Palette(colourMode);
const view = new PreformView($('view', HTMLCanvasElement), palette, scheduleFrame);
const grid = new MatrixGrid($('grid'), palette);
const status = new StatusPanel();
const job = new JobPanel({ onAnswer: answered, onUnreachable: unreachable });
const record = new HistoryPanel({ onAnswer: answered, onUnreachable: unreachable, onOpen: openProgram });
const programs = new ProgramPanel({
  onLoaded: () => refetch(),
  onUnauthorized: () => loggedOut(true),
  onForbidden: (answer) => forbidden(answer, 'program'),
});
const link = new EventLink({ onEvent, onLink });
const session = new Session({ onLogIn: logIn, onLogOut: logOut });
const notices = new Notices();
// The view's colours changed on their own (a section line's zones arrived, a pause
// refreshed them): what shares the palette follows.
view.onColoursChanged = () => {
  grid.repaint();
  drawLegend();
};
const selection = new Selection(view, grid, (id) => {
  hooks.selected = id;
});
const commands = new Commands({
  state: () => live.state,
  index: currentIndex,
  may: mayCommand,
  mayMode: mayChangeMode,
  answered: (/** @type {CommandAnswer} */ body) => {
    if (live.state) showState({ ...live.state, name: body.name, reason: body.reason, allowed: body.allowed });
  },
  refreshState: () => refreshState(),
  heard,
  unreachable,
  loggedOut: () => loggedOut(true),
  forbidden,
});
// The axes, manual moves, resume, console and job history (panels.js).
const panels = new OperatorPanels({
  state: () => live.state,
  active: () => link.wanted && online() === true,
  may: mayCommand,
  operator: () => session.mayCommand(),
  refreshState: () => refreshState(),
  heard,
  unreachable,
  loggedOut: () => loggedOut(true),
});
const colourBy = $('colour-by', HTMLSelectElement);
colourBy.value = colourMode;

// ----- the animation frame: every change reaches the screen here, once per frame -----

function scheduleFrame() {
  if (frameRequested) return;
  frameRequested = true;
  requestAnimationFrame(frame);
}

/** @param {DOMHighResTimeStamp} now */
function frame(now) {
  const started = performance.now();
  frameRequested = false;
  if (renderedAt && !measured) {
    renderCost = now - renderedAt; // from the frame that drew the view to the next one
    measured = true;
  }
  const applied = applyInbox();
  unshown.push(...applied);
  const flowing = performance.now() < flowingUntil;
  // While updates flow and drawing the view takes longer than a frame (software WebGL: up to
  // 50 ms), the view leaves as much time free as its last drawing took before it draws again:
  // drawing at every frame would leave no time to take the events in, and they would queue.
  const due = !flowing || renderCost <= SLOW_FRAME_MS || now - renderedAt >= 2 * renderCost;
  const drawn = (unshown.length > 0 || view.needsRender) && due;
  if (drawn) {
    view.render();
    if (lastTick && renderedAt) keep(hooks.drawn, now - renderedAt);
    renderedAt = now;
    measured = false;
  }
  if ((gridDirty || statusDirty) && (!flowing || now - panelsDrawn >= PANEL_MS)) {
    panelsDrawn = now;
    drawGrid(); // both, so that the matrix's next line and the job never disagree
    drawStatus();
  }
  if (drawn) {
    const shown = Date.now();
    for (const event of unshown) keep(hooks.latencies, shown - event.at * 1000);
    unshown = [];
    drawCounts();
  }
  if (applied.length > 0) keep(hooks.work, { ms: performance.now() - started, nodes: view.nodeCount });
  if (lastTick) keep(hooks.frames, now - lastTick); // every frame while updates flow
  // While instructions keep coming, keep ticking so frame times measure the real pace;
  // otherwise draw only on demand.
  if (flowing) {
    lastTick = now;
    scheduleFrame();
  } else if (lastTick) {
    lastTick = 0;
    // the updates paused: draw the grown tails into the settled layer (the colours wait
    // until the machine stands)
    view.settleTails(!RUNNING_STATES.has(live.state?.name ?? ''));
  }
}

/** A change of state: the matrix, the status and the job are drawn at the next frame. */
function panelsNow() {
  panelsDrawn = -Infinity;
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
      if (event.skeleton && view.applyDelta(event.skeleton)) { // (judge found the delta)
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

/**
 * "apply", "ignore" or "refetch": what to do with an instruction event now.
 * @param {InstructionEvent} event
 */
function judge(event) {
  const delta = event.skeleton;
  if (!live.loaded || event.program_id !== live.programId) {
    // An event of a program older than the one shown is history; a newer one needs it all.
    const shown = live.programId;
    const older = live.loaded && shown !== null && event.program_id !== undefined && event.program_id !== null && event.program_id < shown;
    return older ? 'ignore' : 'refetch';
  }
  if (!delta || typeof delta.since !== 'number') return 'refetch';
  if (delta.since === live.done) return 'apply';
  if (delta.since < live.done) return event.index <= live.done ? 'ignore' : 'refetch';
  return 'refetch'; // instructions were missed
}

/**
 * The progress and next line an instruction event announces (shown at this frame).
 * @param {InstructionEvent} event
 */
function noteProgress(event) {
  const state = live.state;
  if (!state || event.program_id !== state.program_id || event.index <= Math.max(live.eventIndex, state.index)) return;
  live.eventIndex = event.index;
  live.eventNext = event.next ?? null;
  job.noteInstruction(event);
  statusDirty = true;
  gridDirty = true;
}

// ----- fetching -----

/** The fetch of the state and the whole skeleton; events wait while it runs. */
const fullFetch = new Coalesced(fetchAll, {
  after: () => {
    live.fetchedOnce = true;
    inbox = waiting.concat(inbox); // then the same rule, in order
    waiting = [];
    scheduleFrame();
  },
  onError: unreachable,
});

/** Fetch the state and the whole skeleton again (one fetch at a time; asks coalesce). */
function refetch() {
  return fullFetch.run();
}

async function fetchAll() {
  const asked = generation;
  const stateAnswer = await request('api/v1/state');
  if (asked !== generation || !accept(stateAnswer)) return;
  showState(stateAnswer.body);
  const programId = stateAnswer.body.program_id;
  if (programId === null || programId === undefined) {
    showNoProgram();
    return;
  }
  const recovering = stateAnswer.body.recovering;
  if (recovering) { // no twin to read while it is rebuilt, or when it cannot be: not asked
    showNoProgram(`no skeleton: ${recovering}`);
    return;
  }
  const skeletonAnswer = await request('api/v1/skeleton', { timeoutMs: 0 }); // a large one takes its time
  if (asked !== generation) return;
  if (skeletonAnswer.status === 409) {
    showNoProgram();
    return;
  }
  if (!accept(skeletonAnswer)) return;
  /** @type {Skeleton} */
  const skeleton = skeletonAnswer.body;
  showSkeleton(skeleton, skeleton.program_id ?? programId);
}

/** GET the state alone (after a state, mode or fault event, or a command). */
const stateFetch = new Coalesced(
  async () => {
    const asked = generation;
    const answer = await request('api/v1/state');
    if (asked === generation && accept(answer)) showState(answer.body);
  },
  { onError: unreachable },
);

function refreshState() {
  if (!link.wanted) return Promise.resolve(); // logged out, or not started
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

/**
 * True for an answer to show; a 401 logs out, other refusals are said.
 * @param {Answer} answer
 */
function accept(answer) {
  heard();
  if (answer.ok) return true;
  if (answer.status === 401) loggedOut(true);
  // Over the address's limit while the event link is down, the link's banner says so.
  else if (!crowdedAnswer(answer) || connection.linkUp) say(errorText(answer), 'error');
  return false;
}

/**
 * A refused answer from a panel: a 401 logs out (the panel shows the rest).
 * @param {Answer} answer
 */
function answered(answer) {
  heard();
  if (answer.status === 401) loggedOut(true);
}

// ----- the link to the daemon -----

/** The daemon answered or sent an event. */
function heard() {
  connection.heard();
}

/**
 * A request found no daemon (a network error or no answer in time).
 * @param {unknown} error
 */
function unreachable(error) {
  connection.unreachable(error);
}

/** The daemon answers and the event link is up; null while the page does not ask. */
function online() {
  return connection.online(link.wanted);
}

// At rest nothing arrives on the event link: read the state now and then, so a daemon that
// stopped answering (its socket still open) is seen within WATCH_EVERY_MS.
setInterval(() => {
  if (link.wanted && connection.linkUp) refreshState();
}, WATCH_EVERY_MS);

// ----- showing what was fetched -----

/** @param {State} state */
function showState(state) {
  if (restartedFrom) sayRestored(restartedFrom, state);
  else if (live.state) noteRecovery(live.state, state);
  restartedFrom = null;
  const sameProgram = live.state && live.state.program_id === state.program_id;
  if (!sameProgram || state.index >= live.eventIndex || !RUNNING_STATES.has(state.name)) {
    // The state is the truth as of its answer; events only run ahead of it while running.
    live.eventIndex = state.index;
    live.eventNext = state.next ?? null;
  }
  if (!sameProgram) refreshHistory();
  if (live.state?.name !== state.name || !RUNNING_STATES.has(state.name)) panelsNow();
  if (live.state && RUNNING_STATES.has(live.state.name) && !RUNNING_STATES.has(state.name)) view.settleTails();
  live.state = state;
  status.readFaultNames(state.bus?.faulted ?? [], () => {
    statusDirty = true;
    scheduleFrame();
  });
  statusDirty = true;
  gridDirty = true;
  scheduleFrame();
}

/**
 * No skeleton to show: no program loaded, or (``note``) why the loaded one's is not there.
 * @param {string} [note]
 */
function showNoProgram(note = NO_PROGRAM) {
  view.clear();
  live.loaded = false;
  live.programId = null;
  live.noProgram = true;
  live.emptyNote = note;
  $('view-note').textContent = note;
  live.done = 0;
  selection.select(null);
  gridDirty = true;
  statusDirty = true;
  $('view-note').hidden = false;
  scheduleFrame();
}

/**
 * @param {Skeleton} skeleton
 * @param {number} programId
 */
function showSkeleton(skeleton, programId) {
  const newProgram = !live.loaded || programId !== live.programId;
  view.load(skeleton);
  if (typeof grid.setGeometry === 'function') grid.setGeometry(skeleton.machine ?? null);
  live.loaded = true;
  live.noProgram = false;
  live.programId = programId;
  live.done = skeleton.instructions;
  $('view-note').hidden = true;
  if (newProgram) {
    view.fit(); // keep the operator's camera on a refetch of the same program
    selection.select(null);
  }
  drawLegend();
  gridDirty = true;
  statusDirty = true;
  scheduleFrame();
}

/** The matrix grid and the next-instruction line. */
function drawGrid() {
  gridDirty = false;
  const next = currentNext();
  if (!live.loaded || !view.occupancy) {
    grid.showEmpty(live.noProgram ? live.emptyNote : live.state ? 'waiting for the skeleton…' : 'not logged in');
    grid.setNext(null);
  } else {
    grid.setOccupancy(view.occupancy);
    grid.setNext(next?.instruction ?? null);
  }
  document.body.style.setProperty('--matrix-cols', String(grid.cols)); // a wide window's matrix column
  grid.setRunning(RUNNING_STATES.has(live.state?.name ?? '') && online() !== false);
  const instruction = next?.instruction;
  if (typeof grid.setNextWeft === 'function') grid.setNextWeft(instruction?.kind === 'weft' && live.loaded ? instruction : null);
  if (typeof grid.setMachine === 'function') {
    const bus = live.state?.bus;
    const known = bus && online() !== false && bus.connected === true;
    grid.setMachine(known ? { differs: bus.differs ?? [], estop: Boolean(bus.estop), faulted: bus.faulted ?? [] } : null);
  }
  const line = optionalById('next');
  if (line) line.textContent = describeNext(live.state, next, currentIndex());
}

/**
 * The next instruction: from the newest of the state and the instruction events.
 * @returns {Next | null}
 */
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

/** State, program, status, job; and which commands are open. */
function drawStatus() {
  statusDirty = false;
  const state = live.state;
  const up = online();
  hooks.online = up === true;
  status.draw(state, up, connection.lastSeen, connection.why, link.retryAt);
  hooks.state = state?.name ?? null;
  if (state) {
    const hasProgram = state.program_id !== null && state.program_id !== undefined;
    $('program-label').textContent = hasProgram ? `${state.program_name ?? 'unnamed'} (#${state.program_id})` : 'none loaded';
    $('program-label').title = $('program-label').textContent;
    job.draw(state, currentIndex(), currentNext(), up !== false);
    record.setProgress(hasProgram ? state.program_id ?? null : null, currentIndex(), state.count);
  } else {
    $('program-label').textContent = '—';
    record.setProgress(null, 0, 0);
  }
  drawButtons();
}

/** The token may command and the daemon answers. */
function mayCommand() {
  return session.mayCommand() && online() === true;
}

/** The token may change the unit mode and the daemon answers. */
function mayChangeMode() {
  return session.mayChangeMode() && online() === true;
}

function drawButtons() {
  const may = mayCommand();
  hooks.allowed = commands.drawButtons(live.state?.allowed, may);
  commands.drawMode(live.state, mayChangeMode());
  const state = live.state;
  const loadable = state !== null && LOADABLE.has(state.name) && !state.recovering;
  programs.setAllowed({
    check: may,
    load: may && loadable,
    loadWhy: may ? 'a program is loaded only in Stopped, Idle, Complete or Aborted' : 'needs an operator token and a daemon that answers',
  });
  panels.draw();
  session.draw();
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
  if (selection.selected !== null) selection.draw(); // its contacts and length grow
  if (palette.weftColours.size !== legendFamilies) drawLegend(); // a weft of a new angle
  if (!hooks.ready && live.state && (live.loaded || live.noProgram)) hooks.ready = true;
}

let legendFamilies = -1; // weft families in the legend shown

function drawLegend() {
  const legend = optionalById('legend');
  if (!legend) return;
  legendFamilies = palette.weftColours.size;
  if (palette.mode === 'yarn') {
    legend.textContent = 'a colour per yarn, no two neighbours alike';
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

/** @param {DaemonEvent} event */
function onEvent(event) {
  heard();
  panels.event(event);
  switch (event.event) {
    case 'hello':
      noteBoot(/** @type {HelloEvent} */ (event)); // its `event` says what it is
      refetch(); // (re)connected: fetch it all
      refreshHistory();
      break;
    case 'auth':
      noteRole(/** @type {AuthEvent} */ (event));
      break;
    case 'program':
    case 'dropped':
      refetch(); // a new program, or events missed: fetch it all
      refreshHistory();
      break;
    case 'instruction':
      inbox.push(/** @type {InstructionEvent} */ (event)); // its `event` says what it is
      flowingUntil = performance.now() + FLOW_MS;
      scheduleFrame();
      refreshStateNowAndThen(); // the bus health and the rest of the state, while it runs
      break;
    case 'state':
      if (live.state && event.to) {
        live.state = { ...live.state, name: event.to, allowed: [] }; // until the fetch says
        panelsNow();
        statusDirty = true;
        scheduleFrame();
      }
      refreshState();
      refreshHistory();
      break;
    case 'mode':
      refreshState();
      refreshHistory();
      break;
    default: // fault, bus, ...: the state answer has it all
      refreshState();
  }
}

/**
 * @param {boolean} up
 * @param {LinkDown | null} why
 */
function onLink(up, why) {
  if (!up && connection.linkUp && live.state) programBefore = programOf(live.state);
  if (why?.kind === 'denied' && link.wanted && connection.why?.kind !== 'denied') {
    notices.add('token', why.wasUp
      ? `The daemon closed this page's event stream: ${why.reason}. The token was revoked, or no longer allows reading.`
      : `The daemon refused this page's event stream: ${why.reason}.`);
  }
  connection.setLink(up, why);
  if (up || !link.wanted) return;
  // Lost (or never had) the stream: show what the daemon says now; this also finds a
  // token that was revoked meanwhile (a 401 logs out and stops the retries).
  if (!live.fetchedOnce) refetch();
  else refreshState();
}

function refreshHistory() {
  if (link.wanted) record.refreshSoon();
}

// ----- what changed that the page did not ask for -----

/**
 * @param {State} state
 * @returns {ProgramShown}
 */
function programOf(state) {
  return { id: state.program_id ?? null, name: state.program_name ?? null, state: state.name };
}

/** @param {ProgramShown} program */
function named(program) {
  return `${program.name ?? 'unnamed'} (#${program.id})`;
}

/**
 * A hello from another start of the daemon than the last: it restarted.
 * @param {HelloEvent} hello
 */
function noteBoot(hello) {
  if (daemonBoot !== null && hello.boot !== daemonBoot) {
    notices.add('restart', `The daemon restarted: this start began at ${clock(new Date(hello.started * 1000))}.`);
    restartedFrom = programBefore ?? (live.state ? programOf(live.state) : { id: null, name: null, state: '—' });
  }
  daemonBoot = hello.boot;
}

/**
 * After a restart, the first state: the program the daemon restored, or lost, and why.
 * @param {ProgramShown} before
 * @param {State} state
 */
function sayRestored(before, state) {
  const now = programOf(state);
  const says = state.recovering || state.reason || '';
  const why = `the daemon is ${state.name} (it was ${before.state})${says ? `: ${says}` : ''}`;
  if (before.id !== null && now.id === before.id) {
    const how = state.recovering ? 'is being restored' : 'was restored';
    notices.add('program', `Program ${named(now)} ${how}; ${why}.`);
  } else if (before.id !== null && now.id === null) {
    notices.add('program', `Program ${named(before)} was not restored: no program is loaded; ${why}.`);
  } else if (now.id !== null) {
    const not = before.id !== null ? `, not ${named(before)}` : '';
    notices.add('program', `The daemon came back with program ${named(now)}${not}; ${why}.`);
  }
}

/**
 * A recovery that began, ended or failed between two states of the same start.
 * @param {State} old
 * @param {State} state
 */
function noteRecovery(old, state) {
  const was = old.recovering ?? '';
  const now = state.recovering ?? '';
  if (was === now) return;
  if (now) {
    notices.add('recovery', `After the restart: ${now}.`);
    return;
  }
  const before = programOf(old);
  if (state.program_id === before.id && state.count > 0) {
    const at = `instruction ${state.index} of ${state.count}`;
    notices.add('recovery', `After the restart: program ${named(before)} is restored, at ${at}.`);
    refetch(); // its skeleton could not be read while it was rebuilt
  } else if (before.id !== null && (state.program_id ?? null) === null) {
    notices.add('recovery', `After the restart: program ${named(before)} was not restored: ${state.reason ?? ''}.`);
  }
}

/**
 * The daemon's answer to the stream's auth message, and its word when the token's role
 * changed: the page then offers what the new role may do.
 * @param {AuthEvent} event
 */
function noteRole(event) {
  const before = session.role;
  if (before !== null && event.role !== before) {
    notices.add('role', `The role of the token ${event.name} changed from ${before} to ${event.role}: the page offers what ${event.role === 'admin' ? 'an' : 'a'} ${event.role} may do.`);
  }
  session.name = event.name;
  session.role = event.role;
  drawSession();
  drawButtons();
}

// ----- session -----

/**
 * A 403: the role it names; say what is needed.
 * @param {Answer} answer
 * @param {string} what
 */
function forbidden(answer, what) {
  session.noteRefusal(answer);
  const needs = answer.body?.needs ? ` (needs ${answer.body.needs})` : '';
  say(`${what}: your token's role is ${session.role ?? 'too low'}${needs}`, 'error');
  drawButtons();
}

/**
 * Show the login form (the token was refused).
 * @param {boolean} refused
 */
function loggedOut(refused) {
  if (refused && getToken()) say('the token was refused: log in again', 'error');
  session.end();
  link.stop();
  clearPicture();
  drawSession();
}

/** Forget everything shown: the 3D view, the matrix, the job, the history, the status. */
function clearPicture() {
  generation += 1;
  dismissConfirm();
  selection.select(null);
  view.clear();
  $('view-note').hidden = false;
  live = fresh();
  inbox = [];
  waiting = [];
  status.clear();
  job.clear();
  record.clear();
  programs.clear();
  panels.clear();
  $('reason-input', HTMLInputElement).value = '';
  $('mode-message').textContent = '';
  Object.assign(hooks, { ready: false, done: 0, nodes: 0, yarns: 0, contacts: 0, state: null, allowed: [] });
  $('view-stats').textContent = '';
  connection.reset();
  gridDirty = true;
  statusDirty = true;
  scheduleFrame();
}

function drawSession() {
  session.draw();
  hooks.role = session.role;
}

/**
 * Start (again): without a token, ask the daemon whether reads are open (else only the
 * login form shows, and nothing is asked that would be refused); then learn the token's
 * role, read the state and follow the events.
 */
async function start() {
  drawSession();
  drawButtons();
  let answer;
  try {
    if (!getToken()) {
      const health = await request('healthz');
      heard();
      if (!health.body?.open_reads) return; // the login form is showing (503: a part is down)
    }
    answer = await session.readRole();
    if (answer.ok) answer = await request('api/v1/state');
  } catch (error) {
    unreachable(error);
    link.start(); // keeps trying; the first "hello" fetches everything
    drawSession();
    return;
  }
  if (answer.status === 401) {
    loggedOut(Boolean(getToken()));
    return;
  }
  drawSession();
  if (crowdedAnswer(answer)) {
    // This address holds its limit of connections: the event link says so, and keeps
    // trying; once a connection is freed, its "hello" fetches everything.
    heard();
    link.start();
    return;
  }
  if (!accept(answer)) return;
  showState(answer.body);
  link.start(); // its "hello" fetches the skeleton
}

/**
 * Log in with `token` (from the form, or a link opened in this tab).
 * @param {string} token
 * @param {boolean} remember
 */
function logIn(token, remember) {
  if (link.wanted || getToken()) clearPicture(); // another token: nothing of the old one stays
  link.stop();
  session.keep(token, remember);
  say('', '');
  start();
}

function logOut() {
  session.end();
  link.stop();
  clearPicture();
  notices.dismiss();
  say('logged out', '');
  start();
}

/**
 * A program of the history: its text in the Program panel, to check or load again.
 * @param {number} id
 * @param {string} name
 */
async function openProgram(id, name) {
  try {
    const answer = await request(`api/v1/programs/${id}`);
    if (answer.ok) programs.open(name, answer.body.text ?? '');
    else answered(answer);
  } catch (error) {
    unreachable(error);
  }
}

// ----- view tools -----

colourBy.addEventListener('change', () => {
  const mode = COLOUR_MODES.includes(colourBy.value) ? colourBy.value : 'family';
  try {
    localStorage.setItem(COLOUR_KEY, mode);
  } catch {
    // storage disabled
  }
  view.setColourMode(mode);
  grid.repaint();
  drawLegend();
});

const showContacts = $('show-contacts', HTMLInputElement);
showContacts.addEventListener('change', () => view.setContactsVisible(showContacts.checked));
$('fit').addEventListener('click', () => view.fit());

// ----- go -----
takeTokenFromFragment();
drawLegend();
start();
