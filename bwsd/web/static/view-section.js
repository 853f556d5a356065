// @ts-check
// The cross-section at a height z, drawn as `bwsd slice` draws it: a 2D view with x and y
// in mm at equal scale (x to the right, y down: row 0 of the matrix at the top, as the
// Matrix panel, the top view and `bwsd slice` draw it), every crossing a circle of the yarn
// diameter, filled with a dark rim where the yarn is laid (a fixed segment), open where it
// is a warp's free segment (a dot and a cross when the model has no diameter); wefts lying
// within half a diameter of the plane as strips. The section's nominal cells (the
// program's "# section:" line), mapped to the fell, are shaded underneath. Colours are the
// 3D view's. Also the marks of the section in the 3D view: the plane and its crossings.

import * as THREE from 'three';

import { css } from './colours.js';
import { bandCorners, fellXY, sliceLimits } from './section.js';
import { niceStep } from './view-axes.js';
import { discTexture, mmPointsMaterial } from './view-batches.js';

/** @import { Machine } from '../types/daemon' */
/** @import { Band, Crossing } from './section.js' */

/**
 * What the section view draws: the crossings and strips, the machine, the diameter, the
 * height and the take-up, the colours, and the nominal section's cells and spec (or none).
 * @typedef {object} SectionShown
 * @property {Crossing[]} found
 * @property {Band[]} strips
 * @property {Machine | null} machine
 * @property {number} diameter
 * @property {number} z
 * @property {number} takeup
 * @property {(yarnId: number) => number} colour
 * @property {number[][] | null} cells [row, col] of each cell of the section
 * @property {string | undefined} spec
 */
/** @typedef {(mm: number) => number} ToScreen x or y in mm -> CSS pixels */

const MARGIN = { left: 52, right: 14, top: 30, bottom: 94 }; // CSS px around the plot
const INK = '#1a202c';
const GRID = '#dde2e8';
const CELL_FILL = '#e6eaf0';
const SPREAD_INK = '#8a94a6'; // the reference scaled to the yarns' spread
const PLANE_COLOUR = 0x3182ce;
const MIN_RADIUS_PX = 2.5; // a yarn never drawn smaller (a thin yarn in a wide view)

/** The 2D section in its own canvas. */
export class SectionView {
  /** @param {HTMLCanvasElement} canvas */
  constructor(canvas) {
    this.canvas = canvas;
    const g = canvas.getContext('2d');
    const host = canvas.parentElement;
    if (!g || !host) throw new Error('the section view needs a 2D canvas in the page');
    this.g = g;
    this.host = host;
    /** @type {SectionShown | null} what was last drawn */
    this.shown = null;
    /** @type {{sx: ToScreen, sy: ToScreen, scale: number, found: Crossing[]} | null} */
    this.toScreen = null;
    /** @type {string[]} the key's lines as last drawn (for tests and diagnostics) */
    this.key = [];
    /** @type {number | null} the reference's scale to the yarns' spread, as last drawn */
    this.spread = null;
    new ResizeObserver(() => this.redraw()).observe(host);
  }

  /**
   * Draw the section: `found` crossings and `strips` (section.js), `colour(yarnId)`, the
   * machine and diameter, `z` and the take-up, and the nominal section's cells (or null).
   * @param {SectionShown} shown
   */
  draw(shown) {
    this.shown = shown;
    this.redraw();
  }

