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
// take-up moves the free node. So each yarn is split: its settled part (all but the last
// TAIL nodes when the layer was made) is drawn once into an off-screen image, and every
// frame shows that image plus the short live tails. The image is drawn again when the
// camera moves; the split is made again (and the image redrawn) when a change reaches into
// a settled part, the tails grow long, the colours change, or the updates pause. A small
// preform is all tails: drawn whole each frame, which is cheaper than the image.

import * as THREE from 'three';
import { OrbitControls } from 'three/addons/controls/OrbitControls.js';

// Unlit lines: every colour goes to the screen exactly as given (and the settled image
// stores exactly what the screen shows).
THREE.ColorManagement.enabled = false;

const FIRST_CAPACITY = 8; // nodes of a yarn's buffer, doubled as it grows
const TAIL = 8; // nodes at a yarn's free end kept live
const MAX_LIVE_NODES = 12000; // longer tails than this in all: split again
const LAYERS_FROM = 10000; // nodes: a smaller preform is drawn whole every frame
const RESTART = 0xffffffff; // ends a line strip in an index buffer (WebGL 2 primitive restart)
const BACKGROUND = 0xf3f4f6;
const CONTACT_COLOUR = 0xe67e22;
const FELL_COLOUR = 0xb7791f; // amber: the fell plane, outlined and lightly filled
const MATRIX_COLOUR = 0xa0aec0;
const EMPTY_GUIDE_COLOUR = 0xb8bec8;
const VIEW_DIRECTION = new THREE.Vector3(1.0, -1.5, 0.8).normalize(); // front right, a bit above

/** Smallest power of two ≥ n (and ≥ FIRST_CAPACITY). */
function capacityFor(n) {
  let capacity = FIRST_CAPACITY;
  while (capacity < n) capacity *= 2;
  return capacity;
}

/** One yarn: its node ids and coordinates (exactly as the daemon sent them). */
class Yarn {
  constructor(data, family) {
    this.id = data.id;
    this.kind = data.kind;
    this.family = family;
    this.nodeIds = Array.from(data.node_ids); // in order along the yarn
    this.count = this.nodeIds.length;
    // A warp keeps growing (every contact adds a node); a weft starts as two fixed nodes.
    this.xyz = new Float64Array(capacityFor(this.kind === 'warp' ? this.count * 2 : this.count) * 3);
    data.nodes.forEach((p, i) => this.xyz.set(p, 3 * i));
    this.settled = 1; // nodes [0, settled) are in the settled layer, [settled - 1, count) live
  }

  /** Where node `nodeId` is along the yarn (searched from the free end, where changes are). */
  indexOf(nodeId) {
    return this.nodeIds.lastIndexOf(nodeId);
  }

  /** Insert node `nodeId` at `xyz` after node `after` (-1: at the start); its index, -1 if unknown. */
  insertAfter(after, nodeId, xyz) {
    let at = 0;
    if (after !== -1) {
      at = this.indexOf(after) + 1;
      if (at === 0) return -1;
    }
    if (3 * (this.count + 1) > this.xyz.length) {
      const bigger = new Float64Array(this.xyz.length * 2);
      bigger.set(this.xyz.subarray(0, 3 * this.count));
      this.xyz = bigger;
    }
    this.xyz.copyWithin(3 * (at + 1), 3 * at, 3 * this.count);
    this.xyz.set(xyz, 3 * at);
    this.nodeIds.splice(at, 0, nodeId);
    this.count += 1;
    if (at < this.settled) this.settled += 1; // (the split is made again before the next image)
    return at;
  }

  /** Node `nodeId` moved to `xyz`; its index, -1 if the yarn has no such node. */
  move(nodeId, xyz) {
    const i = this.indexOf(nodeId);
    if (i >= 0) this.xyz.set(xyz, 3 * i);
    return i;
  }

