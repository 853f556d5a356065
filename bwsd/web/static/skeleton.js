// @ts-check
// The 3D view of the predicted preform: the twin's skeleton as yarn polylines.
//
// Coordinates are the skeleton's preform frame (mm): z is up, z = 0 is the fell at the
// start of the run, the fell is at z = take-up now and the guides of the matrix at
// z = d_mat + take-up. Nothing is drawn in a loop: the page asks for a frame when
// something changed or the camera moved.
//
// Each yarn keeps its nodes in its own growing buffer (the capacity doubles when full); a
// delta only touches the yarns it names. What the GPU draws is built from those buffers in
// batches: many yarns in one draw call (a line strip per yarn, separated by restart
// indices), because a draw call per yarn is what costs most with hundreds of yarns.
//
// Two layers keep a big preform smooth while it grows. A twin's change is almost always
// at a yarn's free end: a contact adds a node just before the free node, a move or a
// take-up moves the free node. So each yarn is split: its settled part (all but its last
// TAIL nodes) is drawn into an off-screen image, and every frame shows that image plus the
// short live tails. When the tails grow long, or the updates pause, the split advances:
// only the newly settled segments (and contacts) are drawn into the image, on top of what
// it holds, so that cost follows the change and not the preform. The image is drawn whole
// again when the camera moves; the split is made again from scratch (and the image drawn
// whole) when a change reaches into a settled part or the colours change. A small preform
// is all tails: drawn whole each frame, which is cheaper than the image.
//
// The layers are view-layers.js; the textile views (presets, projection, axes, the section,
// picking) the other view-*.js. This file holds the model and the drawing loop.

import * as THREE from 'three';

import { mix } from './colours.js';
import { Axes, ScaleBar } from './view-axes.js';
import { ContactPoints, NodeTable, discTexture, mmPointsMaterial, sizePoints } from './view-batches.js';
import { CameraRig, PRESETS } from './view-camera.js';
import { Layers } from './view-layers.js';
import { MachineMarks } from './view-machine.js';
import { ViewTools } from './view-tools.js';
import { Yarn } from './view-yarn.js';

/** @import { ContactData, Machine, Skeleton, SkeletonDelta, XYZ, YarnData } from '../types/daemon' */
/** @import { Palette } from './colours.js' */

// Unlit lines: every colour goes to the screen exactly as given (and the settled image
// stores exactly what the screen shows).
THREE.ColorManagement.enabled = false;

const MAX_LIVE_NODES = 12000; // longer tails than this in all: the split advances
const FLOW_MS = 1000; // updates flow while the last instruction's change is younger than this
const BACKGROUND = 0xf3f4f6;
const CONTACT_COLOUR = 0xe67e22;

/**
 * Whether WebGL is drawn by the CPU (SwiftShader, llvmpipe: a PC without a graphics card).
 * There the view draws without antialiasing, which would cost it about half of every frame.
 */
export function softwareWebGL() {
  try {
    const gl = document.createElement('canvas').getContext('webgl2');
    if (!gl) return true;
    const info = gl.getExtension('WEBGL_debug_renderer_info');
    const name = String(gl.getParameter(info ? info.UNMASKED_RENDERER_WEBGL : gl.RENDERER));
    gl.getExtension('WEBGL_lose_context')?.loseContext();
    return /swiftshader|llvmpipe|softpipe|software/i.test(name);
  } catch {
    return true;
  }
}

/** The canvas, its camera and controls, and everything drawn in it. */
export class PreformView {
  // The model, as `clear` sets it (the constructor calls it) and `load` and `applyDelta` fill it.
  /** @type {Map<number, Yarn>} yarn id -> Yarn */
  yarns;
  /** @type {NodeTable} every node's position, by id */
  nodes;
  /** @type {number} */
  nodeCount;
  /** @type {Map<number, number>} yarn id -> contacts it is in */
  contactsOf;
  /** @type {THREE.Box3} what the model spans */
  bounds;
  /** @type {Machine | null} */
  machine;
  /** @type {number} the yarn diameter, mm (0: centrelines only) */
  diameter;
  /** @type {number} the take-up, mm */
  takeup;
  /** @type {number[][] | null} the twin's cases: rows of yarn ids, -1 empty */
  occupancy;
  /** @type {boolean} the machine's marks must be drawn again */
  machineDirty;
  /** @type {number | undefined} the canvas's size in CSS pixels, once laid out */
  width;
  /** @type {number | undefined} */
  height;

