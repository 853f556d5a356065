// @ts-check
// What the 3D view hands the GPU: yarn polylines batched into few draw calls, node
// positions by id, and contact points. Buffers grow by doubling and are uploaded in the
// parts that changed only.

import * as THREE from 'three';

/** @import { ViewCamera } from './view-camera.js' */

const FIRST_CAPACITY = 8;
const RESTART = 0xffffffff; // ends a line strip in an index buffer (WebGL 2 primitive restart)
export const MIN_POINT_PX = 3; // a point never shrinks below this (a centreline-only model)

/**
 * Smallest power of two ≥ n (and ≥ 8).
 * @param {number} n
 */
export function capacityFor(n) {
  let capacity = FIRST_CAPACITY;
  while (capacity < n) capacity *= 2;
  return capacity;
}

/**
 * Many polylines in one draw call: one line strip each, ended by a restart index, each
 * in its own colour. Built by `begin`, `add`..., `end`; `add` after an `end` appends, and
 * the next `end` uploads only what was appended. `drawFrom(mark)` limits the draw to what
 * was added since `mark` (the indices then), `drawAll()` undoes it.
 */
export class StripBatch {
  // What `allocate` and `begin` set (the constructor calls both).
  /** @type {Float32Array} xyz per vertex */
  positions;
  /** @type {Uint8Array} rgb per vertex */
  colours;
  /** @type {Uint32Array} the strips' vertices, each strip ended by RESTART */
  index;
  /** @type {boolean} the buffers were made anew: `end` hands the GPU new ones */
  regrown;
  /** @type {number} vertices in the batch */
  vertices;
  /** @type {number} indices in the batch */
  indices;
  /** @type {number} */
  uploadedVertices;
  /** @type {number} */
  uploadedIndices;

  /** @param {THREE.LineBasicMaterial} material */
  constructor(material) {
    this.line = new THREE.Line(new THREE.BufferGeometry(), material);
    this.line.frustumCulled = false; // its bounds change all the time
    /** @type {THREE.BufferAttribute[]} position, colour and index: what `end` uploads */
    this.attributes = [];
    this.allocate(1024);
    this.begin();
  }

  /** @param {number} vertices */
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
    this.uploadedVertices = 0;
    this.uploadedIndices = 0;
  }

  /**
   * Nodes [from, to) of `xyz` (a yarn's coordinates) as one strip of colour 0xRRGGBB.
   * @param {Float64Array} xyz
   * @param {number} from
   * @param {number} to
   * @param {number} colour
   */
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

  /** Hand the batch to the GPU: what changed since the last `end`, or new buffers when they grew. */
  end() {
    let geometry = this.line.geometry;
    if (this.regrown) {
      geometry.dispose();
      geometry = new THREE.BufferGeometry();
      const position = new THREE.BufferAttribute(this.positions, 3).setUsage(THREE.DynamicDrawUsage);
      const colour = new THREE.BufferAttribute(this.colours, 3, true).setUsage(THREE.DynamicDrawUsage);
      const index = new THREE.BufferAttribute(this.index, 1).setUsage(THREE.DynamicDrawUsage);
      geometry.setAttribute('position', position);
      geometry.setAttribute('color', colour);
      geometry.setIndex(index);
      this.attributes = [position, colour, index];
      this.line.geometry = geometry;
      this.regrown = false;
    } else {
      const [v0, i0] = [this.uploadedVertices, this.uploadedIndices];
      const [position, colour, index] = this.attributes;
      /** @type {[THREE.BufferAttribute, number, number][]} */
      const parts = [
        [position, 3 * v0, 3 * this.vertices],
        [colour, 3 * v0, 3 * this.vertices],
        [index, i0, this.indices],
      ];
      for (const [attribute, from, to] of parts) {
        if (to <= from) continue;
        attribute.addUpdateRange(from, to - from);
        attribute.needsUpdate = true;
      }
    }
    this.uploadedVertices = this.vertices;
    this.uploadedIndices = this.indices;
    this.drawAll();
  }

  /** Where the next strip goes (for `drawFrom`). */
  mark() {
    return this.indices;
  }

  /** @param {number} mark */
  drawFrom(mark) {
    this.line.geometry.setDrawRange(mark, this.indices - mark);
  }

  drawAll() {
    this.line.geometry.setDrawRange(0, this.indices);
  }

  dispose() {
    this.line.geometry.dispose();
  }
}

/** A growable Float32Array of xyz triples, indexed by node id (contacts need positions by id). */
export class NodeTable {
  constructor() {
    this.xyz = new Float32Array(3 * 1024);
  }

