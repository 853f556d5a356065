// @ts-check
// The matrix's marks as SVG: the cells' overlays in the drawing's units (CELL per cell,
// row 0 at the top), and the rulers and move arrows in the element's pixels, laid out
// again whenever the view zooms or pans.

/** @import { AxisCells, Span, WeftCells } from './matrix-geometry.js' */
/** @import { ZoomPan } from './matrix-zoom.js' */

/** @typedef {{rows: Map<number, string>, cols: Map<number, string>}} LineMarks line -> class */

// The SVG namespace, as the HTML parser gives it (so no address appears in the page's files).
export const SVG_NS = (() => {
  const holder = document.createElement('div');
  holder.innerHTML = '<svg></svg>';
  return holder.firstElementChild?.namespaceURI ?? null;
})();
export const CELL = 24; // drawing units per cell

/**
 * An SVG element with these attributes and text.
 * @param {string} tag
 * @param {Record<string, string | number>} [attributes]
 * @param {string} [text]
 * @returns {SVGElement}
 */
export function svg(tag, attributes = {}, text) {
  // An element of SVG_NS, the SVG namespace, is an SVGElement.
  const element = /** @type {SVGElement} */ (document.createElementNS(SVG_NS, tag));
  for (const [name, value] of Object.entries(attributes)) element.setAttribute(name, String(value));
  if (text !== undefined) element.textContent = text;
  return element;
}

/**
 * A step with its sign, as the program writes it: +1, -2.
 * @param {number} k
 */
export function signed(k) {
  return k > 0 ? `+${k}` : String(k);
}

/**
 * The hatches the marks fill with (ids made unique per grid: a page may hold two).
 * @param {string} prefix
 */
export function patterns(prefix) {
  const defs = svg('defs');
  for (const [name, colour] of [['differs', '#c53030'], ['faulted', '#9b2c2c']]) {
    const pattern = svg('pattern', { id: `${prefix}-${name}`, width: 6, height: 6, patternUnits: 'userSpaceOnUse', patternTransform: 'rotate(45)' });
    pattern.append(svg('rect', { width: 1.8, height: 6, fill: colour }));
    defs.append(pattern);
  }
  return defs;
}

/**
 * The rectangle, in units, over cells first..last of a row or column.
 * @param {boolean} row
 * @param {number} line
 * @param {number} first
 * @param {number} last
 */
export function span(row, line, first, last, inset = 0) {
  const from = first * CELL + inset;
  const length = (last - first + 1) * CELL - 2 * inset;
  const across = line * CELL + inset;
  const breadth = CELL - 2 * inset;
  return row ? { x: from, y: across, width: length, height: breadth } : { x: across, y: from, width: breadth, height: length };
}

/**
 * The outline of a line's cells first..last that move next (two segments: two bands), on
 * the cells' edges: neighbouring lines that both move share one stroke.
 * @param {boolean} row
 * @param {number} line
 * @param {number} first
 * @param {number} last
 */
export function band(row, line, first, last) {
  return svg('rect', { ...span(row, line, first, last), class: 'moving', 'data-axis': row ? 'row' : 'col', 'data-line': line, 'data-first': first, 'data-last': last });
}

/** A faulted shift axis over the cells it drives ({axis, line, first, last} of axisCells);
 * `prefix` names the grid's hatch patterns.
 * @param {string} prefix
 * @param {string} name
 * @param {AxisCells} cells
 */
export function faultMark(prefix, name, cells) {
  const group = svg('g', { class: 'faulted', 'data-axis': name, 'data-line': cells.line, 'data-first': cells.first, 'data-last': cells.last });
  const place = span(cells.axis === 'row', cells.line, cells.first, cells.last, 1);
  group.append(svg('rect', { ...place, class: 'faulted-hatch', fill: `url(#${prefix}-faulted)` }), svg('rect', { ...place, class: 'faulted-edge' }),
    svg('title', {}, `axis ${name} reports a fault`));
  return group;
}

