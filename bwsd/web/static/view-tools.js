// @ts-check
// The 3D view's tools beyond drawing the yarns: the section (its height, the plane and
// crossings in 3D, the cut above it, the 2D view beside), the braided section's zones for
// colouring, picking a yarn with the mouse, the view's controls in the page and its test
// hooks on `window.bwsd` (`section(z)`, and `view`: the PreformView).
//
// The section is recomputed when it is shown and the skeleton or the height changed; while
// a program runs, at most every SECTION_EVERY_MS (a pass over every node).
// The view's `onColoursChanged` is called when the zones arrive (the program's section line).

import * as THREE from 'three';

import { request } from './api.js';
import { optionalById } from './dom.js';
import { bands, crossings, fellXY } from './section.js';
import { listenForClicks, pickYarn } from './view-pick.js';
import { RelaxedLayer } from './view-relaxed.js';
import { SectionMarks, SectionView } from './view-section.js';
import { sectionFrom } from './view-zones.js';

/** @import { PreformView } from './skeleton.js' */
/** @import { Band, Crossing } from './section.js' */

const SECTION_EVERY_MS = 250;

export class ViewTools {
  /** @param {PreformView} view */
  constructor(view) {
    this.view = view;
    this.shown = false;
    this.z = 0;
    this.userZ = false; // the operator chose the height (kept over reloads of the skeleton)
    this.cut = false;
    /** @type {{shown: boolean, cut: boolean} | null} the section and cut before "top" changed them */
    this.beforeTop = null;
    this.cutPlane = new THREE.Plane(new THREE.Vector3(0, 0, -1), 0); // keeps z <= constant
    this.dirty = true;
    this.lastAt = 0;
    /** @type {ReturnType<typeof setTimeout> | null} */
    this.timer = null;
    /** @type {Crossing[]} */
    this.found = [];
    /** @type {Band[]} */
    this.strips = [];
    this.relaxed = new RelaxedLayer(view.layers.liveScene, () => view.invalidate(true));
    this.marks = new SectionMarks();
    for (const object of this.marks.objects) view.layers.liveScene.add(object);
    const canvas = optionalById('section-view', HTMLCanvasElement);
    const sectionView = canvas ? new SectionView(canvas) : null;
    this.sectionView = sectionView;
    this.sectionGiven = false; // setSection was called: no fetching of the program's text
    this.loads = 0;
    /** @type {{id: number, text: string} | null} the last program read */
    this.programText = null;
    /** @type {string | null} */
    this.sectionError = null;
    listenForClicks(view.canvas, (x, y) => this.pickAt(x, y));
    if (canvas && sectionView) listenForClicks(canvas, (x, y) => view.onPick?.(sectionView.yarnAt(x, y)));
    this.wire();
    // Not enumerable: `{...window.bwsd}` copies the page's numbers, not the whole view.
    const hooks = window.bwsd ?? (window.bwsd = {});
    Object.defineProperty(hooks, 'section', { value: (/** @type {number} */ z) => view.section(z), configurable: true });
    Object.defineProperty(hooks, 'view', { value: view, configurable: true });
  }

  get pointMaterials() {
    return [this.marks.fixed.material, this.marks.free.material];
  }

  // ----- the model's life -----

  cleared() {
    this.found = [];
    this.strips = [];
    this.dirty = true;
  }

  loaded() {
    this.loads += 1;
    if (!this.userZ) this.z = this.defaultHeight();
    if (!this.sectionGiven) this.fetchSection(this.loads);
    if (this.relaxed.shown) void this.relaxed.setShown(true); // the new skeleton's
    this.applyCut();
    this.syncControls();
  }

  modelChanged() {
    this.dirty = true;
  }

  /** The top of what is drawn: the guides. */
  top() {
    const view = this.view;
    return view.machine ? Math.max(view.bounds.max.z, view.machine.d_mat + view.takeup) : Math.max(view.bounds.max.z, 0);
  }

  /**
   * Until the operator sets one: half the distance from the fell to the guides (d_mat / 2), a
   * property of the machine, so the same whenever the page is opened (not of the skeleton so
   * far, which depends on when that is).
   */
  defaultHeight() {
    const machine = this.view.machine;
    return machine ? Number((machine.d_mat / 2).toFixed(1)) : 0;
  }

  // ----- the section -----

