// @ts-check
// Axes of the preform frame in the 3D view, with millimetre ticks, and a scale bar.
//
// Three axes start at a corner below the machine's footprint: x along the front edge
// (y = its lowest value), y along the left edge, z up the front left corner, from z = 0
// (the fell at the start) to the guides. Ticks every 1, 2 or 5 x 10^k mm, the same step on
// x and y; labels are HTML over the canvas, placed where each tick projects. An axis seen
// end-on (z from the top) shows no tick labels. The scale bar, in the orthographic
// projection only (where a screen length is the same number of mm everywhere), is a round
// length about a fifth of the view's width.

import * as THREE from 'three';

/** @import { ViewCamera } from './view-camera.js' */

/**
 * A label of the axes: a tick's value (its `index` along the axis) or the axis's title.
 * @typedef {{axis: string, index?: number, text: string, xyz: THREE.Vector3, title?: boolean}} LabelSpec
 */
/** @typedef {LabelSpec & {element: HTMLElement}} AxisLabel a label with its element */

const AXIS_COLOUR = 0x4a5568;
const TARGET_TICKS = 6;
const MIN_LABEL_GAP_PX = 30; // closer ticks are labelled every other (or k-th) one
const END_ON_PX = 4; // an axis whose ticks are closer than this on screen is seen end-on

/**
 * The round step (1, 2 or 5 x 10^k) nearest to `span` / `ticks`, on a log scale.
 * @param {number} span
 */
export function niceStep(span, ticks = TARGET_TICKS) {
  const raw = Math.max(span, 1e-9) / ticks;
  const power = 10 ** Math.floor(Math.log10(raw));
  const steps = [1, 2, 5, 10].map((m) => m * power);
  return steps.reduce((best, step) => (Math.abs(Math.log(step / raw)) < Math.abs(Math.log(best / raw)) ? step : best));
}

/**
 * A tick value as text: no float noise (0.30000000000000004 is "0.3").
 * @param {number} value
 */
function label(value) {
  return String(Number(value.toPrecision(10)));
}

export class Axes {
  /** @type {number} the tick step along x and y, mm (set by `update`) */
  step;
  /** @type {number} along z */
  zStep;

  /** @param {HTMLElement} host the element over the canvas that holds the labels */
  constructor(host) {
    this.lines = new THREE.LineSegments(new THREE.BufferGeometry(), new THREE.LineBasicMaterial({ color: AXIS_COLOUR }));
    this.lines.frustumCulled = false;
    this.lines.material.depthTest = false;
    this.lines.renderOrder = 1;
    this.host = host;
    /** @type {AxisLabel[]} */
    this.labels = [];
    this.key = '';
    this.visible = true;
    /** @type {THREE.Box3 | null} what the axes and their labels span (for framing the view) */
    this.region = null;
    /** @type {string | null} the picture the labels were placed for */
    this.placed = null;
  }

  /**
   * Build the axes for a region [min, max] (Vector3s) of the preform frame, if it changed.
   * @param {THREE.Vector3} min
   * @param {THREE.Vector3} max
   */
  update(min, max) {
    const step = niceStep(Math.max(max.x - min.x, max.y - min.y));
    const zStep = niceStep(max.z - Math.min(min.z, 0));
    const lo = new THREE.Vector3(Math.floor(min.x / step) * step, Math.floor(min.y / step) * step, Math.min(0, Math.floor(min.z / zStep) * zStep));
    const hi = new THREE.Vector3(Math.ceil(max.x / step) * step, Math.ceil(max.y / step) * step, Math.ceil(max.z / zStep) * zStep);
    const key = [step, zStep, ...lo.toArray(), ...hi.toArray()].join(',');
    if (key === this.key) return;
    this.key = key;
    const tick = 0.25 * step;
    /** @type {number[]} */
    const points = [];
    /** @type {LabelSpec[]} */
    const labels = [];
    /**
     * @param {THREE.Vector3} a
     * @param {THREE.Vector3} b
     */
    const segment = (a, b) => points.push(...a.toArray(), ...b.toArray());
    /**
     * @param {string} name
     * @param {number} unit
     * @param {number[]} span
     * @param {number} stepOf
     * @param {THREE.Vector3} out
     */
    const axis = (name, unit, span, stepOf, out) => {
      const [from, to] = span;
      /** @param {number} v */
      const at = (v) => lo.clone().setComponent(unit, v);
      segment(at(from), at(to));
      for (let v = from; v <= to + stepOf * 1e-6; v += stepOf) {
        const p = at(v);
        segment(p, p.clone().add(out.clone().multiplyScalar(tick)));
        // the corner's 0 once, on x (and z, the fell at the start)
        const index = Math.round((v - from) / stepOf);
        if (name === 'y' && index === 0) continue;
        labels.push({ axis: name, index, text: label(v), xyz: p.clone().add(out.clone().multiplyScalar(2.2 * tick)) });
      }
      const end = at(to + 1.6 * stepOf); // clear of the last tick's label
      labels.push({ axis: name, text: `${name} mm`, xyz: end, title: true });
    };
    axis('x', 0, [lo.x, hi.x], step, new THREE.Vector3(0, -1, 0));
    axis('y', 1, [lo.y, hi.y], step, new THREE.Vector3(-1, 0, 0));
    axis('z', 2, [lo.z, hi.z], zStep, new THREE.Vector3(-1, -1, 0).normalize());
    const geometry = new THREE.BufferGeometry();
    geometry.setAttribute('position', new THREE.Float32BufferAttribute(points, 3));
    this.lines.geometry.dispose();
    this.lines.geometry = geometry;
    this.setLabels(labels);
    this.step = step;
    this.zStep = zStep;
    const room = 3 * tick; // the tick labels, outside the axes
    this.region = new THREE.Box3(lo.clone().sub(new THREE.Vector3(room, room, 0)), hi.clone().add(new THREE.Vector3(2.2 * step, 2.2 * step, 2.2 * zStep)));
  }

