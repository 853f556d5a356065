// @ts-check
// The machine matrix: rows × cols cells, row 0 at the top as in the program's FILL block,
// each cell showing the id of the warp whose case is in it, in that yarn's colour. Over the
// twin's picture: the lines the next shift moves (with an arrow and step each), the cells
// where the machine's occupancy sensors differ from the twin, the e-stop, the axes that
// report a fault, and the path of the next weft. Zoom (wheel, pinch, +/−), pan (drag,
// arrow keys) and fit; a click picks the yarn in a cell.

import { css, mix, textOn } from './colours.js';
import { CELL, arrow, band, differMark, faultMark, rulers, svg, weftPath } from './matrix-draw.js';
import { axisCells, differingCells, movesByLine, weftInCells } from './matrix-geometry.js';
import { describeWeft, panel, statusLine } from './matrix-panel.js';
import { ZoomPan } from './matrix-zoom.js';

export { signed } from './matrix-draw.js';

/** @import { Cell, Instruction, Machine, ShiftInstruction, WeftInstruction } from '../types/daemon' */
/** @import { Palette } from './colours.js' */
/** @import { LineMarks } from './matrix-draw.js' */
/** @import { Span, WeftCells } from './matrix-geometry.js' */
/** @import { MachineRead } from './matrix-panel.js' */

/**
 * A cell of the matrix: its SVG parts and the yarn shown in it (-1: none; null before the
 * first occupancy).
 * @typedef {{group: SVGElement, rect: SVGElement, text: SVGElement, title: SVGElement, yarn: number | null}} GridCell
 */

const FIT_CELL_PX = 44; // a small matrix stops growing at this cell size
const TOP = 14; // px: the column numbers
const BOTTOM = 28; // px: room under the matrix for the columns' arrows
const ARROWS = 40; // px: room right of the matrix for the rows' arrows...
const ROOMY_CELL_PX = 20; // ...kept while the cells stay at least this big
const ID_PX = 8.5; // the smallest id worth printing in a cell
const CALM = 0.6; // while the machine runs, the cells' colours this far towards white
const TALLEST_LESS = 280; // px of the window's height left to the bar and the panel's other lines
let grids = 0; // numbers each grid's hatch patterns

export class MatrixGrid {
  /**
   * @param {HTMLElement} host the element to draw in (#grid)
   * @param {Palette} palette the yarn colours (colours.js)
   */
  constructor(host, palette) {
    this.host = host;
    this.palette = palette;
    this.rows = 0;
    this.cols = 0;
    /** @type {GridCell[][]} [row][col] */
    this.cells = [];
    /** @type {ShiftInstruction | null} the next shift instruction */
    this.shift = null;
    /** @type {WeftInstruction | null} the next weft instruction */
    this.weft = null;
    /** @type {WeftCells | null} where the next weft runs, in cells */
    this.weftCells = null;
    /** @type {Machine | null} the skeleton JSON's `machine`: pitches and convergence */
    this.geometry = null;
    /** @type {MachineRead | null} the machine as last read */
    this.machine = null;
    /** @type {number | null} the highlighted yarn id */
    this.picked = null;
    this.running = false; // the machine runs: calm cells under the moving lines' outlines
    /** @type {((yarnId: number | null) => void) | null} set by the page */
    this.onPick = null;
    /** @type {{x: number, y: number} | null} the pointer over the frame, px */
    this.hover = null;
    this.frameRequested = false;
    /** @type {{rows: Map<number, Span[]>, cols: Map<number, Span[]>}} line -> spans, of the next shift */
    this.moving = { rows: new Map(), cols: new Map() };
    /** @type {LineMarks} line -> axis name */
    this.faultedLines = { rows: new Map(), cols: new Map() };
    /** @type {Set<string>} "r,c" of the cells whose sensor differs */
    this.differKeys = new Set();
    this.prefix = `matrix${(grids += 1)}`;
    const parts = panel(this.host, this.prefix, {
      zoomOut: () => this.view.zoomBy(1 / 1.5), zoomIn: () => this.view.zoomBy(1.5), fit: () => this.view.fit(),
    });
    this.buttons = parts.buttons;
    this.frame = parts.frame;
    this.root = parts.root;
    this.world = parts.world;
    this.layers = parts.layers;
    this.screen = parts.screen;
    this.note = parts.note;
    this.estop = parts.estop;
    this.label = parts.label;
    this.status = parts.status;
    this.highlights = this.layers.highlights;
    this.view = new ZoomPan(this.frame, {
      cell: CELL, maxCellPx: FIT_CELL_PX, onChange: () => this.schedule(),
      onTap: (x, y) => this.tap(x, y), onHover: (x, y) => this.pointAt(x, y),
    });
    this.frame.addEventListener('keydown', (event) => {
      if (event.key === 'Escape' && this.onPick) this.onPick(null);
    });
    new ResizeObserver(() => this.layout()).observe(this.frame);
    window.addEventListener('resize', () => this.layout()); // the tallest frame follows the window
    this.showEmpty('no program loaded');
  }

