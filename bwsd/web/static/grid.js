// The machine matrix: rows × cols cells, row 0 at the top as in the program's FILL block,
// each cell showing the id of the warp whose case is in it, in that yarn's colour. The
// line(s) the next ROW/COL instruction moves are highlighted with an arrow and their step.

import { css, textOn } from './colours.js';

// The SVG namespace, as the HTML parser gives it (so no address appears in the page's files).
const SVG = (() => {
  const holder = document.createElement('div');
  holder.innerHTML = '<svg></svg>';
  return holder.firstChild.namespaceURI;
})();
const CELL = 24; // user units per cell (the SVG scales to the panel)
const MARGIN = 30; // around the cells: line numbers on the top/left, move arrows on the right/bottom

function svg(tag, attributes = {}, text) {
  const element = document.createElementNS(SVG, tag);
  for (const [name, value] of Object.entries(attributes)) element.setAttribute(name, value);
  if (text !== undefined) element.textContent = text;
  return element;
}

/** A step with its sign, as the program writes it: +1, -2. */
export function signed(k) {
  return k > 0 ? `+${k}` : String(k);
}

export class MatrixGrid {
  /**
   * @param host the element to draw in (#grid)
   * @param palette the yarn colours (colours.js)
   */
  constructor(host, palette) {
    this.host = host;
    this.palette = palette;
    this.rows = 0;
    this.cols = 0;
    this.cells = []; // [row][col] -> {rect, text, yarn}
    this.shift = null; // the next shift instruction, or null
    this.showEmpty('no program loaded');
  }

  /** No matrix to show: a line of text instead. */
  showEmpty(text) {
    this.rows = this.cols = 0;
    this.cells = [];
    const note = document.createElement('p');
    note.className = 'grid-empty';
    note.textContent = text;
    this.host.replaceChildren(note);
  }

  /** Build the cells for a rows × cols matrix (only when the size changes). */
  build(rows, cols) {
    this.rows = rows;
    this.cols = cols;
    const width = cols * CELL + 2 * MARGIN;
    const height = rows * CELL + 2 * MARGIN;
    const root = svg('svg', {
      viewBox: `0 0 ${width} ${height}`,
      role: 'img',
      'aria-label': `machine matrix, ${rows} rows × ${cols} columns, row 0 at the top`,
    });
    // Line numbers: columns along the top, rows down the left.
    const every = Math.max(1, Math.ceil(Math.max(rows, cols) / 13)); // keep the numbers legible
    for (let c = 0; c < cols; c += every) {
      root.append(svg('text', { x: MARGIN + (c + 0.5) * CELL, y: MARGIN - 8, class: 'axis' }, String(c)));
    }
    for (let r = 0; r < rows; r += every) {
      root.append(svg('text', { x: MARGIN - 6, y: MARGIN + (r + 0.5) * CELL, class: 'axis row-number' }, String(r)));
    }
    this.highlights = svg('g', { class: 'highlights' });
    root.append(this.highlights);
    const cellGroup = svg('g', { class: 'cells' });
    this.cells = [];
    for (let r = 0; r < rows; r += 1) {
      const row = [];
      for (let c = 0; c < cols; c += 1) {
        const cell = svg('g', { class: 'cell empty', 'data-row': r, 'data-col': c });
        const x = MARGIN + c * CELL;
        const y = MARGIN + r * CELL;
        const rect = svg('rect', { x: x + 1, y: y + 1, width: CELL - 2, height: CELL - 2, rx: 3 });
        const text = svg('text', { x: x + CELL / 2, y: y + CELL / 2 });
        const title = svg('title', {}, `row ${r}, col ${c}: empty`);
        cell.append(rect, text, title);
        cellGroup.append(cell);
        row.push({ group: cell, rect, text, title, yarn: null });
      }
      this.cells.push(row);
    }
    root.append(cellGroup);
    this.arrows = svg('g', { class: 'arrows' });
    root.append(this.arrows);
    root.style.maxWidth = `${width * 1.6}px`; // a small matrix stays a sensible size
    this.host.replaceChildren(root);
  }