  redraw() {
    const shown = this.shown;
    const { clientWidth: width, clientHeight: height } = this.host;
    if (!shown || width === 0 || height === 0) return;
    const ratio = window.devicePixelRatio || 1;
    this.canvas.width = Math.round(width * ratio);
    this.canvas.height = Math.round(height * ratio);
    const g = this.g;
    g.setTransform(ratio, 0, 0, ratio, 0, 0);
    g.clearRect(0, 0, width, height);
    const { found, strips, machine, diameter } = shown;
    const [cx, cy, half] = sliceLimits(found, strips, machine, diameter);
    const side = Math.max(Math.min(width - MARGIN.left - MARGIN.right, height - MARGIN.top - MARGIN.bottom), 10);
    const scale = side / (2 * half); // px per mm
    const left = MARGIN.left + (width - MARGIN.left - MARGIN.right - side) / 2;
    const top = MARGIN.top + Math.max(0, (height - MARGIN.top - MARGIN.bottom - side) / 3);
    /** @type {ToScreen} */
    const sx = (x) => left + (x - (cx - half)) * scale;
    /** @type {ToScreen} */
    const sy = (y) => top + (y - (cy - half)) * scale;
    this.toScreen = { sx, sy, scale, found };
    g.save();
    g.beginPath();
    g.rect(left, top, side, side);
    g.clip();
    this.drawGrid(left, top, side, cx, cy, half, sx, sy);
    this.spread = spreadOf(shown);
    this.drawCells(shown, sx, sy);
    this.drawStrips(strips, shown.colour, sx, sy);
    this.drawCrossings(found, shown.colour, diameter, sx, sy, scale);
    g.restore();
    g.strokeStyle = INK;
    g.lineWidth = 1;
    g.strokeRect(left, top, side, side);
    this.drawTicks(left, top, side, cx, cy, half, sx, sy);
    g.fillStyle = INK;
    g.font = '13px system-ui, sans-serif';
    g.textAlign = 'center';
    g.textBaseline = 'top';
    const free = found.filter((c) => c.free).length;
    g.fillText(`z = ${num(shown.z)} mm (take-up ${num(shown.takeup)} mm): ${found.length} crossings${free ? `, ${free} free` : ''}`, left + side / 2, top - 22);
    this.drawKey(shown, left, top + side + 44, free);
  }

  /**
   * @param {number} left
   * @param {number} top
   * @param {number} side
   * @param {number} cx
   * @param {number} cy
   * @param {number} half
   * @param {ToScreen} sx
   * @param {ToScreen} sy
   */
  drawGrid(left, top, side, cx, cy, half, sx, sy) {
    const g = this.g;
    const step = niceStep(2 * half);
    g.strokeStyle = GRID;
    g.lineWidth = 1;
    g.beginPath();
    for (let v = Math.ceil((cx - half) / step) * step; v <= cx + half; v += step) {
      g.moveTo(sx(v), top);
      g.lineTo(sx(v), top + side);
    }
    for (let v = Math.ceil((cy - half) / step) * step; v <= cy + half; v += step) {
      g.moveTo(left, sy(v));
      g.lineTo(left + side, sy(v));
    }
    g.stroke();
  }

  /**
   * @param {number} left
   * @param {number} top
   * @param {number} side
   * @param {number} cx
   * @param {number} cy
   * @param {number} half
   * @param {ToScreen} sx
   * @param {ToScreen} sy
   */
  drawTicks(left, top, side, cx, cy, half, sx, sy) {
    const g = this.g;
    const step = niceStep(2 * half);
    g.fillStyle = INK;
    g.font = '11px system-ui, sans-serif';
    g.textAlign = 'center';
    g.textBaseline = 'top';
    for (let v = Math.ceil((cx - half) / step) * step; v <= cx + half; v += step) g.fillText(num(v), sx(v), top + side + 4);
    g.textAlign = 'right';
    g.textBaseline = 'middle';
    for (let v = Math.ceil((cy - half) / step) * step; v <= cy + half; v += step) g.fillText(num(v), left - 5, sy(v));
    g.font = '12px system-ui, sans-serif';
    g.textAlign = 'center';
    g.textBaseline = 'bottom';
    g.fillText('x [mm]', left + side / 2, top + side + 36);
    g.save();
    g.translate(14, top + side / 2);
    g.rotate(-Math.PI / 2);
    g.textBaseline = 'middle';
    g.fillText('y [mm]', 0, 0);
    g.restore();
  }

  /**
   * What the marks mean, under the plot.
   * @param {SectionShown} shown
   * @param {number} left
   * @param {number} y
   * @param {number} free the free crossings
   */
  drawKey({ cells, spec, diameter, machine, takeup, z }, left, y, free) {
    const g = this.g;
    g.font = '11px system-ui, sans-serif';
    g.textAlign = 'left';
    g.textBaseline = 'top';
    g.fillStyle = '#5a6473';
    const marks = diameter > 0 ? 'circles: the yarn diameter, filled on laid yarn' : 'dots: laid yarn';
    const lines = [`${marks}${free ? (diameter > 0 ? ', open on free segments' : ', crosses on free segments') : ''}`];
    if (cells && machine) {
      lines.push(`shaded: ${spec ?? 'the section'}'s cells at the fell, z = ${num(takeup)} mm (c_mat ${num(machine.c_mat)} × pitch)`);
      const k = this.spread;
      if (k !== null) {
        lines.push(`dashed: the same ×${k.toFixed(2)} about the matrix centre, as the yarns spread at z = ${num(z)} mm (${(k * machine.c_mat).toFixed(2)} of the guides' spread)`);
      }
    }
    this.key = lines;
    lines.forEach((text, i) => g.fillText(text, left, y + 15 * i));
  }