  /**
   * @param {HTMLCanvasElement} canvas the <canvas> to draw in
   * @param {Palette} palette the yarn colours (colours.js)
   * @param {() => void} requestFrame called when the view wants a frame drawn
   */
  constructor(canvas, palette, requestFrame) {
    this.canvas = canvas;
    this.palette = palette;
    this.requestFrame = requestFrame;
    this.needsRender = true;

    this.software = softwareWebGL();
    const renderer = new THREE.WebGLRenderer({ canvas, antialias: !this.software, preserveDrawingBuffer: true });
    renderer.outputColorSpace = THREE.LinearSRGBColorSpace; // colours as given (see above)
    renderer.setPixelRatio(Math.min(window.devicePixelRatio || 1, 2));
    renderer.setClearColor(BACKGROUND, 1);
    renderer.autoClear = false; // a frame is the settled image (or nothing), then the live parts
    renderer.localClippingEnabled = true; // the section's cut
    this.renderer = renderer;

    this.rig = new CameraRig(canvas, () => this.invalidate(true));
    // After "fit" the camera follows the growing preform, until the operator moves it.
    this.following = true;
    this.fittedTop = Infinity;
    this.rig.controls.addEventListener('start', () => {
      if (this.rig.isSoft) this.fit(); // the operator takes a real camera
      this.following = false;
    });
    this.lastDeltaAt = -Infinity; // when the last instruction's change came

    this.layers = new Layers(this);
    const { liveScene } = this.layers;

    this.machineMarks = new MachineMarks();
    for (const object of this.machineMarks.objects) liveScene.add(object);
    const host = canvas.parentElement;
    if (!host) throw new Error("the view's canvas is not in the page");
    this.host = host;
    this.axes = new Axes(part(host, '.view-labels'));
    liveScene.add(this.axes.lines);
    this.scaleBar = new ScaleBar(part(host, '.view-scale'));

    // Contacts: node pairs always kept; their points built when first shown.
    this.contactNodes = new Int32Array(2 * 1024); // [moving node, hit node] per contact
    this.contactCount = 0;
    this.contactMaterial = mmPointsMaterial({ color: CONTACT_COLOUR, map: discTexture(false) });
    /** @type {ContactPoints | null} */
    this.contactPoints = null;
    this.showContacts = false;

    /** @type {number | null} the yarn that stands out, the others dimmed */
    this.highlighted = null;

    this.tools = new ViewTools(this);
    // Called with a yarn's id when the operator clicks on it (in 3D or in the section), null
    // on empty space; the page may set its own (and call `highlight` in it to keep this).
    /** @type {(id: number | null) => void} */
    this.onPick = (id) => this.highlight(id);
    // Called when the colours changed on their own (not by `setColourMode`): the zones of a
    // program's section line arrived, or a pause refreshed the colours; the page repaints
    // what shares the palette (the matrix, the legend).
    /** @type {(() => void) | null} */
    this.onColoursChanged = null;
    this.clear();
    new ResizeObserver(() => this.resize()).observe(host);
    this.resize();
  }

  get camera() {
    return this.rig.camera;
  }

  /** Ask for a frame; `image`: the settled image must be drawn whole again too (camera, size, cut). */
  invalidate(image = false) {
    if (image) this.layers.imageDirty = true;
    this.needsRender = true;
    this.requestFrame();
  }

  resize() {
    const { clientWidth: width, clientHeight: height } = this.host;
    if (width === 0 || height === 0) return;
    this.width = width;
    this.height = height;
    this.renderer.setSize(width, height, false);
    const size = this.renderer.getDrawingBufferSize(new THREE.Vector2());
    this.layers.setSize(size.x, size.y);
    this.rig.setAspect(width / height);
    this.invalidate(true);
  }

  // ----- the whole skeleton -----

  /** Forget everything drawn (no program loaded). */
  clear() {
    this.yarns = new Map(); // yarn id -> Yarn
    this.nodes = new NodeTable();
    this.nodeCount = 0;
    this.layers.liveNodes = 0;
    this.contactCount = 0;
    this.contactsOf = new Map(); // yarn id -> contacts it is in
    this.dropContactPoints();
    this.bounds = new THREE.Box3();
    this.machine = null;
    this.diameter = 0;
    this.takeup = 0;
    this.occupancy = null;
    this.machineDirty = true;
    this.highlighted = null;
    this.palette.clear();
    this.tools.cleared();
    this.changed(true);
  }