  /**
   * No matrix to show: a line of text instead.
   * @param {string} text
   */
  showEmpty(text) {
    this.rows = this.cols = 0;
    this.cells = [];
    for (const layer of Object.values(this.layers)) layer.replaceChildren();
    this.screen.replaceChildren();
    this.note.textContent = text;
    this.frame.classList.add('empty');
    this.root.setAttribute('aria-label', text);
    for (const each of this.buttons) each.disabled = true;
    this.frame.style.height = '';
    this.drawStatus();
  }

  /**
   * Build the cells for a rows × cols matrix (only when the size changes).
   * @param {number} rows
   * @param {number} cols
   */
  build(rows, cols) {
    this.rows = rows;
    this.cols = cols;
    this.differKeys = differingCells(this.machine?.differs, rows, cols);
    this.frame.classList.remove('empty');
    for (const each of this.buttons) each.disabled = false;
    this.root.setAttribute('aria-label', `machine matrix, ${rows} rows × ${cols} columns, row 0 at the top`);
    this.cells = [];
    const group = this.layers.cells;
    group.replaceChildren();
    for (let r = 0; r < rows; r += 1) {
      /** @type {GridCell[]} */
      const row = [];
      for (let c = 0; c < cols; c += 1) {
        const cell = svg('g', { class: 'cell empty', 'data-row': r, 'data-col': c });
        const rect = svg('rect', { x: c * CELL, y: r * CELL, width: CELL, height: CELL });
        const text = svg('text', { x: (c + 0.5) * CELL, y: (r + 0.5) * CELL });
        const title = svg('title', {}, `row ${r}, col ${c}: empty`);
        cell.append(rect, text, title);
        group.append(cell);
        row.push({ group: cell, rect, text, title, yarn: null });
      }
      this.cells.push(row);
    }
    this.view.fitted = true;
    this.layout();
  }

  /**
   * Show `occupancy` (rows arrays of cols yarn ids, -1 empty); only changed cells are touched.
   * @param {number[][]} occupancy
   */
  setOccupancy(occupancy) {
    const rows = occupancy.length;
    const cols = rows ? occupancy[0].length : 0;
    const built = rows !== this.rows || cols !== this.cols;
    if (built) {
      this.build(rows, cols);
      this.drawWeft();
    }
    let changed = built;
    for (let r = 0; r < rows; r += 1) {
      for (let c = 0; c < cols; c += 1) {
        const yarn = occupancy[r][c];
        const cell = this.cells[r][c];
        if (cell.yarn === yarn) continue;
        cell.yarn = yarn;
        changed = true;
        this.paint(cell, r, c);
      }
    }
    if (!changed) return;
    const most = Math.max(0, ...occupancy.map((line) => Math.max(...line)));
    this.layers.cells.style.fontSize = `${Math.min(13, 19 / (0.62 * String(most).length))}px`; // the widest id fits
    this.drawShift();
    this.drawMachine(); // the sensors' side of a cell depends on the twin's
    this.drawPicked();
  }

  /**
   * @param {GridCell} cell
   * @param {number} r
   * @param {number} c
   */
  paint(cell, r, c) {
    const yarn = cell.yarn;
    const sensor = this.sensorNote(r, c);
    if (yarn === null || yarn < 0) {
      cell.group.setAttribute('class', 'cell empty');
      cell.group.removeAttribute('data-yarn');
      cell.rect.removeAttribute('style');
      cell.text.textContent = '';
      cell.title.textContent = `row ${r}, col ${c}: empty${sensor}`;
      return;
    }
    const own = this.palette.colour(yarn);
    const colour = this.running && yarn !== this.picked ? mix(own, 0xffffff, CALM) : own;
    cell.group.setAttribute('class', yarn === this.picked ? 'cell picked' : 'cell');
    cell.group.setAttribute('data-yarn', String(yarn));
    cell.rect.style.fill = css(colour);
    cell.text.style.fill = textOn(colour);
    cell.text.textContent = String(yarn);
    cell.title.textContent = `row ${r}, col ${c}: yarn ${yarn}${sensor}`;
  }