  /** The yarn as the skeleton JSON has it: {id, node_ids, nodes: [[x, y, z], ...]}. */
  dump() {
    const nodes = [];
    for (let i = 0; i < this.count; i += 1) nodes.push(Array.from(this.xyz.subarray(3 * i, 3 * i + 3)));
    return { id: this.id, node_ids: this.nodeIds.slice(), nodes };
  }
}

/**
 * Many polylines in one draw call: one line strip each, ended by a restart index, each
 * in its own colour. Rebuilt in place (`begin`, `add`..., `end`); the buffers grow as needed.
 */
class StripBatch {
  constructor() {
    this.line = new THREE.Line(new THREE.BufferGeometry(), new THREE.LineBasicMaterial({ vertexColors: true }));
    this.line.frustumCulled = false; // its bounds change all the time
    this.allocate(1024);
    this.begin();
  }

  allocate(vertices) {
    const old = this.vertices ? { positions: this.positions, colours: this.colours, index: this.index } : null;
    this.positions = new Float32Array(3 * vertices);
    this.colours = new Uint8Array(3 * vertices);
    this.index = new Uint32Array(2 * vertices); // a strip of n nodes takes n + 1 indices
    if (old) {
      this.positions.set(old.positions.subarray(0, 3 * this.vertices));
      this.colours.set(old.colours.subarray(0, 3 * this.vertices));
      this.index.set(old.index.subarray(0, this.indices));
    }
    this.regrown = true;
  }

  begin() {
    this.vertices = 0;
    this.indices = 0;
  }

  /** Nodes [from, to) of `xyz` (a yarn's coordinates) as one strip of colour 0xRRGGBB. */
  add(xyz, from, to, colour) {
    const n = to - from;
    if (n < 2) return;
    if (3 * (this.vertices + n) > this.positions.length || this.indices + n + 1 > this.index.length) {
      this.allocate(capacityFor(2 * (this.vertices + n)));
    }
    const first = this.vertices;
    this.positions.set(xyz.subarray(3 * from, 3 * to), 3 * first);
    const [r, g, b] = [(colour >> 16) & 255, (colour >> 8) & 255, colour & 255];
    for (let k = 0; k < n; k += 1) {
      this.colours[3 * (first + k)] = r;
      this.colours[3 * (first + k) + 1] = g;
      this.colours[3 * (first + k) + 2] = b;
      this.index[this.indices + k] = first + k;
    }
    this.index[this.indices + n] = RESTART;
    this.vertices += n;
    this.indices += n + 1;
  }

  /** Hand the batch to the GPU: the parts in use only, or new buffers when they grew. */
  end() {
    let geometry = this.line.geometry;
    if (this.regrown) {
      geometry.dispose();
      geometry = new THREE.BufferGeometry();
      geometry.setAttribute('position', new THREE.BufferAttribute(this.positions, 3).setUsage(THREE.DynamicDrawUsage));
      geometry.setAttribute('color', new THREE.BufferAttribute(this.colours, 3, true).setUsage(THREE.DynamicDrawUsage));
      geometry.setIndex(new THREE.BufferAttribute(this.index, 1).setUsage(THREE.DynamicDrawUsage));
      this.line.geometry = geometry;
      this.regrown = false;
    } else {
      for (const [attribute, used] of [
        [geometry.getAttribute('position'), 3 * this.vertices],
        [geometry.getAttribute('color'), 3 * this.vertices],
        [geometry.getIndex(), this.indices],
      ]) {
        if (used === 0) continue;
        attribute.addUpdateRange(0, used);
        attribute.needsUpdate = true;
      }
    }
    geometry.setDrawRange(0, this.indices);
  }

  dispose() {
    this.line.geometry.dispose();
    this.line.material.dispose();
  }
}

/** A growable Float32Array of xyz triples, indexed by node id (contacts need positions by id). */
class NodeTable {
  constructor() {
    this.xyz = new Float32Array(3 * 1024);
  }

  set(id, xyz) {
    if (3 * id + 3 > this.xyz.length) {
      let size = this.xyz.length;
      while (size < 3 * id + 3) size *= 2;
      const bigger = new Float32Array(size);
      bigger.set(this.xyz);
      this.xyz = bigger;
    }
    this.xyz.set(xyz, 3 * id);
  }
}