  /**
   * Build the view of a whole skeleton (its JSON document).
   * @param {Skeleton} skeleton
   */
  load(skeleton) {
    const highlighted = this.highlighted;
    this.clear();
    this.machine = skeleton.machine;
    this.diameter = skeleton.diameter ?? skeleton.machine?.yarn_diameter ?? 0;
    this.takeup = skeleton.takeup;
    this.occupancy = skeleton.occupancy;
    for (const yarn of skeleton.yarns) this.addYarn(yarn);
    for (const contact of skeleton.contacts) this.addContact(contact);
    this.palette.recolour();
    if (highlighted !== null && this.yarns.has(highlighted)) this.highlighted = highlighted;
    this.includeGuides();
    this.tools.loaded();
    this.changed(true);
  }

  /** What is drawn must follow the model; `split`: make the settled/live split from scratch. */
  changed(split = false) {
    if (split) this.layers.splitDirty = true;
    this.layers.liveDirty = true;
    this.machineDirty = true;
    this.tools.modelChanged();
    this.invalidate(split);
  }

  /** @param {YarnData} data */
  addYarn(data) {
    const yarn = new Yarn(data, this.palette.add(data));
    this.yarns.set(yarn.id, yarn);
    for (let i = 0; i < yarn.count; i += 1) this.noteNode(yarn.nodeIds[i], data.nodes[i]);
    this.nodeCount += yarn.count;
    this.layers.liveNodes += yarn.count; // a new yarn is live until the next split
  }

  /**
   * @param {number} id
   * @param {XYZ} xyz
   */
  noteNode(id, xyz) {
    this.nodes.set(id, xyz);
    this.bounds.expandByPoint({ x: xyz[0], y: xyz[1], z: xyz[2] });
  }

  /** @param {ContactData} contact */
  addContact(contact) {
    if (2 * this.contactCount + 2 > this.contactNodes.length) {
      const bigger = new Int32Array(this.contactNodes.length * 2);
      bigger.set(this.contactNodes);
      this.contactNodes = bigger;
    }
    this.contactNodes.set(contact.nodes, 2 * this.contactCount);
    this.contactCount += 1;
    if (!contact.yarns) return;
    const [a, b] = contact.yarns;
    for (const id of [a, b]) this.contactsOf.set(id, (this.contactsOf.get(id) ?? 0) + 1);
    this.palette.noteContact(a, b);
  }

  /** Every yarn shown, in id order, as the skeleton JSON has it (for tests and diagnostics). */
  dump() {
    return this.yarnsInOrder().map((yarn) => yarn.dump());
  }

  yarnsInOrder() {
    return [...this.yarns.values()].sort((a, b) => a.id - b.id);
  }

  // ----- one instruction's change -----

  /**
   * Apply one skeleton delta (the "skeleton" of an instruction event) to the model; the
   * GPU gets it at the next frame. False when the delta does not fit what is shown (a
   * node it names is unknown): the caller then fetches the whole skeleton.
   * @param {SkeletonDelta} delta
   */
  applyDelta(delta) {
    for (const data of delta.new_yarns ?? []) {
      if (this.yarns.has(data.id)) return false;
      this.addYarn(data);
    }
    for (const { yarn: id, node, after, xyz } of delta.inserted ?? []) {
      const yarn = this.yarns.get(id);
      if (!yarn) return false;
      const at = yarn.insertAfter(after, node, xyz);
      if (at < 0) return false;
      this.layers.touched(yarn, at);
      this.noteNode(node, xyz);
      this.nodeCount += 1;
      this.layers.liveNodes += 1;
    }
    for (const { yarn: id, node, xyz } of delta.moved ?? []) {
      const yarn = this.yarns.get(id);
      if (!yarn) return false;
      const at = yarn.move(node, xyz);
      if (at < 0) return false;
      this.layers.touched(yarn, at, true);
      this.noteNode(node, xyz);
    }
    for (const contact of delta.contacts ?? []) this.addContact(contact);
    if (typeof delta.takeup === 'number') this.takeup = delta.takeup;
    if (delta.occupancy) this.occupancy = delta.occupancy;
    if (this.layers.liveNodes > MAX_LIVE_NODES) this.layers.advanceDirty = true;
    this.lastDeltaAt = performance.now();
    this.changed();
    return true;
  }

  /**
   * The updates paused: settle long tails, and (`recolour`, once the machine stands) let the
   * colours catch up with the contacts; a recolour draws the whole image again, too much at
   * every pause between two instructions of a run.
   */
  settleTails(recolour = true) {
    if (this.following && this.rig.isSoft) this.fit(); // a real camera again, the image drawn whole
    if (recolour && this.palette.refresh()) {
      this.changed(true);
      this.onColoursChanged?.();
      return;
    }
    if (this.layers.tailsLong) {
      this.layers.advanceDirty = true;
      this.invalidate();
    }
  }