  /** The colours changed (colour mode): repaint every cell. */
  repaint() {
    this.cells.forEach((row, r) => row.forEach((cell, c) => this.paint(cell, r, c)));
  }

  /**
   * Whether the machine runs: then the cells are drawn in calm tints of their colours, so
   * that the outlined lines of the instruction under way stand out.
   * @param {boolean} running
   */
  setRunning(running) {
    if (running === this.running) return;
    this.running = running;
    this.frame.classList.toggle('running', running);
    this.repaint();
  }

  // ----- the next instruction -----

  /**
   * Show the next instruction: a shift ({kind: "shift", axis, moves: [[line, k], ...], a
   * move on a segment being [line, k, first, last]) highlights the cells it moves; a weft
   * shows its path as setNextWeft does; anything else, neither.
   * @param {Instruction | null} instruction
   */
  setNext(instruction) {
    this.shift = instruction && instruction.kind === 'shift' ? instruction : null;
    this.drawShift();
    this.setNextWeft(instruction && instruction.kind === 'weft' ? instruction : null);
  }

  drawShift() {
    this.highlights.replaceChildren();
    this.moving = { rows: new Map(), cols: new Map() };
    if (this.shift && this.rows) {
      const row = this.shift.axis === 'row';
      const [lines, along] = row ? [this.rows, this.cols] : [this.cols, this.rows];
      for (const [line, spans] of movesByLine(this.shift.moves, along)) {
        if (line < 0 || line >= lines) continue;
        for (const { first, last } of spans) this.highlights.append(band(row, line, first, last));
        (row ? this.moving.rows : this.moving.cols).set(line, spans);
      }
    }
    this.schedule();
  }

  /**
   * The next weft ({kind: "weft", x, y, z, angle, length}) drawn over the matrix, or null.
   * @param {Instruction | null} instruction
   */
  setNextWeft(instruction) {
    const weft = instruction && instruction.kind === 'weft' ? instruction : null;
    if (JSON.stringify(weft) === JSON.stringify(this.weft)) return; // asked again every frame
    this.weft = weft;
    this.drawWeft();
  }

  /**
   * The machine's geometry (the skeleton JSON's `machine`): the weft needs its pitches.
   * @param {Machine | null | undefined} machine
   */
  setGeometry(machine) {
    if (machine === this.geometry) return;
    this.geometry = machine ?? null;
    this.drawWeft();
  }

  drawWeft() {
    const layer = this.layers.weft;
    layer.replaceChildren();
    this.weftCells = this.rows ? weftInCells(this.weft, this.geometry) : null;
    if (this.weft && this.weftCells) layer.append(weftPath(this.weftCells, describeWeft(this.weft, this.weftCells)));
    this.drawStatus();
  }

  // ----- the machine as read -----

  /**
   * The machine as the controller last read it (`/state`'s `bus`): `differs` the cells
   * [row, col] where the occupancy sensors differ from the twin, `estop` pressed,
   * `faulted` the names of the axes reporting a fault; null when not known.
   * @param {{differs?: Cell[], estop?: boolean, faulted?: string[]} | null} machine
   */
  setMachine(machine) {
    const next = machine ? { differs: machine.differs ?? [], estop: Boolean(machine.estop), faulted: machine.faulted ?? [] } : null;
    if (JSON.stringify(next) === JSON.stringify(this.machine)) return;
    this.machine = next;
    this.differKeys = differingCells(next?.differs, this.rows, this.cols);
    this.drawMachine();
    this.repaint(); // the sensors' reading in each cell's tooltip
  }