  /**
   * The nominal section: each body cell a tile of c_mat pitch at the fell.
   * @param {SectionShown} shown
   * @param {ToScreen} sx
   * @param {ToScreen} sy
   */
  drawCells({ cells, machine }, sx, sy) {
    if (!cells || !machine) return;
    const g = this.g;
    const [hx, hy] = [(machine.c_mat * machine.pitch_x) / 2, (machine.c_mat * machine.pitch_y) / 2];
    g.fillStyle = CELL_FILL;
    for (const [row, col] of cells) {
      const [x, y] = fellXY(machine, row, col);
      g.fillRect(sx(x - hx), sy(y - hy), sx(x + hx) - sx(x - hx), sy(y + hy) - sy(y - hy));
    }
    const k = this.spread;
    if (k === null) return;
    // The same cells scaled by k about the matrix's centre O: where the yarns at this height lie.
    const [ox, oy] = centreOf(machine);
    g.save();
    g.strokeStyle = SPREAD_INK;
    g.lineWidth = 1;
    g.setLineDash([4, 3]);
    for (const [row, col] of cells) {
      const [fx, fy] = fellXY(machine, row, col);
      const [x, y] = [ox + k * (fx - ox), oy + k * (fy - oy)];
      g.strokeRect(sx(x - k * hx), sy(y - k * hy), sx(x + k * hx) - sx(x - k * hx), sy(y + k * hy) - sy(y - k * hy));
    }
    g.restore();
  }

  /**
   * @param {Band[]} strips
   * @param {(yarnId: number) => number} colour
   * @param {ToScreen} sx
   * @param {ToScreen} sy
   */
  drawStrips(strips, colour, sx, sy) {
    const g = this.g;
    g.globalAlpha = 0.6;
    for (const band of strips) {
      const corners = bandCorners(band);
      g.fillStyle = css(colour(band.yarn));
      g.beginPath();
      corners.forEach(([x, y], i) => (i ? g.lineTo(sx(x), sy(y)) : g.moveTo(sx(x), sy(y))));
      g.closePath();
      g.fill();
    }
    g.globalAlpha = 1;
  }

  /**
   * @param {Crossing[]} found
   * @param {(yarnId: number) => number} colour
   * @param {number} diameter
   * @param {ToScreen} sx
   * @param {ToScreen} sy
   * @param {number} scale px per mm
   */
  drawCrossings(found, colour, diameter, sx, sy, scale) {
    const g = this.g;
    const r = diameter > 0 ? Math.max((diameter / 2) * scale, MIN_RADIUS_PX) : 0;
    for (const c of found) {
      const [x, y] = [sx(c.x), sy(c.y)];
      const fill = css(colour(c.yarn));
      g.lineWidth = 1;
      if (r > 0) {
        g.beginPath();
        g.arc(x, y, r, 0, 2 * Math.PI);
        if (!c.free) {
          g.fillStyle = fill;
          g.fill();
        }
        g.strokeStyle = c.free ? fill : '#111';
        g.lineWidth = c.free ? 1.5 : 0.8;
        g.stroke();
      } else if (c.free) {
        g.strokeStyle = fill;
        g.beginPath();
        g.moveTo(x - 3, y - 3);
        g.lineTo(x + 3, y + 3);
        g.moveTo(x - 3, y + 3);
        g.lineTo(x + 3, y - 3);
        g.stroke();
      } else {
        g.fillStyle = fill;
        g.beginPath();
        g.arc(x, y, 2.5, 0, 2 * Math.PI);
        g.fill();
      }
    }
  }

  /**
   * The yarn whose crossing is under (x, y) CSS pixels of the canvas, or null.
   * @param {number} x
   * @param {number} y
   */
  yarnAt(x, y) {
    if (!this.toScreen || !this.shown) return null;
    const { sx, sy, scale, found } = this.toScreen;
    const reach = Math.max(((this.shown.diameter / 2) * scale), 4);
    /** @type {number | null} */
    let best = null;
    let bestDistance = reach;
    for (const c of found) {
      const distance = Math.hypot(sx(c.x) - x, sy(c.y) - y);
      if (distance <= bestDistance) [best, bestDistance] = [c.yarn, distance];
    }
    return best;
  }
}