  /** @param {boolean} shown */
  setShown(shown) {
    this.shown = Boolean(shown);
    this.marks.setVisible(this.shown);
    const pane = optionalById('section-pane');
    if (pane) pane.hidden = !this.shown;
    this.view.resize(); // the 3D view shares its row with the section: its size now, not after layout
    this.view.machineMarks.fillFell = !this.shown;
    this.view.machineDirty = true;
    if (!this.shown) this.setCut(false);
    this.dirty = true;
    this.syncControls();
    this.view.invalidate();
  }

  /** @param {number | string} z */
  setHeight(z) {
    const value = Number(z);
    if (!Number.isFinite(value)) return;
    this.z = value;
    this.userZ = true;
    this.dirty = true;
    this.applyCut();
    this.syncControls();
  }

  /** @param {boolean} cut */
  setCut(cut) {
    this.cut = Boolean(cut) && this.shown;
    this.applyCut();
    this.syncControls();
  }

  /** Clip the yarns, the contacts and the matrix above the section (or nothing). */
  applyCut() {
    const view = this.view;
    this.cutPlane.constant = this.z;
    const planes = this.cut ? [this.cutPlane] : null;
    const { yarnMaterial, highlightYarn } = view.layers;
    const materials = [yarnMaterial, view.contactMaterial, highlightYarn.line.material, ...view.machineMarks.clipped];
    for (const material of materials) material.clippingPlanes = planes;
    view.invalidate(true);
  }

  /** @param {number | string} z */
  crossingsAt(z) {
    return crossings(this.view.yarnsInOrder(), Number(z)).map(({ yarn, x, y, free }) => ({ yarn, x, y, free }));
  }

  /** Called before each frame: recompute the section when it is shown and out of date. */
  beforeRender() {
    if (!this.shown || !this.dirty) return;
    const flowing = performance.now() - this.view.lastDeltaAt < SECTION_EVERY_MS * 4;
    const wait = this.lastAt + SECTION_EVERY_MS - performance.now();
    if (flowing && wait > 0) {
      if (!this.timer) this.timer = setTimeout(() => {
        this.timer = null;
        this.view.invalidate();
      }, wait);
      return;
    }
    this.lastAt = performance.now();
    this.dirty = false;
    this.compute();
  }

  compute() {
    const view = this.view;
    const yarns = view.yarnsInOrder();
    this.found = crossings(yarns, this.z);
    this.strips = bands(yarns, this.z, view.diameter);
    /** @param {number} id */
    const colour = (id) => view.shownColour(id);
    const m = view.machine;
    const extent = m ? [-0.5 * m.pitch_x, -0.5 * m.pitch_y, (m.cols - 0.5) * m.pitch_x, (m.rows - 0.5) * m.pitch_y] : [-50, -50, 50, 50];
    this.marks.update(this.found, colour, view.diameter, extent, this.z);
    const section = view.palette.section;
    const cells = section ? section.zones.flatMap(([, set]) => [...set].map((key) => key.split(',').map(Number))) : null;
    this.sectionView?.draw({
      found: this.found, strips: this.strips, machine: m, diameter: view.diameter,
      z: this.z, takeup: view.takeup, colour, cells, spec: section?.spec,
    });
    this.syncRange();
  }

  /**
   * The region the top view frames when the section is cut: the preform below the cut.
   * @param {boolean} fresh recompute the section first if it is out of date
   */
  focusBox(fresh) {
    const view = this.view;
    const m = view.machine;
    if (!(this.shown && this.cut && view.rig.preset === 'top' && m)) return null;
    if (fresh && this.dirty) this.compute();
    const [x0, y0] = fellXY(m, 0, 0);
    const [x1, y1] = fellXY(m, m.rows - 1, m.cols - 1);
    const xs = [x0, x1, ...this.found.map((c) => c.x), ...this.strips.flatMap((b) => [b.start[0], b.end[0]])];
    const ys = [y0, y1, ...this.found.map((c) => c.y), ...this.strips.flatMap((b) => [b.start[1], b.end[1]])];
    const pad = 2 * Math.max(view.diameter, 1);
    return new THREE.Box3(
      new THREE.Vector3(Math.min(...xs) - pad, Math.min(...ys) - pad, Math.min(0, this.z)),
      new THREE.Vector3(Math.max(...xs) + pad, Math.max(...ys) + pad, Math.max(this.z, 0)),
    );
  }

