// @ts-check
// The matrix panel around the drawing: the zoom buttons, the frame the matrix is drawn in
// (with the e-stop sign and the hover label), the line saying what the machine reports, and
// the legend of the marks.

import { patterns, svg } from './matrix-draw.js';

/** @import { Cell, WeftInstruction } from '../types/daemon' */
/** @import { WeftCells } from './matrix-geometry.js' */

const LAYERS = /** @type {const} */ (['cells', 'faults', 'differs', 'highlights', 'marks', 'weft']); // bottom to top

/** @typedef {Record<typeof LAYERS[number], SVGElement>} Layers the drawing's layers, by name */
/** @typedef {{differs: Cell[], estop: boolean, faulted: string[]}} MachineRead the machine as read */

/**
 * Build the panel in `host`; `actions` {zoomOut, zoomIn, fit} for the buttons. Returns its
 * parts: buttons, frame, root (the SVG), world (its zoomed group), layers (by name), screen
 * (its group in pixels), note, estop, label (the hover's), status.
 * @param {HTMLElement} host
 * @param {string} prefix
 * @param {{zoomOut: () => void, zoomIn: () => void, fit: () => void}} actions
 */
export function panel(host, prefix, actions) {
  const tools = element('div', 'matrix-tools');
  /**
   * @param {string} label
   * @param {string} title
   * @param {() => void} action
   * @param {string} [className]
   */
  const button = (label, title, action, className) => {
    const made = element('button', className ?? '', label);
    made.type = 'button';
    made.title = title;
    made.addEventListener('click', action);
    tools.append(made);
    return made;
  };
  const buttons = [button('−', 'zoom out (−)', actions.zoomOut), button('+', 'zoom in (+)', actions.zoomIn),
    button('fit', 'show the whole matrix (0)', actions.fit, 'matrix-fit')];
  tools.append(element('span', 'matrix-hint', 'wheel zooms · drag pans · click picks a yarn'));
  const frame = element('div', 'matrix-frame');
  frame.tabIndex = 0;
  const root = svg('svg', { class: 'matrix-svg', role: 'img' });
  const world = svg('g', { class: 'world' });
  const layers = /** @type {Layers} */ (Object.fromEntries(LAYERS.map((name) => [name, svg('g', { class: `layer-${name}` })])));
  for (const name of LAYERS) world.append(layers[name]);
  const screen = svg('g', { class: 'screen' });
  root.append(patterns(prefix), world, screen);
  const note = element('p', 'grid-empty');
  const estop = element('div', 'matrix-estop');
  estop.title = 'the emergency stop is pressed: no axis moves until it is released';
  estop.append(element('span', 'matrix-estop-sign', 'E-STOP'));
  const label = element('div', 'matrix-hover');
  label.hidden = true;
  frame.append(root, note, estop, label);
  const status = element('p', 'matrix-machine');
  status.setAttribute('aria-live', 'polite');
  host.replaceChildren(tools, frame, status, legend());
  return { buttons, frame, root, world, layers, screen, note, estop, label, status };
}

/**
 * @template {keyof HTMLElementTagNameMap} K
 * @param {K} tag
 * @param {string} className
 * @param {string} [text]
 * @returns {HTMLElementTagNameMap[K]}
 */
function element(tag, className, text) {
  const made = document.createElement(tag);
  if (className) made.className = className;
  if (text !== undefined) made.textContent = text;
  return made;
}

/** What the marks mean. */
function legend() {
  const box = element('div', 'matrix-legend');
  const entries = [
    ['moving', 'moves next'],
    ['differs', 'sensor ≠ twin (● sees a case, ○ sees none)'],
    ['faulted', 'axis fault'],
    ['weft', "next weft, at the guides' scale"],
    ['picked', 'picked yarn'],
  ];
  for (const [kind, text] of entries) {
    const item = element('span', `matrix-key key-${kind}`, text);
    item.dataset.key = kind;
    box.append(item);
  }
  return box;
}

/**
 * The line under the matrix, and whether it is an alarm: the e-stop, the faulted axes,
 * where the sensors differ (`twin(r, c)`: the twin's yarn in a cell), the next weft, the
 * picked yarn and its cell ({r, c} or null).
 * @param {MachineRead | null} machine
 * @param {(r: number, c: number) => number | null | undefined} twin the yarn id, -1 for none
 * @param {boolean} shown
 * @param {WeftInstruction | null} weft
 * @param {WeftCells | null} weftCells
 * @param {number | null} picked
 * @param {{r: number, c: number} | null} cell
 */
export function statusLine(machine, twin, shown, weft, weftCells, picked, cell) {
  const parts = [];
  let alarm = false;
  if (machine) {
    if (machine.estop) parts.push('E-STOP pressed');
    if (machine.faulted.length) parts.push(`faulted: ${machine.faulted.join(', ')}`);
    alarm = machine.estop || machine.faulted.length > 0 || machine.differs.length > 0;
    parts.push(describeDiffers(machine.differs, twin, shown));
  }
  if (weft) parts.push(weftCells ? describeWeft(weft, weftCells) : 'next weft: waiting for the matrix geometry');
  if (picked !== null) {
    parts.push(cell ? `yarn ${picked}: row ${cell.r}, col ${cell.c}` : `yarn ${picked} has no case on the matrix`);
  }
  return { text: parts.filter(Boolean).join(' · '), alarm };
}

/**
 * "sensors differ from the twin at (1, 2) case, (0, 0) empty": what each sensor reads.
 * @param {Cell[]} differs
 * @param {(r: number, c: number) => number | null | undefined} twin the yarn id, -1 for none
 * @param {boolean} shown
 */
function describeDiffers(differs, twin, shown) {
  if (!differs.length) return shown ? 'sensors agree with the twin' : '';
  if (differs.some(([r, c]) => r < 0 || c < 0)) return "the sensors' matrix is not the twin's size";
  const listed = differs.slice(0, 6).map(([r, c]) => `(${r}, ${c}) ${(twin(r, c) ?? -1) >= 0 ? 'empty' : 'case'}`);
  const more = differs.length > 6 ? ` and ${differs.length - 6} more` : '';
  return `sensors differ from the twin at ${listed.join(', ')}${more}`;
}

/**
 * "next weft: 0°, 60.775 mm, 10.5 mm above the fell (drawn ×1.81, at the guides' scale)".
 * @param {WeftInstruction} weft
 * @param {WeftCells} cells
 */
export function describeWeft(weft, cells) {
  /** @param {unknown} value */
  const number = (value, places = 3) => String(Number(Number(value).toFixed(places)));
  return `next weft: ${number(weft.angle)}°, ${number(weft.length)} mm, ${number(weft.z)} mm above the fell ` +
    `(drawn ×${number(1 / cells.fan, 2)}, at the guides' scale)`;
}