/** Contact links: one segment per contact, joining its two nodes; settled and live parts. */
class ContactLinks {
  constructor() {
    const material = new THREE.LineBasicMaterial({ color: CONTACT_COLOUR });
    this.settledLinks = new THREE.LineSegments(undefined, material);
    this.liveLinks = new THREE.LineSegments(undefined, material);
    this.settledLinks.frustumCulled = this.liveLinks.frustumCulled = false;
    this.array = new Float32Array(6 * 1024);
    this.makeGeometries();
    this.shown = 0; // contacts in the buffer
    this.settled = 0; // contacts in the settled layer
  }

  makeGeometries() {
    this.attribute = new THREE.BufferAttribute(this.array, 3).setUsage(THREE.DynamicDrawUsage);
    for (const links of [this.settledLinks, this.liveLinks]) {
      links.geometry.dispose();
      links.geometry = new THREE.BufferGeometry();
      links.geometry.setAttribute('position', this.attribute); // one buffer, two ranges
    }
  }

  /** Append contacts [shown, count) of `nodes` (pairs of node ids) at `table` positions. */
  extend(nodes, count, table) {
    if (count === this.shown) return;
    const from = this.shown;
    if (6 * count > this.array.length) {
      const bigger = new Float32Array(capacityFor(count) * 6);
      bigger.set(this.array.subarray(0, 6 * from));
      this.array = bigger;
      this.makeGeometries();
    } else {
      this.attribute.addUpdateRange(6 * from, 6 * (count - from));
      this.attribute.needsUpdate = true;
    }
    const xyz = table.xyz;
    for (let c = from; c < count; c += 1) {
      for (let end = 0; end < 2; end += 1) {
        const node = nodes[2 * c + end];
        this.array.set(xyz.subarray(3 * node, 3 * node + 3), 6 * c + 3 * end);
      }
    }
    this.shown = count;
    this.setRanges();
  }

  setRanges() {
    this.settledLinks.geometry.setDrawRange(0, 2 * this.settled);
    this.liveLinks.geometry.setDrawRange(2 * this.settled, 2 * (this.shown - this.settled));
  }

  /** Every contact shown goes into the settled layer (or back to live: `settled` false). */
  settle(settled = true) {
    this.settled = settled ? this.shown : 0;
    this.setRanges();
  }

  dispose() {
    this.settledLinks.geometry.dispose();
    this.liveLinks.geometry.dispose();
    this.settledLinks.material.dispose();
  }
}

