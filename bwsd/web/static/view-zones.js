// @ts-check
// Braided sections and their zones, as bwsd/program/sections.py defines them (pure), and
// the program's "# section: SPEC" line, as bwsd/export/mixing.py reads it.
//
// rect:RxC has one zone, "all". An L is a flange on top and a web below it, flush left:
// zones "flange", "junction" (the flange cells above the web) and "web". A T centres its
// web under the flange: "wing-left", "junction", "wing-right", "web". An I has a flange
// above and below: "top-left", "top-junction", "top-right", "web", "bottom-left",
// "bottom-junction", "bottom-right". The body starts at row 1, column 1 unless "@ROW,COL"
// follows. Zones are kept in this order.

import { messageOf } from './message.js';

/**
 * A braided section: its shape and written form, its zones in order (each a set of "row,col"
 * cells), and the zones a program of it must fill.
 * @typedef {{shape: string, spec: string, zones: [string, Set<string>][], required: string[]}} Section
 */
/** @typedef {[number, number]} Size rows, cols */

const MARGIN = 1;
const SPEC = /^(rect|L|T|I):(\d{1,4})x(\d{1,4})(?::(\d{1,4})x(\d{1,4}))?(?:@(\d{1,4}),(\d{1,4}))?$/;
// A whole-line comment "# section: SPEC [remark]".
const HEADER = /^[ \t]*#[ \t]*section[ \t]*:[ \t]*(\S*)/i;

/**
 * A section: {shape, spec, zones: [[name, Set of "row,col"]...], required: [names]}.
 * @param {string} shape
 * @param {string} spec
 * @param {Record<string, Set<string>>} zones
 * @param {string[]} required
 * @returns {Section}
 */
function section(shape, spec, zones, required) {
  return { shape, spec, zones: Object.entries(zones), required };
}

/**
 * @param {number} row
 * @param {number} col
 * @param {Size} size
 */
function block(row, col, [rows, cols]) {
  /** @type {Set<string>} */
  const cells = new Set();
  for (let r = 0; r < rows; r += 1) {
    for (let c = 0; c < cols; c += 1) cells.add(`${row + r},${col + c}`);
  }
  return cells;
}

/**
 * @param {Set<string>} a
 * @param {Set<string>} b
 */
function minus(a, b) {
  return new Set([...a].filter((cell) => !b.has(cell)));
}

/**
 * @param {string} prefix
 * @param {number} row
 * @param {number} col
 * @param {Size} flange
 * @param {number} wing
 * @param {number} webCols
 * @returns {Record<string, Set<string>>}
 */
function flangeZones(prefix, row, col, [rows], wing, webCols) {
  return {
    [`${prefix}left`]: block(row, col, [rows, wing]),
    [`${prefix}junction`]: block(row, col + wing, [rows, webCols]),
    [`${prefix}right`]: block(row, col + wing + webCols, [rows, wing]),
  };
}

/**
 * @param {string} shape
 * @param {Size} flange
 * @param {Size} web
 * @param {[number, number]} at
 */
function shaped(shape, flange, web, [r0, c0]) {
  const [[fr, fc], [wr, wc]] = [flange, web];
  const spec = `${shape}:${fr}x${fc}:${wr}x${wc}`;
  if (shape === 'L') {
    if (fc <= wc) throw new Error('an L section needs a flange wider than its web');
    const junction = block(r0, c0, [fr, wc]);
    const zones = { flange: minus(block(r0, c0, flange), junction), junction, web: block(r0 + fr, c0, web) };
    return section('L', spec, zones, ['flange', 'web']);
  }
  if (fc <= wc || (fc - wc) % 2) throw new Error(`a ${shape} section needs a flange wider than its web by an even number of cells`);
  const wing = (fc - wc) / 2;
  const top = flangeZones('', r0, c0, flange, wing, wc);
  const webCells = block(r0 + fr, c0 + wing, web);
  if (shape === 'T') {
    const zones = { 'wing-left': top.left, junction: top.junction, 'wing-right': top.right, web: webCells };
    return section('T', spec, zones, ['wing-left', 'wing-right', 'web']);
  }
  const zones = {
    'top-left': top.left, 'top-junction': top.junction, 'top-right': top.right, web: webCells,
    ...flangeZones('bottom-', r0 + fr + wr, c0, flange, wing, wc),
  };
  return section('I', spec, zones, ['top-left', 'top-right', 'web', 'bottom-left', 'bottom-right']);
}

/**
 * A section from its written form (`rect:3x4`, `L:2x6:4x2`, `T:2x8:4x2@1,1`); throws if malformed.
 * @param {string} text
 */
export function parseSection(text) {
  const m = SPEC.exec(text.trim());
  if (!m || (m[1] === 'rect') !== (m[4] === undefined)) throw new Error(`not a section: ${JSON.stringify(text.slice(0, 40))}`);
  /** @type {[number, number]} */
  const at = m[6] !== undefined ? [Number(m[6]), Number(m[7])] : [MARGIN, MARGIN];
  /** @type {Size} */
  const first = [Number(m[2]), Number(m[3])];
  for (const [r, c] of [first, m[4] === undefined ? [1, 1] : [Number(m[4]), Number(m[5])]]) {
    if (r < 1 || c < 1) throw new Error('blocks must be at least 1 x 1');
  }
  if (m[1] === 'rect') return section('rect', `rect:${first[0]}x${first[1]}`, { all: block(...at, first) }, ['all']);
  return shaped(m[1], first, [Number(m[4]), Number(m[5])], at);
}

/**
 * The SPEC of a program's "# section: SPEC" line, or null without one (two lines: the first).
 * @param {string} programText
 */
export function sectionLine(programText) {
  for (const line of programText.split('\n')) {
    const m = HEADER.exec(line);
    if (m) return m[1];
  }
  return null;
}

/**
 * The section named by `text`: a written section, or a program whose "# section:" line
 * names one; null for none (or for a malformed one: then `error` says why).
 * @param {string | null | undefined} text
 * @returns {{section: Section | null, error: string | null}}
 */
export function sectionFrom(text) {
  if (text === null || text === undefined) return { section: null, error: null };
  const spec = SPEC.test(text.trim()) ? text : sectionLine(text);
  if (spec === null) return { section: null, error: null };
  try {
    return { section: parseSection(spec), error: null };
  } catch (error) {
    return { section: null, error: messageOf(error) };
  }
}

/**
 * The zone of cell (row, col) in `sec`, or null (an edge or empty cell).
 * @param {Section} sec
 * @param {number} row
 * @param {number} col
 */
export function zoneOf(sec, row, col) {
  const key = `${row},${col}`;
  for (const [name, cells] of sec.zones) {
    if (cells.has(key)) return name;
  }
  return null;
}