  // ----- colours, contacts, highlight -----

  /**
   * Colour by a mode of colours.js (COLOUR_MODES: "yarn", "family", "zone", "contacts").
   * @param {string} mode
   */
  setColourMode(mode) {
    this.palette.setMode(mode);
    this.changed(true);
  }

  /**
   * The colour yarn `id` is drawn in now (dimmed while another yarn is highlighted).
   * @param {number} id
   */
  shownColour(id) {
    const colour = this.palette.colour(id);
    if (this.highlighted === null || id === this.highlighted) return colour;
    return dim(colour);
  }

  /** @param {boolean} visible */
  setContactsVisible(visible) {
    this.showContacts = visible;
    if (!visible) this.dropContactPoints(); // built at the next frame when shown
    this.changed(true); // a new split takes the points into the settled layer
  }

  dropContactPoints() {
    if (!this.contactPoints) return;
    this.layers.settledScene.remove(this.contactPoints.settledPoints);
    this.layers.liveScene.remove(this.contactPoints.livePoints);
    this.contactPoints.dispose();
    this.contactPoints = null;
  }

  /**
   * Make yarn `id` stand out, the others dimmed (null: none).
   * @param {number | null | undefined} id
   */
  highlight(id) {
    const next = id === null || id === undefined || !this.yarns.has(id) ? null : id;
    if (next === this.highlighted) return;
    this.highlighted = next;
    this.changed(true);
  }

  /**
   * {id, kind, family, contacts, length (mm along the polyline)}, or null for an unknown id.
   * @param {number} id
   */
  yarnInfo(id) {
    const yarn = this.yarns.get(id);
    if (!yarn) return null;
    return { id, kind: yarn.kind, family: yarn.family, contacts: this.contactsOf.get(id) ?? 0, length: yarn.length() };
  }

  // ----- the machine, and the region the camera frames -----

  /** Let the camera's box take in the whole matrix of guides. */
  includeGuides() {
    if (!this.machine) return;
    const { rows, cols, d_mat: dMat, pitch_x: px, pitch_y: py } = this.machine;
    this.bounds.expandByPoint({ x: 0, y: 0, z: 0 });
    this.bounds.expandByPoint({ x: (cols - 1) * px, y: (rows - 1) * py, z: dMat + this.takeup });
  }

  /**
   * Put the camera where the whole preform and the matrix are in view (or, in the top view
   * with the section cut, the preform below the cut), along the view chosen; with room above
   * for the preform to grow (a fifth of d_mat, or a quarter of its height if more) before the
   * camera follows it again.
   */
  fit(orthographic = this.rig.isOrthographic) {
    this.following = true;
    this.rig.fit(this.fitBox(), orthographic);
    this.invalidate(true);
  }

  /** What `fit` frames; sets the height past which the camera follows the preform. */
  fitBox() {
    let box = this.tools.focusBox(true);
    if (box) {
      this.fittedTop = Infinity; // looking down at the cut: growth does not leave the view
    } else {
      box = this.bounds.isEmpty()
        ? new THREE.Box3(new THREE.Vector3(-50, -50, 0), new THREE.Vector3(50, 50, 150))
        : this.bounds.clone();
      const height = box.max.z - Math.min(box.min.z, 0);
      if (this.machine) box.max.z += Math.max(0.2 * this.machine.d_mat, 0.25 * height);
      this.fittedTop = box.max.z;
    }
    this.drawMachine(); // the axes for this view
    if (this.axes.visible && this.axes.region) box.union(this.axes.region);
    return box;
  }

  /**
   * The preform grew out of the framing. While updates flow over a big preform, the picture
   * is only scaled and shifted (the settled image follows it without being drawn again);
   * otherwise the camera fits again.
   */
  follow() {
    const flowing = performance.now() - this.lastDeltaAt < FLOW_MS;
    if (this.layers.layered && flowing && this.rig.softFit(this.fitBox())) this.invalidate();
    else this.fit();
  }

  /**
   * Look along a preset view ("3d", "top", "front", "side"; view-camera.js) in its default projection.
   * @param {string | undefined} preset
   */
  setView(preset) {
    const chosen = preset !== undefined && PRESETS[preset] ? preset : '3d';
    this.rig.preset = chosen;
    this.tools.presetChosen(chosen);
    this.fit(PRESETS[chosen].orthographic);
    this.tools.syncControls();
  }