/** The canvas, its camera and controls, and everything drawn in it. */
export class PreformView {
  /**
   * @param canvas the <canvas> to draw in
   * @param palette the yarn colours (colours.js)
   * @param requestFrame called when the view wants a frame drawn
   */
  constructor(canvas, palette, requestFrame) {
    this.canvas = canvas;
    this.palette = palette;
    this.requestFrame = requestFrame;
    this.needsRender = true;

    const renderer = new THREE.WebGLRenderer({ canvas, antialias: true, preserveDrawingBuffer: true });
    renderer.outputColorSpace = THREE.LinearSRGBColorSpace; // colours as given (see above)
    renderer.setPixelRatio(Math.min(window.devicePixelRatio || 1, 2));
    renderer.setClearColor(BACKGROUND, 1);
    renderer.autoClear = false; // a frame is the settled image (or nothing), then the live parts
    this.renderer = renderer;

    this.camera = new THREE.PerspectiveCamera(35, 1, 0.1, 10000);
    this.camera.up.set(0, 0, 1); // z up: the preform grows along +z
    this.camera.position.set(100, -150, 80);
    this.controls = new OrbitControls(this.camera, canvas);
    this.controls.addEventListener('change', () => this.invalidate(true));
    // After "fit" the camera follows the growing preform, until the operator moves it.
    this.following = true;
    this.fittedTop = Infinity;
    this.controls.addEventListener('start', () => {
      this.following = false;
    });

    // The layers: settled (drawn into `settledImage` now and then) and live (every frame).
    this.settledScene = new THREE.Scene();
    this.liveScene = new THREE.Scene();
    this.settledYarns = new StripBatch();
    this.liveYarns = new StripBatch();
    this.settledScene.add(this.settledYarns.line);
    this.liveScene.add(this.liveYarns.line);
    this.settledImage = new THREE.WebGLRenderTarget(1, 1, { samples: 4 });
    this.settledImage.texture.minFilter = this.settledImage.texture.magFilter = THREE.NearestFilter;
    this.layered = false; // whether the settled image is in use
    this.imageDirty = true; // the image must be drawn again (camera, size, new split)
    this.splitDirty = true; // the split between settled and live must be made again
    this.liveDirty = true; // the live batch must be rebuilt
    this.liveNodes = 0; // nodes drawn live, all yarns together
    // The settled image is shown by one screen-filling quad.
    this.imageCamera = new THREE.OrthographicCamera(-1, 1, 1, -1, 0, 1);
    this.imageScene = new THREE.Scene();
    this.imageScene.add(new THREE.Mesh(
      new THREE.PlaneGeometry(2, 2),
      new THREE.MeshBasicMaterial({ map: this.settledImage.texture, depthTest: false, depthWrite: false }),
    ));

    // Machine decorations (drawn live, on top: a few points and lines): the converged
    // matrix at the fell, the guides, the outline of the matrix.
    this.fell = new THREE.LineLoop(new THREE.BufferGeometry(), new THREE.LineBasicMaterial({ color: FELL_COLOUR }));
    this.fellPlane = new THREE.Mesh(new THREE.BufferGeometry(), new THREE.MeshBasicMaterial({
      color: FELL_COLOUR, transparent: true, opacity: 0.18, depthWrite: false, side: THREE.DoubleSide,
    }));
    this.matrixOutline = new THREE.LineLoop(new THREE.BufferGeometry(), new THREE.LineBasicMaterial({ color: MATRIX_COLOUR }));
    this.guides = new THREE.Points(new THREE.BufferGeometry(), new THREE.PointsMaterial({ vertexColors: true }));
    for (const decoration of [this.fellPlane, this.fell, this.matrixOutline, this.guides]) {
      decoration.frustumCulled = false;
      decoration.visible = false;
      // Always in front, drawn last: the same whether the yarns around are settled or live.
      decoration.material.depthTest = false;
      decoration.renderOrder = 1;
      this.liveScene.add(decoration);
    }

    // Contacts: node pairs always kept; their links built when first shown.
    this.contactNodes = new Int32Array(2 * 1024); // [moving node, hit node] per contact
    this.contactCount = 0;
    this.links = null;
    this.showContacts = false;

    this.clear();
    new ResizeObserver(() => this.resize()).observe(canvas.parentElement);
    this.resize();
  }

  /** Ask for a frame; `image`: the settled image must be drawn again too (camera, size). */
  invalidate(image = false) {
    if (image) this.imageDirty = true;
    this.needsRender = true;
    this.requestFrame();
  }

  resize() {
    const { clientWidth: width, clientHeight: height } = this.canvas.parentElement;
    if (width === 0 || height === 0) return;
    this.renderer.setSize(width, height, false);
    const size = this.renderer.getDrawingBufferSize(new THREE.Vector2());
    this.settledImage.setSize(size.x, size.y);
    this.camera.aspect = width / height;
    this.camera.updateProjectionMatrix();
    this.invalidate(true);
  }

  // ----- the whole skeleton -----

  /** Forget everything drawn (no program loaded). */
  clear() {
    this.yarns = new Map(); // yarn id -> Yarn
    this.nodes = new NodeTable();
    this.nodeCount = 0;
    this.liveNodes = 0;
    this.contactCount = 0;
    this.dropContactLinks();
    this.bounds = new THREE.Box3();
    this.machine = null;
    this.takeup = 0;
    this.occupancy = null;
    this.machineDirty = true;
    this.palette.clear();
    this.changed(true);
  }

