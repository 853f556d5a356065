// @ts-check
// Zoom and pan of the matrix: a scale and an offset from the drawing's units to the
// element's pixels, driven by the wheel, a drag, a two-finger pinch and the keyboard. A
// press that does not move is a tap (a pick); the pointer over the element is reported
// for the hover label.

const TAP_SLOP = 4; // px a press may wander and still be a tap
const KEEP = 48; // px of the drawing kept in view by a pan
const KEY_PAN = 40; // px per arrow key
const KEY_ZOOM = 1.25;
const MAX_CELL_PX = 120; // the closest zoom

/** @typedef {{x: number, y: number}} Point element pixels */

export class ZoomPan {
  /**
   * @param {HTMLElement} element the element that takes the pointer (the drawing fills it)
   * @param {object} options
   * @param {number} options.cell units per cell
   * @param {number} options.maxCellPx the largest cell at fit
   * @param {() => void} options.onChange
   * @param {(x: number, y: number) => void} options.onTap element pixels
   * @param {(x: number | null, y?: number) => void} options.onHover element pixels, or
   *   onHover(null) when the pointer left
   */
  constructor(element, options) {
    this.element = element;
    this.cell = options.cell;
    this.maxCellPx = options.maxCellPx;
    this.onChange = options.onChange;
    this.onTap = options.onTap;
    this.onHover = options.onHover;
    this.scale = 1;
    this.tx = 0;
    this.ty = 0;
    this.width = 0; // the element, px
    this.height = 0;
    this.content = { width: 0, height: 0 }; // the drawing, units
    this.insets = { left: 0, top: 0, right: 0, bottom: 0 }; // px kept for rulers
    this.fitted = true; // follows resizes until the operator zooms or pans
    /** @type {Map<number, Point>} pointer id -> where it is */
    this.pointers = new Map();
    /** @type {{start: Point, moved: boolean} | null} */
    this.gesture = null;
    this.listen();
  }

  /**
   * The drawing's size in units, and the pixels at its edges kept for rulers.
   * @param {number} width
   * @param {number} height
   * @param {Partial<ZoomPan['insets']>} insets
   */
  setContent(width, height, insets) {
    this.content = { width, height };
    this.insets = { ...this.insets, ...insets };
  }

  /**
   * The element's size in px; refits while the operator has not moved the view.
   * @param {number} width
   * @param {number} height
   */
  resize(width, height) {
    this.width = width;
    this.height = height;
    if (this.fitted) this.fit();
    else this.clamp();
  }

  /** The scale that shows the whole drawing in the room left by the insets. */
  fitScale() {
    const { left, top, right, bottom } = this.insets;
    const { width, height } = this.content;
    if (!width || !height) return 1;
    const across = (this.width - left - right) / width;
    const down = (this.height - top - bottom) / height;
    return Math.max(0.01, Math.min(this.maxCellPx / this.cell, across, down));
  }

  fit() {
    const { left, top, right, bottom } = this.insets;
    this.scale = this.fitScale();
    this.tx = left + (this.width - left - right - this.content.width * this.scale) / 2;
    this.ty = top + Math.max(0, (this.height - top - bottom - this.content.height * this.scale) / 2);
    this.fitted = true;
    this.onChange();
  }

  /**
   * Zoom by `factor` keeping the point (x, y) of the element where it is.
   * @param {number} factor
   * @param {number} x
   * @param {number} y
   */
  zoomAt(factor, x, y) {
    const fit = this.fitScale();
    const lowest = fit / 2;
    const highest = Math.max(fit, MAX_CELL_PX / this.cell);
    const scale = Math.min(highest, Math.max(lowest, this.scale * factor));
    if (scale === this.scale) return;
    this.tx = x - ((x - this.tx) * scale) / this.scale;
    this.ty = y - ((y - this.ty) * scale) / this.scale;
    this.scale = scale;
    this.moved();
  }

  /**
   * Zoom about the middle of the room the drawing has.
   * @param {number} factor
   */
  zoomBy(factor) {
    const { left, top, right, bottom } = this.insets;
    this.zoomAt(factor, (left + this.width - right) / 2, (top + this.height - bottom) / 2);
  }

  /**
   * @param {number} dx
   * @param {number} dy
   */
  panBy(dx, dy) {
    this.tx += dx;
    this.ty += dy;
    this.moved();
  }

  moved() {
    this.fitted = false;
    this.clamp();
    this.onChange();
  }

  /** Keep some of the drawing in view, however far it is dragged. */
  clamp() {
    const { left, top, right, bottom } = this.insets;
    const w = this.content.width * this.scale;
    const h = this.content.height * this.scale;
    const keepX = Math.min(KEEP, w);
    const keepY = Math.min(KEEP, h);
    this.tx = Math.min(this.width - right - keepX, Math.max(left + keepX - w, this.tx));
    this.ty = Math.min(this.height - bottom - keepY, Math.max(top + keepY - h, this.ty));
  }

