// The machine matrix: rows × cols cells, row 0 at the top as in the program's FILL block,
// each cell showing the id of the warp whose case is in it, in that yarn's colour. The
// cells the next ROW/COL instruction moves (whole lines, or a segment's span of one) are
// highlighted, with an arrow and the step of each line.

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
   * Highlight the cells the next instruction moves: `instruction` is the next one
   * ({kind: "shift", axis, moves: [[line, k], ...]}, a move on a segment being
   * [line, k, first, last]) or anything else for none.
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
    const row = this.shift.axis === 'row';
    const [lines, along] = row ? [this.rows, this.cols] : [this.cols, this.rows];
    for (const [line, spans] of movesByLine(this.shift.moves, along)) {
      if (line < 0 || line >= lines) continue;
      for (const { first, last } of spans) this.highlights.append(this.band(row, line, first, last));
      this.arrows.append(...this.arrow(row, line, spans, along));
    }
  }

  /**
   * The highlight over cells first..last of a row or column. At an end inside the line it
   * stops at the last cell's edge, so two segments of one line show as two bands.
   */
  band(row, line, first, last) {
    const along = row ? this.cols : this.rows;
    const across = MARGIN + line * CELL - 1;
    const from = first === 0 ? MARGIN - 2 : MARGIN + first * CELL + 1;
    const to = last === along - 1 ? MARGIN + along * CELL + 2 : MARGIN + (last + 1) * CELL - 1;
    const length = to - from;
    const place = row
      ? { x: from, y: across, width: length, height: CELL + 2 }
      : { x: across, y: from, width: CELL + 2, height: length };
    return svg('rect', { ...place, class: 'moving', 'data-line': line, 'data-first': first, 'data-last': last });
  }

  /**
   * The arrow and step of one line, in the right margin (rows: → for +k, ← for -k) or
   * under the matrix (columns: ↓ for +k, towards higher rows, ↑ for -k). Segments of one
   * line moving opposite ways share a ⇄ or ⇅; the highlights show which cells go.
   */
  arrow(row, line, spans, along) {
    const steps = [...new Set(spans.map((span) => span.k))];
    const k = steps.length === 1 ? steps[0] : null;
    const step = k === null ? '±' : signed(k);
    const what = spans.map(({ first, last, k: each }) =>
      first === 0 && last === along - 1 ? `moves ${signed(each)}` : `cells ${first}..${last} move ${signed(each)}`);
    const title = svg('title', {}, `${row ? 'row' : 'column'} ${line}: ${what.join(', ')} along its ${row ? 'columns' : 'rows'}`);
    if (row) {
      const glyph = k === null ? '⇄' : k > 0 ? '→' : '←';
      const y = MARGIN + line * CELL + CELL / 2;
      const arrow = svg('text', { x: MARGIN + this.cols * CELL + 3, y, class: 'arrow row-arrow' }, `${glyph}\u2009${step}`);
      arrow.append(title);
      return [arrow];
    }
    const x = MARGIN + line * CELL + CELL / 2;
    const bottom = MARGIN + this.rows * CELL;
    const glyph = k === null ? '⇅' : k > 0 ? '↓' : '↑';
    const arrow = svg('text', { x, y: bottom + 11, class: 'arrow col-arrow' }, glyph);
    const label = svg('text', { x, y: bottom + 23, class: 'arrow col-arrow' }, step);
    label.append(title);
    return [arrow, label];
  }
}

/**
 * A shift's moves by line, in the order given: line -> [{k, first, last}], the cells each
 * move carries (a whole line is cells 0..along-1; a segment's span is clipped to the matrix).
 */
function movesByLine(moves, along) {
  const lines = new Map();
  for (const [line, k, first = 0, last = along - 1] of moves) {
    const span = { k, first: Math.max(0, first), last: Math.min(along - 1, last) };
    if (span.first > span.last) continue;
    if (!lines.has(line)) lines.set(line, []);
    lines.get(line).push(span);
  }
  return lines;
}