  /** Build the view of a whole skeleton (its JSON document). */
  load(skeleton) {
    this.clear();
    this.machine = skeleton.machine;
    this.takeup = skeleton.takeup;
    this.occupancy = skeleton.occupancy;
    for (const yarn of skeleton.yarns) this.addYarn(yarn);
    for (const contact of skeleton.contacts) this.addContact(contact);
    this.includeGuides();
    this.changed(true);
  }

  /** What is drawn must follow the model; `split`: make the settled/live split again. */
  changed(split = false) {
    if (split) this.splitDirty = true;
    this.liveDirty = true;
    this.machineDirty = true;
    this.invalidate(split);
  }

  addYarn(data) {
    const yarn = new Yarn(data, this.palette.add(data));
    this.yarns.set(yarn.id, yarn);
    for (let i = 0; i < yarn.count; i += 1) this.noteNode(yarn.nodeIds[i], data.nodes[i]);
    this.nodeCount += yarn.count;
    this.liveNodes += yarn.count; // a new yarn is live until the next split
  }

  noteNode(id, xyz) {
    this.nodes.set(id, xyz);
    this.bounds.expandByPoint({ x: xyz[0], y: xyz[1], z: xyz[2] });
  }

  addContact(contact) {
    if (2 * this.contactCount + 2 > this.contactNodes.length) {
      const bigger = new Int32Array(this.contactNodes.length * 2);
      bigger.set(this.contactNodes);
      this.contactNodes = bigger;
    }
    this.contactNodes.set(contact.nodes, 2 * this.contactCount);
    this.contactCount += 1;
  }

  /** Every yarn shown, in id order, as the skeleton JSON has it (for tests and diagnostics). */
  dump() {
    return [...this.yarns.values()].sort((a, b) => a.id - b.id).map((yarn) => yarn.dump());
  }

  // ----- one instruction's change -----

  /**
   * Apply one skeleton delta (the "skeleton" of an instruction event) to the model; the
   * GPU gets it at the next frame. False when the delta does not fit what is shown (a
   * node it names is unknown): the caller then fetches the whole skeleton.
   */
  applyDelta(delta) {
    for (const data of delta.new_yarns ?? []) {
      if (this.yarns.has(data.id)) return false;
      this.addYarn(data);
    }
    for (const { yarn: id, node, after, xyz } of delta.inserted ?? []) {
      const yarn = this.yarns.get(id);
      const at = yarn ? yarn.insertAfter(after, node, xyz) : -1;
      if (at < 0) return false;
      if (at < yarn.settled - 1) this.splitDirty = true; // it reached into the settled part
      this.noteNode(node, xyz);
      this.nodeCount += 1;
      this.liveNodes += 1;
    }
    for (const { yarn: id, node, xyz } of delta.moved ?? []) {
      const yarn = this.yarns.get(id);
      const at = yarn ? yarn.move(node, xyz) : -1;
      if (at < 0) return false;
      if (at < yarn.settled) this.splitDirty = true;
      this.noteNode(node, xyz);
    }
    for (const contact of delta.contacts ?? []) this.addContact(contact);
    if (typeof delta.takeup === 'number') this.takeup = delta.takeup;
    if (delta.occupancy) this.occupancy = delta.occupancy;
    if (this.liveNodes > MAX_LIVE_NODES) this.splitDirty = true;
    this.changed();
    return true;
  }

  /** The updates paused: a good moment to settle long tails (one full drawing). */
  settleTails() {
    if (this.layered && this.liveNodes > 2 * TAIL * Math.max(1, this.yarns.size)) this.changed(true);
  }

  // ----- colours -----

  /** Colour by "family" or by "yarn". */
  setColourMode(mode) {
    this.palette.mode = mode;
    this.changed(true);
  }

  // ----- contact links -----

  setContactsVisible(visible) {
    this.showContacts = visible;
    if (!visible) this.dropContactLinks(); // built at the next frame when shown
    this.changed(true); // a new split takes the links into the settled layer
  }

