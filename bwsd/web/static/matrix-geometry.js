// @ts-check
// What the matrix draws, worked out without the page: which cells a shift moves, which
// line a faulted axis drives, and where the next weft runs in the matrix's coordinates.
// Every result is in cells: column c, row r is the cell's centre (c + 0.5, r + 0.5) on screen.

/** @import { Cell, Machine, ShiftMove, WeftInstruction } from '../types/daemon' */

/** @typedef {{k: number, first: number, last: number}} Span the cells first..last a move carries by k */
/** @typedef {{axis: string, line: number, first: number, last: number}} AxisCells */
/**
 * A weft's ends and centre in cells ([col, row]) and how far the yarns fan there.
 * @typedef {{from: number[], to: number[], centre: number[], fan: number}} WeftCells
 */

/**
 * A shift's moves by line, in the order given: line -> [{k, first, last}], the cells each
 * move carries (a whole line is cells 0..along-1; a segment's span is clipped to the matrix).
 * @param {ShiftMove[]} moves
 * @param {number} along
 */
export function movesByLine(moves, along) {
  /** @type {Map<number, Span[]>} */
  const lines = new Map();
  for (const [line, k, first = 0, last = along - 1] of moves) {
    const span = { k, first: Math.max(0, first), last: Math.min(along - 1, last) };
    if (span.first > span.last) continue;
    const spans = lines.get(line);
    if (spans) spans.push(span);
    else lines.set(line, [span]);
  }
  return lines;
}

const SHIFT_AXIS = /^(row|col)(\d+)(?:\[(\d+)\.\.(\d+)\])?$/;

/**
 * The cells a shift axis drives, from its bus name: `row3` -> {axis: "row", line: 3,
 * first: 0, last: along - 1}, `col2[1..3]` -> its segment's span; null for an axis that
 * drives no line (`weft_angle`, `weft_insert`, `takeup`) or a line outside the matrix.
 * @param {string} name
 * @param {number} rows
 * @param {number} cols
 * @returns {AxisCells | null}
 */
export function axisCells(name, rows, cols) {
  const match = SHIFT_AXIS.exec(String(name));
  if (!match) return null;
  const axis = match[1];
  const line = Number(match[2]);
  const [lines, along] = axis === 'row' ? [rows, cols] : [cols, rows];
  if (line >= lines) return null;
  const first = match[3] === undefined ? 0 : Math.max(0, Number(match[3]));
  const last = match[4] === undefined ? along - 1 : Math.min(along - 1, Number(match[4]));
  if (first > last) return null;
  return { axis, line, first, last };
}

/**
 * How far apart the yarns are at height z above the fell, as a fraction of their spacing
 * at the guides: c_mat at the fell, 1 at the matrix (d_mat above it), straight between.
 * @param {number} z
 * @param {Machine} machine
 */
export function fanAt(z, machine) {
  return machine.c_mat + ((1 - machine.c_mat) * z) / machine.d_mat;
}

/**
 * The next weft's ends in cells, scaled back from the fell to the guides: a weft
 * instruction {x, y, z, angle, length} (x, y mm in the preform frame, z mm above the fell)
 * on a machine {rows, cols, pitch_x, pitch_y, c_mat, d_mat} gives {from: [col, row],
 * to: [col, row], centre: [col, row], fan}, guide (r, c) at [c, r]; null when the
 * instruction or the machine lacks what it takes.
 * @param {WeftInstruction | null} weft
 * @param {Machine | null} machine
 * @returns {WeftCells | null}
 */
export function weftInCells(weft, machine) {
  if (!weft || weft.kind !== 'weft' || !machine) return null;
  const numbers = [weft.x, weft.y, weft.z, weft.angle, weft.length, machine.pitch_x, machine.pitch_y,
    machine.c_mat, machine.d_mat, machine.rows, machine.cols];
  if (!numbers.every(Number.isFinite) || machine.pitch_x <= 0 || machine.pitch_y <= 0) return null;
  const fan = fanAt(weft.z, machine);
  if (!(fan > 0)) return null;
  const ox = ((machine.cols - 1) / 2) * machine.pitch_x; // O, the convergence point
  const oy = ((machine.rows - 1) / 2) * machine.pitch_y;
  const radians = (weft.angle * Math.PI) / 180;
  const half = weft.length / 2;
  /**
   * @param {number} x
   * @param {number} y
   */
  const cells = (x, y) => [(ox + (x - ox) / fan) / machine.pitch_x, (oy + (y - oy) / fan) / machine.pitch_y];
  return {
    from: cells(weft.x - half * Math.cos(radians), weft.y - half * Math.sin(radians)),
    to: cells(weft.x + half * Math.cos(radians), weft.y + half * Math.sin(radians)),
    centre: cells(weft.x, weft.y),
    fan,
  };
}

/**
 * The cells where the sensors differ, as a set of "r,c" keys (cells outside the matrix left out).
 * @param {Cell[] | undefined} differs
 * @param {number} rows
 * @param {number} cols
 */
export function differingCells(differs, rows, cols) {
  /** @type {Set<string>} */
  const keys = new Set();
  for (const cell of differs ?? []) {
    const [r, c] = cell;
    if (Number.isInteger(r) && Number.isInteger(c) && r >= 0 && c >= 0 && r < rows && c < cols) keys.add(`${r},${c}`);
  }
  return keys;
}