  /**
   * @param {number} id
   * @param {ArrayLike<number>} xyz
   */
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

/** A round point sprite: a disc (`ring` false) with a dark rim, or a ring only. */
export function discTexture(ring = false) {
  const size = 64;
  const canvas = document.createElement('canvas');
  canvas.width = canvas.height = size;
  const g = canvas.getContext('2d');
  if (!g) throw new Error('no 2D canvas context');
  g.beginPath();
  g.arc(size / 2, size / 2, size / 2 - 2, 0, 2 * Math.PI);
  if (!ring) {
    g.fillStyle = '#fff';
    g.fill();
  }
  g.lineWidth = ring ? 8 : 5;
  g.strokeStyle = ring ? '#fff' : '#333';
  g.stroke();
  const texture = new THREE.CanvasTexture(canvas);
  texture.colorSpace = THREE.NoColorSpace;
  return texture;
}

/**
 * Round points of a size in mm (`diameter`), whatever the camera.
 * @param {THREE.PointsMaterialParameters} [options]
 */
export function mmPointsMaterial(options = {}) {
  const material = new THREE.PointsMaterial({ size: 1, sizeAttenuation: true, alphaTest: 0.5, ...options });
  material.userData.diameter = 0;
  return material;
}

/**
 * Set a material's point size so that a point covers its diameter in mm on screen
 * (three.js scales a perspective point by half the viewport height over its depth; an
 * orthographic one not at all). Never below MIN_POINT_PX.
 * @param {THREE.PointsMaterial} material
 * @param {ViewCamera} camera
 * @param {number} viewportHeight
 */
export function sizePoints(material, camera, viewportHeight, scale = 1) {
  const d = material.userData.diameter * scale;
  if (camera instanceof THREE.PerspectiveCamera) {
    const perDepth = 1 / Math.tan(THREE.MathUtils.degToRad(camera.fov / 2));
    const distance = camera.position.distanceTo(camera.userData.target ?? new THREE.Vector3());
    // the floor, as a size at the target's depth
    const floor = (MIN_POINT_PX * distance * 2) / Math.max(viewportHeight, 1);
    material.size = Math.max(d * perDepth, floor);
  } else {
    const pxPerMm = (camera.zoom * viewportHeight) / (camera.top - camera.bottom);
    material.size = Math.max(d * pxPerMm, MIN_POINT_PX);
  }
}

/** Contact points: one per contact, midway between its two nodes; settled and live parts. */
export class ContactPoints {
  /** @type {THREE.BufferAttribute} the points' positions (set by `makeGeometries`) */
  attribute;

  /** @param {THREE.PointsMaterial} material */
  constructor(material) {
    this.settledPoints = new THREE.Points(undefined, material);
    this.livePoints = new THREE.Points(undefined, material);
    this.settledPoints.frustumCulled = this.livePoints.frustumCulled = false;
    this.array = new Float32Array(3 * 1024);
    this.makeGeometries();
    this.shown = 0; // contacts in the buffer
    this.settled = 0; // contacts in the settled layer
  }

  makeGeometries() {
    this.attribute = new THREE.BufferAttribute(this.array, 3).setUsage(THREE.DynamicDrawUsage);
    for (const points of [this.settledPoints, this.livePoints]) {
      points.geometry.dispose();
      points.geometry = new THREE.BufferGeometry();
      points.geometry.setAttribute('position', this.attribute); // one buffer, two ranges
    }
  }

  /**
   * Append contacts [shown, count) of `nodes` (pairs of node ids) at `table` positions.
   * @param {Int32Array} nodes
   * @param {number} count
   * @param {NodeTable} table
   */
  extend(nodes, count, table) {
    if (count === this.shown) return;
    const from = this.shown;
    if (3 * count > this.array.length) {
      const bigger = new Float32Array(capacityFor(count) * 3);
      bigger.set(this.array.subarray(0, 3 * from));
      this.array = bigger;
      this.makeGeometries();
    } else {
      this.attribute.addUpdateRange(3 * from, 3 * (count - from));
      this.attribute.needsUpdate = true;
    }
    const xyz = table.xyz;
    for (let c = from; c < count; c += 1) {
      const [a, b] = [3 * nodes[2 * c], 3 * nodes[2 * c + 1]];
      for (let k = 0; k < 3; k += 1) this.array[3 * c + k] = (xyz[a + k] + xyz[b + k]) / 2;
    }
    this.shown = count;
    this.setRanges();
  }

  setRanges(from = 0) {
    this.settledPoints.geometry.setDrawRange(from, this.settled - from);
    this.livePoints.geometry.setDrawRange(this.settled, this.shown - this.settled);
  }

  /** Every contact shown goes into the settled layer (or back to live: `settled` false). */
  settle(settled = true) {
    this.settled = settled ? this.shown : 0;
    this.setRanges();
  }

  dispose() {
    this.settledPoints.geometry.dispose();
    this.livePoints.geometry.dispose();
  }
}