  dropContactLinks() {
    if (!this.links) return;
    this.settledScene.remove(this.links.settledLinks);
    this.liveScene.remove(this.links.liveLinks);
    this.links.dispose();
    this.links = null;
  }

  // ----- the machine: fell line, guides, matrix -----

  /** Guide of cell (row, col) in the matrix plane: x = col * pitch_x, y = row * pitch_y. */
  guideXY(row, col) {
    return [col * this.machine.pitch_x, row * this.machine.pitch_y];
  }

  /** Let the camera's box take in the whole matrix of guides. */
  includeGuides() {
    if (!this.machine) return;
    const { rows, cols, d_mat: dMat } = this.machine;
    const [x, y] = this.guideXY(rows - 1, cols - 1);
    this.bounds.expandByPoint({ x: 0, y: 0, z: 0 });
    this.bounds.expandByPoint({ x, y, z: dMat + this.takeup });
  }

  /** Redraw the fell outline, the matrix outline and the guides (cheap: rows × cols points). */
  drawMachine() {
    this.machineDirty = false;
    const machine = this.machine;
    const shown = Boolean(machine);
    this.fell.visible = this.fellPlane.visible = this.matrixOutline.visible = this.guides.visible = shown;
    if (!shown) return;
    const { rows, cols, c_mat: cMat, d_mat: dMat } = machine;
    const [xMax, yMax] = this.guideXY(rows - 1, cols - 1);
    const [ox, oy] = [xMax / 2, yMax / 2]; // O, the centre of the matrix
    const guideZ = dMat + this.takeup;

    // The converged matrix at the fell: centred on O, c_mat times the matrix's half extent.
    this.fell.geometry.dispose();
    this.fell.geometry = rectangle(ox, oy, cMat * (xMax / 2), cMat * (yMax / 2), this.takeup);
    this.fellPlane.geometry.dispose();
    this.fellPlane.geometry = this.fell.geometry.clone().setIndex([0, 1, 2, 0, 2, 3]);
    this.matrixOutline.geometry.dispose();
    this.matrixOutline.geometry = rectangle(ox, oy, xMax / 2, yMax / 2, guideZ);

    // The guides: occupied cells in their yarn's colour, empty ones grey.
    const positions = new Float32Array(rows * cols * 3);
    const colours = new Float32Array(rows * cols * 3);
    const colour = new THREE.Color();
    for (let r = 0; r < rows; r += 1) {
      for (let c = 0; c < cols; c += 1) {
        const i = r * cols + c;
        const [x, y] = this.guideXY(r, c);
        positions.set([x, y, guideZ], 3 * i);
        const yarn = this.occupancy?.[r]?.[c] ?? -1;
        colour.setHex(yarn >= 0 ? this.palette.colour(yarn) : EMPTY_GUIDE_COLOUR);
        colours.set([colour.r, colour.g, colour.b], 3 * i);
      }
    }
    const geometry = new THREE.BufferGeometry();
    geometry.setAttribute('position', new THREE.BufferAttribute(positions, 3));
    geometry.setAttribute('color', new THREE.BufferAttribute(colours, 3));
    this.guides.material.size = 0.35 * Math.min(machine.pitch_x, machine.pitch_y); // mm: a case, roughly
    this.guides.geometry.dispose();
    this.guides.geometry = geometry;
  }

  // ----- camera -----