  /** Show `occupancy` (rows arrays of cols yarn ids, -1 empty); only changed cells are touched. */
  setOccupancy(occupancy) {
    const rows = occupancy.length;
    const cols = rows ? occupancy[0].length : 0;
    if (rows !== this.rows || cols !== this.cols) {
      this.build(rows, cols);
      this.drawShift();
    }
    for (let r = 0; r < rows; r += 1) {
      for (let c = 0; c < cols; c += 1) {
        const yarn = occupancy[r][c];
        const cell = this.cells[r][c];
        if (cell.yarn === yarn) continue;
        cell.yarn = yarn;
        this.paint(cell, r, c);
      }
    }
  }

  paint(cell, r, c) {
    const yarn = cell.yarn;
    if (yarn === null || yarn < 0) {
      cell.group.setAttribute('class', 'cell empty');
      cell.group.removeAttribute('data-yarn');
      cell.rect.removeAttribute('style');
      cell.text.textContent = '';
      cell.title.textContent = `row ${r}, col ${c}: empty`;
      return;
    }
    const colour = this.palette.colour(yarn);
    cell.group.setAttribute('class', 'cell');
    cell.group.setAttribute('data-yarn', yarn);
    cell.rect.style.fill = css(colour);
    cell.text.style.fill = textOn(colour);
    cell.text.textContent = String(yarn);
    cell.title.textContent = `row ${r}, col ${c}: yarn ${yarn}`;
  }

  /** The colours changed (colour mode): repaint every cell. */
  repaint() {
    this.cells.forEach((row, r) => row.forEach((cell, c) => this.paint(cell, r, c)));
  }

  /**
   * Highlight the lines the next instruction moves: `instruction` is the next one
   * ({kind: "shift", axis, moves: [[line, k], ...]}) or anything else for none.
   */
  setNext(instruction) {
    this.shift = instruction && instruction.kind === 'shift' ? instruction : null;
    this.drawShift();
  }

  drawShift() {
    if (!this.highlights) return;
    this.highlights.replaceChildren();
    this.arrows.replaceChildren();
    if (!this.shift || !this.rows) return;
    const { axis, moves } = this.shift;
    const gridRight = MARGIN + this.cols * CELL;
    const gridBottom = MARGIN + this.rows * CELL;
    for (const [line, k] of moves) {
      if (axis === 'row') {
        // Row `line` moves along its columns: → for +k, ← for -k, in the right margin.
        if (line < 0 || line >= this.rows) continue;
        const y = MARGIN + line * CELL;
        this.highlights.append(svg('rect', { x: MARGIN - 2, y: y - 1, width: this.cols * CELL + 4, height: CELL + 2, class: 'moving' }));
        const arrow = svg('text', { x: gridRight + 3, y: y + CELL / 2, class: 'arrow row-arrow' }, `${k > 0 ? '→' : '←'}\u2009${signed(k)}`);
        arrow.append(svg('title', {}, `row ${line} moves ${signed(k)} along its columns`));
        this.arrows.append(arrow);
      } else {
        // Column `line` moves along its rows: ↓ for +k (towards higher rows), ↑ for -k.
        if (line < 0 || line >= this.cols) continue;
        const x = MARGIN + line * CELL;
        this.highlights.append(svg('rect', { x: x - 1, y: MARGIN - 2, width: CELL + 2, height: this.rows * CELL + 4, class: 'moving' }));
        const arrow = svg('text', { x: x + CELL / 2, y: gridBottom + 11, class: 'arrow col-arrow' }, k > 0 ? '↓' : '↑');
        const step = svg('text', { x: x + CELL / 2, y: gridBottom + 23, class: 'arrow col-arrow' }, signed(k));
        step.append(svg('title', {}, `column ${line} moves ${signed(k)} along its rows`));
        this.arrows.append(arrow, step);
      }
    }
  }
}