/**
 * The matrix's centre O, about which the yarns converge from the guides to the fell.
 * @param {Machine} machine
 */
function centreOf(machine) {
  return [((machine.cols - 1) / 2) * machine.pitch_x, ((machine.rows - 1) / 2) * machine.pitch_y];
}

/**
 * How much wider the yarns at this height spread than the reference at the fell: the
 * extent (width plus height) of the crossings over that of the section's cells at the
 * fell, both about their centres; null without cells or crossings.
 * @param {SectionShown} shown
 */
export function spreadOf({ cells, machine, found }) {
  if (!cells || cells.length === 0 || !machine || found.length < 2) return null;
  const fell = cells.map(([row, col]) => fellXY(machine, row, col));
  /** @param {number[][]} points */
  const extent = (points) => {
    const xs = points.map((p) => p[0]);
    const ys = points.map((p) => p[1]);
    return Math.max(...xs) - Math.min(...xs) + Math.max(...ys) - Math.min(...ys);
  };
  const reference = extent(fell);
  return reference > 0 ? extent(found.map((c) => [c.x, c.y])) / reference : null;
}

/**
 * A number without float noise, at most 3 decimals.
 * @param {number} value
 */
function num(value) {
  return String(Number(value.toFixed(3)));
}

/** The section in the 3D view: a translucent plane, and its crossings as discs. */
export class SectionMarks {
  constructor() {
    this.plane = new THREE.Mesh(new THREE.BufferGeometry(), new THREE.MeshBasicMaterial({
      color: PLANE_COLOUR, transparent: true, opacity: 0.07, depthWrite: false, side: THREE.DoubleSide,
    }));
    this.outline = new THREE.LineLoop(new THREE.BufferGeometry(), new THREE.LineBasicMaterial({ color: PLANE_COLOUR }));
    this.fixed = new THREE.Points(new THREE.BufferGeometry(), mmPointsMaterial({ vertexColors: true, map: discTexture(false) }));
    this.free = new THREE.Points(new THREE.BufferGeometry(), mmPointsMaterial({ vertexColors: true, map: discTexture(true) }));
    this.objects = [this.plane, this.outline, this.fixed, this.free];
    for (const object of this.objects) {
      object.frustumCulled = false;
      object.material.depthTest = false; // on top: the cut is what the section shows
      object.renderOrder = 2;
      object.visible = false;
    }
  }

  /**
   * Show the plane over [x0, x1] x [y0, y1] at `z`, and `found` crossings in `colour`.
   * @param {Crossing[]} found
   * @param {(yarnId: number) => number} colour
   * @param {number} diameter
   * @param {number[]} extent [x0, y0, x1, y1]
   * @param {number} z
   */
  update(found, colour, diameter, [x0, y0, x1, y1], z) {
    const corners = [x0, y0, z, x1, y0, z, x1, y1, z, x0, y1, z];
    const quad = new THREE.BufferGeometry();
    quad.setAttribute('position', new THREE.Float32BufferAttribute(corners, 3));
    this.outline.geometry.dispose();
    this.outline.geometry = quad;
    this.plane.geometry.dispose();
    this.plane.geometry = quad.clone().setIndex([0, 1, 2, 0, 2, 3]);
    /** @type {[THREE.Points<THREE.BufferGeometry, THREE.PointsMaterial>, boolean][]} */
    const kinds = [[this.fixed, false], [this.free, true]];
    for (const [points, free] of kinds) {
      const mine = found.filter((c) => c.free === free);
      const positions = new Float32Array(3 * mine.length);
      const colours = new Float32Array(3 * mine.length);
      const c3 = new THREE.Color();
      mine.forEach((c, i) => {
        positions.set([c.x, c.y, z], 3 * i);
        c3.setHex(colour(c.yarn));
        colours.set([c3.r, c3.g, c3.b], 3 * i);
      });
      const geometry = new THREE.BufferGeometry();
      geometry.setAttribute('position', new THREE.BufferAttribute(positions, 3));
      geometry.setAttribute('color', new THREE.BufferAttribute(colours, 3));
      points.geometry.dispose();
      points.geometry = geometry;
      points.material.userData.diameter = diameter;
    }
  }

  /** @param {boolean} visible */
  setVisible(visible) {
    for (const object of this.objects) object.visible = visible;
  }
}