  /**
   * A preset was chosen: the top view shows the section, cut, to read the preform's shape.
   * @param {string} preset
   */
  presetChosen(preset) {
    if (preset === 'top') {
      this.beforeTop ??= { shown: this.shown, cut: this.cut };
      if (!this.shown) this.setShown(true);
      this.setCut(true);
      return;
    }
    // Leaving "top": the section and the cut as they were before it, so that no hidden cut
    // keeps the other views from showing the whole preform.
    const before = this.beforeTop;
    this.beforeTop = null;
    if (!before) return;
    this.setCut(before.cut);
    if (this.shown !== before.shown) this.setShown(before.shown);
  }

  // ----- zones -----

  /**
   * The braided section from a spec or a program's text (`given`: by the page, not fetched here).
   * @param {string | null} text
   */
  setSection(text, given = false) {
    if (given) this.sectionGiven = true;
    const { section, error } = sectionFrom(text);
    this.sectionError = error;
    this.view.palette.setSection(section);
    this.view.changed(true);
    this.dirty = true;
    this.view.onColoursChanged?.();
  }

  /**
   * Read the loaded program's text from the daemon, for its "# section:" line.
   * @param {number} load the load it is for (a later one makes it moot)
   */
  async fetchSection(load) {
    try {
      const state = await request('api/v1/state');
      /** @type {number | null | undefined} */
      const id = state.ok ? state.body?.program_id : null;
      if (id === null || id === undefined) return;
      let program = this.programText;
      if (program?.id !== id) {
        const answer = await request(`api/v1/programs/${id}`);
        if (!answer.ok || typeof answer.body?.text !== 'string') return;
        program = { id, text: answer.body.text };
        this.programText = program;
      }
      if (load === this.loads && !this.sectionGiven) this.setSection(program.text);
    } catch {
      // the daemon cannot be reached: no zones until the next load
    }
  }

  // ----- picking -----

  /**
   * @param {number} x
   * @param {number} y
   */
  pickAt(x, y) {
    const view = this.view;
    const cutZ = this.cut ? this.z : Infinity;
    const id = pickYarn(view.yarnsInOrder(), view.camera, view.width ?? NaN, view.height ?? NaN, x, y, cutZ);
    view.onPick?.(id);
  }

  // ----- the controls in the page -----

  wire() {
    const view = this.view;
    for (const button of document.querySelectorAll('[data-view]')) {
      if (button instanceof HTMLElement) button.addEventListener('click', () => view.setView(button.dataset.view));
    }
    /**
     * Call `onChange(checked)` when the check box `#id` (if the page has it) changes.
     * @param {string} id
     * @param {(checked: boolean) => void} onChange
     */
    const toggle = (id, onChange) => {
      const box = optionalById(id, HTMLInputElement);
      box?.addEventListener('change', () => onChange(box.checked));
    };
    toggle('ortho', (on) => view.setOrthographic(on));
    toggle('show-axes', (on) => view.setAxesVisible(on));
    toggle('show-section', (on) => view.setSectionShown(on));
    toggle('section-cut', (on) => view.setSectionCut(on));
    toggle('show-relaxed', (on) => void this.relaxed.setShown(on));
    for (const id of ['section-z', 'section-z-value']) {
      const input = optionalById(id, HTMLInputElement);
      input?.addEventListener('input', () => {
        if (input.value !== '') view.setSectionHeight(input.value);
      });
    }
  }

  /** Show in the controls what the view does now. */
  syncControls() {
    const view = this.view;
    for (const button of document.querySelectorAll('[data-view]')) {
      if (button instanceof HTMLElement) button.setAttribute('aria-pressed', String(button.dataset.view === view.rig.preset));
    }
    /**
     * @param {string} id
     * @param {'checked' | 'disabled'} property
     * @param {boolean} value
     */
    const set = (id, property, value) => {
      const element = optionalById(id, HTMLInputElement);
      if (element && element[property] !== value) element[property] = value;
    };
    set('ortho', 'checked', view.rig.isOrthographic);
    set('show-section', 'checked', this.shown);
    set('section-cut', 'checked', this.cut);
    set('section-cut', 'disabled', !this.shown);
    for (const id of ['section-z', 'section-z-value']) set(id, 'disabled', !this.shown);
    this.syncRange();
  }

  syncRange() {
    const slider = optionalById('section-z', HTMLInputElement);
    const field = optionalById('section-z-value', HTMLInputElement);
    const top = String(Number(this.top().toFixed(1)));
    if (slider && slider.max !== top) slider.max = top;
    const value = String(this.z);
    if (slider && document.activeElement !== slider && slider.value !== value) slider.value = value;
    if (field && document.activeElement !== field && field.value !== value) field.value = value;
  }
}