  drawMachine() {
    const { differs, faults } = this.layers;
    differs.replaceChildren();
    faults.replaceChildren();
    this.faultedLines = { rows: new Map(), cols: new Map() };
    const machine = this.machine;
    this.frame.classList.toggle('estop', Boolean(machine?.estop));
    if (machine && this.rows) {
      for (const key of this.differKeys) {
        const [r, c] = key.split(',').map(Number);
        const twin = this.cells[r][c].yarn ?? -1;
        const sees = !(twin >= 0);
        differs.append(differMark(this.prefix, r, c, sees, `row ${r}, col ${c}: twin ${twin >= 0 ? `yarn ${twin}` : 'empty'}${this.sensorNote(r, c)}`));
      }
      for (const name of machine.faulted) {
        const cells = axisCells(name, this.rows, this.cols);
        if (!cells) continue;
        faults.append(faultMark(this.prefix, name, cells));
        (cells.axis === 'row' ? this.faultedLines.rows : this.faultedLines.cols).set(cells.line, name);
      }
    }
    this.drawStatus();
    this.schedule();
  }

  /**
   * ", sensor: empty (the twin differs)" for a cell whose sensor disagrees; "" otherwise.
   * @param {number} r
   * @param {number} c
   */
  sensorNote(r, c) {
    if (!this.differKeys.has(`${r},${c}`)) return '';
    const twin = this.cells[r]?.[c]?.yarn ?? -1;
    return ` — sensor: ${twin >= 0 ? 'empty' : 'case'} (differs from the twin)`;
  }

  // ----- picking -----

  /**
   * Outline the cell of yarn `yarnId` and dim the rest; null: no highlight.
   * @param {number | null} yarnId
   */
  highlight(yarnId) {
    this.picked = yarnId ?? null;
    this.repaint();
    const cell = this.drawPicked();
    if (cell) this.bringIntoView(cell.r, cell.c);
  }

  drawPicked() {
    const marks = this.layers.marks;
    marks.querySelector('.picked-edge')?.remove();
    const cell = this.picked === null ? null : this.cellOf(this.picked);
    this.frame.classList.toggle('picking', cell !== null); // a weft has no cell: nothing dims
    if (cell) marks.append(svg('rect', { x: cell.c * CELL, y: cell.r * CELL, width: CELL, height: CELL, class: 'picked-edge', 'data-row': cell.r, 'data-col': cell.c }));
    this.drawStatus();
    return cell;
  }

  /**
   * @param {number} yarn
   * @returns {{r: number, c: number} | null}
   */
  cellOf(yarn) {
    for (let r = 0; r < this.rows; r += 1) {
      for (let c = 0; c < this.cols; c += 1) if (this.cells[r][c].yarn === yarn) return { r, c };
    }
    return null;
  }

  /**
   * @param {number} r
   * @param {number} c
   */
  bringIntoView(r, c) {
    const [x, y] = this.view.toPixels((c + 0.5) * CELL, (r + 0.5) * CELL);
    const { left, top, bottom } = this.view.insets;
    if (x >= left && x <= this.view.width && y >= top && y <= this.view.height - bottom) return;
    this.view.panBy((left + this.view.width) / 2 - x, (top + this.view.height - bottom) / 2 - y);
  }

  /**
   * The cell under element pixels (x, y): {r, c}, or null outside the matrix.
   * @param {number} x
   * @param {number} y
   */
  cellAt(x, y) {
    const { left, top } = this.view.insets;
    if (!this.rows || x < left || y < top) return null;
    const [u, v] = this.view.toUnits(x, y);
    const c = Math.floor(u / CELL);
    const r = Math.floor(v / CELL);
    return r >= 0 && c >= 0 && r < this.rows && c < this.cols ? { r, c } : null;
  }

  /**
   * @param {number} x
   * @param {number} y
   */
  tap(x, y) {
    const cell = this.cellAt(x, y);
    if (!cell || !this.onPick) return;
    const yarn = this.cells[cell.r][cell.c].yarn ?? -1;
    this.onPick(yarn >= 0 ? yarn : null);
  }

  /**
   * @param {number | null} x
   * @param {number} [y]
   */
  pointAt(x, y) {
    this.hover = x === null || x === undefined || y === undefined ? null : { x, y };
    this.schedule();
  }

  // ----- layout and drawing in pixels -----