/**
 * A cell whose sensor differs from the twin: hatched, outlined, and a badge in its corner,
 * a red disc where the sensor sees a case the twin does not have, a ring where it sees none.
 * @param {string} prefix
 * @param {number} r
 * @param {number} c
 * @param {boolean} sensorSeesCase
 * @param {string} title
 */
export function differMark(prefix, r, c, sensorSeesCase, title) {
  const group = svg('g', { class: 'differs', 'data-row': r, 'data-col': c, 'data-sensor': sensorSeesCase ? 'case' : 'empty' });
  const place = { x: c * CELL + 1, y: r * CELL + 1, width: CELL - 2, height: CELL - 2 };
  const badge = { cx: (c + 1) * CELL - 6.5, cy: r * CELL + 6.5, r: 4.5 };
  group.append(svg('rect', { ...place, class: 'differs-hatch', fill: `url(#${prefix}-differs)` }), svg('rect', { ...place, class: 'differs-edge' }),
    svg('circle', { ...badge, class: sensorSeesCase ? 'sensor-case' : 'sensor-empty' }), svg('title', {}, title));
  return group;
}

/**
 * The next weft's path over the matrix, from weftInCells (cells -> units at their centres).
 * @param {WeftCells} cells
 * @param {string} title
 */
export function weftPath(cells, title) {
  /** @param {number[]} cell [col, row] */
  const point = ([col, row]) => [(col + 0.5) * CELL, (row + 0.5) * CELL];
  const [x1, y1] = point(cells.from);
  const [x2, y2] = point(cells.to);
  const [cx, cy] = point(cells.centre);
  /** @param {number} value */
  const fmt = (value) => String(Number(value.toFixed(3)));
  const group = svg('g', { class: 'weft-path', 'data-from': cells.from.map(fmt).join(','), 'data-to': cells.to.map(fmt).join(',') });
  const line = { x1, y1, x2, y2 };
  group.append(svg('line', { ...line, class: 'weft-halo' }), svg('line', { ...line, class: 'weft-line' }),
    svg('circle', { cx: x1, cy: y1, r: 3, class: 'weft-end' }), svg('circle', { cx: x2, cy: y2, r: 3, class: 'weft-end' }),
    svg('circle', { cx, cy, r: 2, class: 'weft-centre' }), svg('title', {}, title));
  return group;
}

// ----- in pixels: rulers and arrows -----

const NICE = [1, 2, 5, 10, 20, 50, 100, 200, 500];

/**
 * Every how many lines a ruler can number when lines are `px` apart.
 * @param {number} px
 * @param {number} room
 */
function every(px, room) {
  return NICE.find((n) => n * px >= room) ?? NICE[NICE.length - 1];
}

/**
 * The line numbers along the top (columns) and down the left (rows), where the view puts
 * them; `marks` names lines to show whatever the spacing: {rows: Map, cols: Map} of line ->
 * class ("line-moving", "line-faulted", "line-hover").
 * @param {ZoomPan} view
 * @param {number} rows
 * @param {number} cols
 * @param {ZoomPan['insets']} sizes
 * @param {LineMarks} marks
 */