  /**
   * The orthographic projection (true) or perspective (false), keeping the view.
   * @param {boolean} on
   */
  setOrthographic(on) {
    this.rig.setOrthographic(on);
    this.invalidate(true);
    this.tools.syncControls();
  }

  /** @param {boolean} visible */
  setAxesVisible(visible) {
    this.axes.setVisible(visible);
    this.invalidate();
  }

  /**
   * Where points [[x, y, z], ...] of the preform frame fall on the canvas, CSS pixels from its
   * top left (NaN before the canvas is laid out).
   * @param {XYZ[]} points
   */
  project(points) {
    const v = new THREE.Vector3();
    const [width, height] = [this.width ?? NaN, this.height ?? NaN];
    this.camera.updateMatrixWorld();
    return points.map(([x, y, z]) => {
      v.set(x, y, z).project(this.camera);
      return [((v.x + 1) / 2) * width, ((1 - v.y) / 2) * height];
    });
  }

  // ----- the section (view-tools.js) -----

  /**
   * Show the section (its plane and crossings in 3D, and the 2D view beside).
   * @param {boolean} shown
   */
  setSectionShown(shown) {
    this.tools.setShown(shown);
  }

  /**
   * The section's height z, mm in the preform frame.
   * @param {number | string} z
   */
  setSectionHeight(z) {
    this.tools.setHeight(z);
  }

  /**
   * Hide everything above the section (true) or not.
   * @param {boolean} cut
   */
  setSectionCut(cut) {
    this.tools.setCut(cut);
  }

  /**
   * The crossings of the plane z = `z`, as `bwsd slice` finds them: [{yarn, x, y, free}].
   * @param {number | string} z
   */
  section(z) {
    return this.tools.crossingsAt(z);
  }

  /**
   * The braided section for colouring by zone: a written section (`L:2x6:4x2`), or a
   * program's text whose "# section: SPEC" line names one; null for none. Until this is
   * called, the view reads the loaded program's text from the daemon itself.
   * @param {string | null} text
   */
  setSection(text) {
    this.tools.setSection(text, true);
  }

  // ----- drawing -----

  /** Draw now (called from the page's animation frame): everything changed since the last. */
  render() {
    if (this.following && this.bounds.max.z > this.fittedTop) this.follow(); // it grew out of view
    if (this.showContacts && !this.contactPoints) {
      this.contactPoints = new ContactPoints(this.contactMaterial);
      this.layers.settledScene.add(this.contactPoints.settledPoints);
      this.layers.liveScene.add(this.contactPoints.livePoints);
    }
    this.contactPoints?.extend(this.contactNodes, this.contactCount, this.nodes);
    if (this.machineDirty) this.drawMachine();
    this.tools.beforeRender();

    this.layers.prepare();
    const camera = this.camera;
    this.contactMaterial.userData.diameter = this.diameter;
    for (const material of [this.contactMaterial, ...this.tools.pointMaterials]) {
      sizePoints(material, camera, this.height ?? 1, this.rig.soft.s);
    }
    this.layers.draw(this.renderer, camera);
    this.axes.place(camera, this.width ?? 1, this.height ?? 1);
    this.scaleBar.place(this.rig.isOrthographic ? this.rig.mmPerPixel(this.height ?? 1) : null, this.width ?? 1);
    this.needsRender = false;
  }

  drawMachine() {
    this.machineDirty = false;
    this.machineMarks.draw(this.machine, this.takeup, this.occupancy, (id) => this.shownColour(id));
    if (!this.machine) return;
    const focus = this.tools.focusBox(false); // the top view of the cut: axes around the preform
    if (focus) {
      this.axes.update(focus.min, focus.max);
      return;
    }
    const { rows, cols, pitch_x: px, pitch_y: py } = this.machine;
    const top = Math.max(this.bounds.max.z, this.machine.d_mat + this.takeup);
    this.axes.update(new THREE.Vector3(0, 0, 0), new THREE.Vector3((cols - 1) * px, (rows - 1) * py, top));
  }
}

/**
 * A colour faded towards the background: a yarn that is not the highlighted one.
 * @param {number} colour
 */
function dim(colour) {
  return mix(colour, BACKGROUND, 0.8);
}

/**
 * The element `selector` in `host` (the view's labels, its scale), or a detached one when
 * the page has none.
 * @param {HTMLElement} host
 * @param {string} selector
 */
function part(host, selector) {
  const found = host.querySelector(selector);
  return found instanceof HTMLElement ? found : document.createElement('div');
}