  /**
   * Element pixels -> drawing units.
   * @param {number} x
   * @param {number} y
   * @returns {[number, number]}
   */
  toUnits(x, y) {
    return [(x - this.tx) / this.scale, (y - this.ty) / this.scale];
  }

  /**
   * Drawing units -> element pixels.
   * @param {number} u
   * @param {number} v
   * @returns {[number, number]}
   */
  toPixels(u, v) {
    return [this.tx + u * this.scale, this.ty + v * this.scale];
  }

  /** A cell's size on screen, px. */
  get cellPx() {
    return this.cell * this.scale;
  }

  // ----- input -----

  listen() {
    const element = this.element;
    element.addEventListener('wheel', (event) => this.wheel(event), { passive: false });
    element.addEventListener('pointerdown', (event) => this.down(event));
    element.addEventListener('pointermove', (event) => this.move(event));
    element.addEventListener('pointerup', (event) => this.up(event, true));
    element.addEventListener('pointercancel', (event) => this.up(event, false));
    element.addEventListener('pointerleave', () => {
      if (!this.pointers.size) this.onHover(null);
    });
    element.addEventListener('keydown', (event) => this.key(event));
  }

  /**
   * @param {MouseEvent} event
   * @returns {Point}
   */
  at(event) {
    const box = this.element.getBoundingClientRect();
    return { x: event.clientX - box.left, y: event.clientY - box.top };
  }

  /** @param {WheelEvent} event */
  wheel(event) {
    event.preventDefault(); // the wheel zooms the matrix, not the page
    const { x, y } = this.at(event);
    const lines = event.deltaMode === 1 ? 16 : event.deltaMode === 2 ? 400 : 1; // to px
    const rate = event.ctrlKey ? 0.01 : 0.0015; // a touchpad pinch comes as a ctrl-wheel
    this.zoomAt(Math.exp(-event.deltaY * lines * rate), x, y);
  }

  /** @param {PointerEvent} event */
  down(event) {
    if (event.pointerType === 'mouse' && event.button !== 0) return;
    try {
      this.element.setPointerCapture(event.pointerId); // a drag may leave the element
    } catch {
      // a pointer the browser no longer knows: the gesture goes on without capture
    }
    const point = this.at(event);
    this.pointers.set(event.pointerId, point);
    if (this.pointers.size === 1) this.gesture = { start: point, moved: false };
    else if (this.gesture) this.gesture.moved = true; // a pinch is never a tap
    this.onHover(null);
  }

  /** @param {PointerEvent} event */
  move(event) {
    const point = this.at(event);
    const before = this.pointers.get(event.pointerId);
    if (!before) {
      this.onHover(point.x, point.y);
      return;
    }
    const gesture = this.gesture;
    if (this.pointers.size === 1 && gesture) {
      const { start } = gesture;
      if (!gesture.moved && Math.hypot(point.x - start.x, point.y - start.y) > TAP_SLOP) gesture.moved = true;
      this.pointers.set(event.pointerId, point);
      if (gesture.moved) this.panBy(point.x - before.x, point.y - before.y);
      return;
    }
    const from = pair([...this.pointers.values()]); // the first two pointers pinch
    this.pointers.set(event.pointerId, point);
    const now = pair([...this.pointers.values()]);
    if (from.span > 0) this.zoomAt(now.span / from.span, now.x, now.y);
    this.panBy(now.x - from.x, now.y - from.y);
  }

  /**
   * @param {PointerEvent} event
   * @param {boolean} released
   */
  up(event, released) {
    if (!this.pointers.has(event.pointerId)) return;
    this.pointers.delete(event.pointerId);
    const gesture = this.gesture;
    if (this.pointers.size === 0) {
      this.gesture = null;
      if (released && gesture && !gesture.moved) {
        const { x, y } = this.at(event);
        this.onTap(x, y);
      }
    }
  }

  /** @param {KeyboardEvent} event */
  key(event) {
    /** @type {Record<string, [number, number]>} */
    const pans = { ArrowLeft: [KEY_PAN, 0], ArrowRight: [-KEY_PAN, 0], ArrowUp: [0, KEY_PAN], ArrowDown: [0, -KEY_PAN] };
    if (event.key in pans) this.panBy(...pans[event.key]);
    else if (event.key === '+' || event.key === '=') this.zoomBy(KEY_ZOOM);
    else if (event.key === '-') this.zoomBy(1 / KEY_ZOOM);
    else if (event.key === '0') this.fit();
    else return;
    event.preventDefault();
  }
}

/**
 * The middle of two pointers and their distance.
 * @param {Point[]} pointers the first two pinch
 */
function pair([a, b]) {
  return { x: (a.x + b.x) / 2, y: (a.y + b.y) / 2, span: Math.hypot(a.x - b.x, a.y - b.y) };
}