  /** Size the frame to the matrix at fit (the panel's width decides), and fit it again. */
  layout() {
    const width = this.frame.clientWidth;
    if (!this.rows || !width) return;
    const left = this.rows > 100 ? 20 : 14; // px: the row numbers (9 px digits)
    const tallest = Math.max(220, window.innerHeight - TALLEST_LESS); // the panel's other lines in view too
    // Room right of the matrix for the rows' arrows, unless the cells would be too small for it.
    const right = (width - left - ARROWS) / this.cols >= ROOMY_CELL_PX ? ARROWS : 0;
    const px = Math.min(FIT_CELL_PX, (width - left - right) / this.cols, (tallest - TOP - BOTTOM) / this.rows);
    const height = Math.ceil(TOP + this.rows * px + BOTTOM);
    if (this.frame.style.height !== `${height}px`) this.frame.style.height = `${height}px`;
    this.view.setContent(this.cols * CELL, this.rows * CELL, { left, top: TOP, right, bottom: BOTTOM });
    this.view.resize(width, height);
  }

  schedule() {
    if (this.frameRequested) return;
    this.frameRequested = true;
    requestAnimationFrame(() => {
      this.frameRequested = false;
      this.render();
    });
  }

  /** What depends on the zoom: the transform, the ids, the rulers, the arrows, the hover. */
  render() {
    this.screen.replaceChildren();
    if (!this.rows) return;
    const view = this.view;
    this.world.setAttribute('transform', `translate(${view.tx} ${view.ty}) scale(${view.scale})`);
    const fontPx = parseFloat(this.layers.cells.style.fontSize || '13') * view.scale;
    this.frame.classList.toggle('ids-hidden', fontPx < ID_PX);
    this.frame.dataset.cellPx = view.cellPx.toFixed(2);
    const cell = this.hover ? this.cellAt(this.hover.x, this.hover.y) : null;
    const marks = { rows: new Map(), cols: new Map() };
    for (const [line] of this.moving.rows) marks.rows.set(line, 'line-moving');
    for (const [line] of this.moving.cols) marks.cols.set(line, 'line-moving');
    for (const [line] of this.faultedLines.rows) marks.rows.set(line, 'line-faulted');
    for (const [line] of this.faultedLines.cols) marks.cols.set(line, 'line-faulted');
    if (cell) {
      marks.rows.set(cell.r, 'line-hover');
      marks.cols.set(cell.c, 'line-hover');
    }
    const sizes = view.insets;
    const arrows = svg('g', { class: 'arrows' });
    for (const [line, spans] of this.moving.rows) arrows.append(...[arrow(view, true, line, spans, this.cols, sizes)].filter((a) => a !== null));
    for (const [line, spans] of this.moving.cols) arrows.append(...[arrow(view, false, line, spans, this.rows, sizes)].filter((a) => a !== null));
    this.screen.append(arrows, rulers(view, this.rows, this.cols, sizes, marks));
    this.drawHover(cell);
  }

  /** @param {{r: number, c: number} | null} cell */
  drawHover(cell) {
    const marks = this.layers.marks;
    marks.querySelector('.hover-edge')?.remove();
    if (!cell || !this.hover) {
      this.label.hidden = true;
      return;
    }
    marks.append(svg('rect', { x: cell.c * CELL, y: cell.r * CELL, width: CELL, height: CELL, class: 'hover-edge' }));
    const yarn = this.cells[cell.r][cell.c].yarn ?? -1;
    this.label.textContent = `row ${cell.r}, col ${cell.c}: ${yarn >= 0 ? `yarn ${yarn}` : 'empty'}${this.sensorNote(cell.r, cell.c)}`;
    this.label.hidden = false;
    const room = this.view.width - this.label.offsetWidth - 4;
    this.label.style.left = `${Math.max(2, Math.min(room, this.hover.x + 14))}px`;
    const tall = this.label.offsetHeight;
    this.label.style.top = `${this.hover.y + 16 + tall > this.view.height ? this.hover.y - tall - 8 : this.hover.y + 16}px`;
  }

  /** The line under the matrix: e-stop, faulted axes, differing sensors, the weft, the pick. */
  drawStatus() {
    const cell = this.picked !== null && this.rows ? this.cellOf(this.picked) : null;
    /**
     * @param {number} r
     * @param {number} c
     */
    const twin = (r, c) => this.cells[r]?.[c]?.yarn;
    const { text, alarm } = statusLine(this.machine, twin, this.rows > 0, this.weft, this.weftCells, this.picked, cell);
    this.status.textContent = text;
    this.status.dataset.alarm = String(alarm);
  }
}
