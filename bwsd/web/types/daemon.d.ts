// What the page reads from the daemon, as JSON: the shapes docs/api.md and
// docs/skeleton-json.md describe, as far as the page uses them. For the type check only
// (`npm run typecheck`): nothing here is loaded by the browser.

/** x, y, z in mm, in the preform frame. */
export type XYZ = [number, number, number];
/** A cell of the guide matrix: [row, col]. */
export type Cell = [number, number];

/** The machine geometry of a skeleton. */
export interface Machine {
  rows: number;
  cols: number;
  pitch_x: number;
  pitch_y: number;
  d_mat: number;
  c_mat: number;
  yarn_diameter?: number;
}

/** One yarn of a skeleton, or a yarn a delta adds. */
export interface YarnData {
  id: number;
  kind: string; // "warp" or "weft"
  family?: string;
  cell?: Cell | null;
  angle?: number | null;
  node_ids: number[];
  nodes: XYZ[];
}

/** A contact: [moving, hit] yarns and the two nodes it inserted. */
export interface ContactData {
  yarns?: [number, number];
  nodes: [number, number];
  instruction?: number;
}

/** The whole skeleton (`GET /api/v1/skeleton`). */
export interface Skeleton {
  program_id?: number | null;
  machine: Machine | null;
  diameter?: number;
  takeup: number;
  instructions: number;
  occupancy: number[][];
  yarns: YarnData[];
  contacts: ContactData[];
}

/** One instruction's change of the skeleton (an instruction event's `skeleton`). */
export interface SkeletonDelta {
  since: number;
  new_yarns?: YarnData[];
  inserted?: { yarn: number; node: number; after: number; xyz: XYZ }[];
  moved?: { yarn: number; node: number; xyz: XYZ }[];
  contacts?: ContactData[];
  takeup?: number;
  occupancy?: number[][];
}

/** A shift's move: [line, k], or [line, k, first, last] on a segment. */
export type ShiftMove = [number, number] | [number, number, number, number];

export interface ShiftInstruction {
  kind: 'shift';
  axis: string;
  moves: ShiftMove[];
}
export interface TakeupInstruction {
  kind: 'takeup';
  length: number;
}
export interface WeftInstruction {
  kind: 'weft';
  x: number;
  y: number;
  z: number;
  angle: number;
  length: number;
}
export type Instruction = ShiftInstruction | TakeupInstruction | WeftInstruction;

/** The instruction to run next (`/state`'s and an instruction event's `next`). */
export interface Next {
  index: number;
  line: number;
  instruction?: Instruction;
}

/** The machine as the controller last read it (`/state`'s `bus`). */
export interface Bus {
  connected?: boolean | null;
  last_error?: string | null;
  checked?: number;
  estop?: boolean | null;
  faulted?: string[];
  differs?: Cell[];
}

/** `GET /api/v1/state`. */
export interface State {
  name: string;
  mode_name?: string;
  program_id?: number | null;
  program_name?: string | null;
  index: number;
  count: number;
  reason?: string;
  stop_cause?: string;
  allowed: string[];
  recovering?: string;
  resumable?: boolean;
  resume_allowed?: boolean; // Start with resume will be accepted now
  manual?: string; // why no manual move is taken now ('' when they are)
  bus?: Bus;
  next?: Next | null;
}

/** An event of the event stream: `hello`, `auth`, `program`, `state`, `mode`, `fault`... */
export interface DaemonEvent {
  event: string;
  to?: string; // a state event's new state
}

/** The first event: the state, and which start of the daemon sends it. */
export interface HelloEvent extends DaemonEvent {
  event: 'hello';
  name: string;
  program_id?: number | null;
  index: number;
  boot: string; // another value than before: the daemon restarted
  started: number; // when this start began, seconds (Unix time)
}

/** The answer to the stream's auth message, and again when the token's role changes. */
export interface AuthEvent extends DaemonEvent {
  event: 'auth';
  name: string;
  role: string;
}

/** An instruction event: what was done, and the skeleton's change. */
export interface InstructionEvent extends DaemonEvent {
  event: 'instruction';
  program_id?: number | null;
  index: number;
  at: number; // seconds (Unix time)
  next?: Next | null;
  skeleton?: SkeletonDelta | null;
}

/** A command's answer (`POST /api/v1/commands/{name}`): the state it led to. */
export interface CommandAnswer {
  name: string;
  reason?: string;
  allowed: string[];
}

/** One axis of `GET /api/v1/machine`: micrometres (the weft angle: millidegrees). */
export interface AxisRead {
  index: number;
  name: string;
  kind: string;
  position: number;
  setpoint: number | null; // the last set-point the daemon wrote; null: none yet
  relative: boolean; // strokes that end back home (the set-point is a stroke)
  busy: boolean;
  fault: number;
  fault_name: string;
}

/** `GET /api/v1/machine`, and the machine a manual move's answer carries. */
export interface MachineRead {
  axes: AxisRead[];
  occupancy: boolean[][];
  estop: boolean;
  read_at: number; // when the bus answered this read (Unix time)
  connected: boolean; // the bus answers now (false: the last read before it was lost)
}

/** A line of the daemon's log (`GET /api/v1/log`, and the `log` event). */
export interface LogLine {
  seq: number;
  at: number; // seconds (Unix time)
  level: string; // INFO, WARNING, ERROR, CRITICAL
  logger: string;
  message: string;
  refusal: boolean; // a request refused by the gate or the controller
}

/** `GET /api/v1/programs/totals`. */
export interface Totals {
  outcomes: Record<string, { programs: number; run_s: number }>;
  programs: number;
  run_s: number;
}