export function rulers(view, rows, cols, sizes, marks) {
  const { left, top } = sizes;
  const group = svg('g', { class: 'rulers' });
  // A ruler sits beside the matrix, or at the view's edge once the matrix passes under it.
  const [x0, y0] = view.toPixels(0, 0);
  const rowsAt = Math.max(left, x0) - 3;
  const colsAt = Math.max(top, y0) - top / 2;
  if (y0 <= top + 1) group.append(svg('rect', { x: 0, y: 0, width: view.width, height: top, class: 'ruler-bg' }));
  if (x0 <= left + 1) group.append(svg('rect', { x: 0, y: 0, width: left, height: view.height, class: 'ruler-bg' }));
  const px = view.cellPx;
  /**
   * @param {number} count
   * @param {number} step
   * @param {Map<number, string>} marked
   * @param {(i: number) => Record<string, number> | null} place
   */
  const put = (count, step, marked, place) => {
    for (let i = 0; i < count; i += 1) {
      const mark = marked.get(i);
      if (i % step && !mark) continue;
      const at = place(i);
      if (at === null) continue;
      group.append(svg('text', { ...at, class: `axis ${mark ?? ''}`.trim() }, String(i)));
    }
  };
  put(cols, every(px, 16), marks.cols, (c) => {
    const [x] = view.toPixels((c + 0.5) * CELL, 0);
    return x < left || x > view.width ? null : { x, y: colsAt, 'data-col': c };
  });
  put(rows, every(px, 12), marks.rows, (r) => {
    const [, y] = view.toPixels(0, (r + 0.5) * CELL);
    return y < top || y > view.height ? null : { x: rowsAt, y, 'data-row': r };
  });
  if (x0 <= left + 1 || y0 <= top + 1) group.append(svg('rect', { x: 0, y: 0, width: left, height: top, class: 'ruler-corner' }));
  return group;
}

/**
 * The arrow and step of one line that moves next: right of a row (→ for +k, ← for -k),
 * under a column (↓ for +k, towards higher rows, ↑ for -k), inside the view's edge when
 * the matrix fills it. Segments of one line moving opposite ways share a ⇄ or ⇅; the
 * highlights show which cells go. Null when the line is out of view.
 * @param {ZoomPan} view
 * @param {boolean} row
 * @param {number} line
 * @param {Span[]} spans
 * @param {number} along
 * @param {ZoomPan['insets']} sizes
 */
export function arrow(view, row, line, spans, along, sizes) {
  const steps = [...new Set(spans.map((each) => each.k))];
  const k = steps.length === 1 ? steps[0] : null;
  const step = k === null ? '±' : signed(k);
  const what = spans.map(({ first, last, k: each }) =>
    first === 0 && last === along - 1 ? `moves ${signed(each)}` : `cells ${first}..${last} move ${signed(each)}`);
  const title = svg('title', {}, `${row ? 'row' : 'column'} ${line}: ${what.join(', ')} along its ${row ? 'columns' : 'rows'}`);
  const group = svg('g', { class: 'arrow-tag', 'data-line': line });
  if (row) {
    const glyph = k === null ? '⇄' : k > 0 ? '→' : '←';
    const [end, y] = view.toPixels(along * CELL, (line + 0.5) * CELL);
    if (y < sizes.top || y > view.height) return null;
    // Beside the row when there is room; else the glyph alone, inside the view's edge.
    const full = 8 + 6.7 * (2 + step.length);
    const room = end + 3 + full <= view.width;
    const label = room ? `${glyph}\u2009${step}` : glyph;
    const width = room ? full : 13;
    const x = room ? end + 3 : Math.min(end + 2, view.width - width - 1);
    const text = svg('text', { x: x + width / 2, y, class: 'arrow row-arrow' }, label);
    text.append(title);
    group.append(svg('rect', { x, y: y - 7.5, width, height: 15, rx: 3, class: 'arrow-pill' }), text);
    if (!room) group.classList.add('tight');
    return group;
  }
  const glyph = k === null ? '⇅' : k > 0 ? '↓' : '↑';
  const width = Math.max(14, 7 * step.length + 4);
  const [x, end] = view.toPixels((line + 0.5) * CELL, along * CELL);
  if (x < sizes.left || x > view.width) return null;
  const y = Math.min(end + 2, view.height - 25);
  const label = svg('text', { x, y: y + 18, class: 'arrow col-arrow' }, step);
  label.append(title);
  group.append(svg('rect', { x: x - width / 2, y, width, height: 24, rx: 3, class: 'arrow-pill' }),
    svg('text', { x, y: y + 7, class: 'arrow col-arrow' }, glyph), label);
  return group;
}