  /** @param {LabelSpec[]} labels */
  setLabels(labels) {
    this.host.replaceChildren();
    this.labels = labels.map((entry) => {
      const element = document.createElement('span');
      element.className = entry.title ? 'axis-label axis-title' : 'axis-label';
      element.dataset.axis = entry.axis;
      element.textContent = entry.text;
      this.host.append(element);
      return Object.assign(entry, { element });
    });
  }

  /** @param {boolean} visible */
  setVisible(visible) {
    this.visible = visible;
    this.placed = null;
    this.lines.visible = visible;
    this.host.hidden = !visible;
  }

  /**
   * Put each label where its point projects (CSS pixels of a `width` x `height` canvas).
   * @param {ViewCamera} camera
   * @param {number} width
   * @param {number} height
   */
  place(camera, width, height) {
    if (!this.visible) return;
    // Only when the picture moved (or the axes changed): a frame of a running program moves nothing here.
    const key = [this.key, width, height, ...camera.projectionMatrix.elements, ...camera.matrixWorld.elements].join();
    if (key === this.placed) return;
    this.placed = key;
    const spacing = this.tickSpacing(camera, width, height);
    // An axis seen end-on shows no labels; ticks too close together, every k-th.
    const every = Object.fromEntries(Object.entries(spacing).map(([axis, px]) =>
      [axis, px < END_ON_PX ? Infinity : Math.ceil(MIN_LABEL_GAP_PX / px)]));
    const v = new THREE.Vector3();
    for (const entry of this.labels) {
      v.copy(entry.xyz).project(camera);
      const step = every[entry.axis];
      const shown = Math.abs(v.z) <= 1 && step !== Infinity && (entry.title || (entry.index ?? 0) % step === 0);
      const element = entry.element;
      element.hidden = !shown;
      if (!shown) continue;
      const x = ((v.x + 1) / 2) * width;
      const y = ((1 - v.y) / 2) * height;
      element.style.transform = `translate(${x.toFixed(1)}px, ${y.toFixed(1)}px) translate(-50%, -50%)`;
    }
  }

  /**
   * Screen distance between two ticks of each axis, in pixels.
   * @param {ViewCamera} camera
   * @param {number} width
   * @param {number} height
   */
  tickSpacing(camera, width, height) {
    /** @type {Record<string, number>} */
    const out = {};
    for (const name of ['x', 'y', 'z']) {
      const ticks = this.labels.filter((e) => e.axis === name && !e.title);
      if (ticks.length < 2) {
        out[name] = Infinity;
        continue;
      }
      const a = ticks[0].xyz.clone().project(camera);
      const b = ticks[1].xyz.clone().project(camera).sub(a).divideScalar((ticks[1].index ?? 0) - (ticks[0].index ?? 0)).add(a);
      out[name] = Math.hypot(((b.x - a.x) / 2) * width, ((b.y - a.y) / 2) * height);
    }
    return out;
  }

  /** What the axes show, for tests: [{axis, text, shown}]. */
  describe() {
    return this.labels.map((e) => ({ axis: e.axis, text: e.text, title: Boolean(e.title), shown: !e.element.hidden && this.visible }));
  }
}

/** The scale bar: a round length near a fifth of the view's width, labelled in mm. */
export class ScaleBar {
  /** @param {HTMLElement} element */
  constructor(element) {
    this.element = element;
    this.bar = document.createElement('span');
    this.bar.className = 'scale-bar';
    this.text = document.createElement('span');
    this.text.className = 'scale-text';
    element.replaceChildren(this.bar, this.text);
    /** @type {number | null} */
    this.length = null;
    /** @type {string | null} what the bar was placed for */
    this.placed = null;
  }

  /**
   * Show `mmPerPx` (null: hide, as in perspective) on a view `width` pixels wide.
   * @param {number | null} mmPerPx
   * @param {number} width
   */
  place(mmPerPx, width) {
    const key = `${mmPerPx},${width}`;
    if (key === this.placed) return;
    this.placed = key;
    this.element.hidden = mmPerPx === null;
    if (mmPerPx === null) return;
    const length = niceStep(width * mmPerPx, 5);
    this.length = length;
    this.bar.style.width = `${(length / mmPerPx).toFixed(1)}px`;
    this.text.textContent = `${label(length)} mm`;
  }
}