  /**
   * Put the camera where the whole preform and the matrix are in view, with room above
   * for the preform to grow (a fifth of d_mat) before the camera follows it again.
   */
  fit() {
    const box = this.bounds.isEmpty()
      ? new THREE.Box3(new THREE.Vector3(-50, -50, 0), new THREE.Vector3(50, 50, 150))
      : this.bounds.clone();
    if (this.machine) box.max.z += 0.2 * this.machine.d_mat;
    this.fittedTop = box.max.z;
    this.following = true;
    const centre = box.getCenter(new THREE.Vector3());
    const radius = Math.max(box.getSize(new THREE.Vector3()).length() / 2, 1);
    const camera = this.camera;
    const halfFov = THREE.MathUtils.degToRad(camera.fov / 2);
    const halfFovAcross = Math.atan(Math.tan(halfFov) * camera.aspect);
    const distance = (radius / Math.sin(Math.min(halfFov, halfFovAcross))) * 1.02;
    camera.position.copy(centre).addScaledVector(VIEW_DIRECTION, distance);
    camera.near = distance / 100;
    camera.far = distance * 10;
    camera.updateProjectionMatrix();
    this.controls.target.copy(centre);
    this.controls.update();
    this.invalidate(true);
  }

  // ----- drawing -----

  /** Draw now (called from the page's animation frame): everything changed since the last. */
  render() {
    if (this.following && this.bounds.max.z > this.fittedTop) this.fit(); // it grew out of view
    if (this.showContacts && !this.links) {
      this.links = new ContactLinks();
      this.settledScene.add(this.links.settledLinks);
      this.liveScene.add(this.links.liveLinks);
    }
    this.links?.extend(this.contactNodes, this.contactCount, this.nodes);
    if (this.machineDirty) this.drawMachine();

    const renderer = this.renderer;
    const layered = this.nodeCount + 2 * this.contactCount >= LAYERS_FROM;
    if (layered !== this.layered) {
      this.layered = layered;
      this.splitDirty = true;
    }
    if (layered && this.splitDirty) this.split();
    if (!layered && this.splitDirty) this.unsplit();
    if (this.liveDirty) this.buildLive();
    renderer.setRenderTarget(null);
    renderer.clear();
    if (layered) {
      if (this.imageDirty) this.drawImage();
      renderer.render(this.imageScene, this.imageCamera);
    }
    renderer.render(this.liveScene, this.camera);
    this.needsRender = false;
  }

  /** Settle every yarn but its last TAIL nodes, and rebuild the settled batch. */
  split() {
    const batch = this.settledYarns;
    batch.begin();
    this.liveNodes = 0;
    for (const yarn of this.yarns.values()) {
      yarn.settled = Math.max(1, yarn.count - TAIL);
      this.liveNodes += yarn.count - yarn.settled + 1;
      batch.add(yarn.xyz, 0, yarn.settled, this.palette.colour(yarn.id));
    }
    batch.end();
    this.links?.settle();
    this.splitDirty = false;
    this.imageDirty = true;
    this.liveDirty = true;
  }

  /** A small preform: nothing settled, all live. */
  unsplit() {
    this.settledYarns.begin();
    this.settledYarns.end();
    for (const yarn of this.yarns.values()) yarn.settled = 1;
    this.liveNodes = this.nodeCount;
    this.links?.settle(false);
    this.splitDirty = false;
    this.liveDirty = true;
  }

  /** The live tails of every yarn, in one batch. */
  buildLive() {
    const batch = this.liveYarns;
    batch.begin();
    for (const yarn of this.yarns.values()) {
      batch.add(yarn.xyz, yarn.settled - 1, yarn.count, this.palette.colour(yarn.id));
    }
    batch.end();
    this.liveDirty = false;
  }

  /** Draw the settled layer into its image (the costly part of a big preform). */
  drawImage() {
    const renderer = this.renderer;
    renderer.setRenderTarget(this.settledImage);
    renderer.clear();
    renderer.render(this.settledScene, this.camera);
    renderer.setRenderTarget(null);
    this.imageDirty = false;
  }
}

/** A closed rectangle centred on (ox, oy) at height z, half sizes hx × hy. */
function rectangle(ox, oy, hx, hy, z) {
  const points = [
    ox - hx, oy - hy, z,
    ox + hx, oy - hy, z,
    ox + hx, oy + hy, z,
    ox - hx, oy + hy, z,
  ];
  const geometry = new THREE.BufferGeometry();
  geometry.setAttribute('position', new THREE.Float32BufferAttribute(points, 3));
  return geometry;
}
