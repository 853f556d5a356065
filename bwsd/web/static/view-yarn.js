// @ts-check
// One yarn of the 3D view: its node ids and exact coordinates, in a buffer grown by doubling.

/** @import { XYZ, YarnData } from '../types/daemon' */

/** One yarn: its node ids and coordinates (exactly as the daemon sent them). */
export class Yarn {
  /**
   * @param {YarnData} data
   * @param {string} family
   */
  constructor(data, family) {
    this.id = data.id;
    this.kind = data.kind;
    this.family = family;
    this.nodeIds = Array.from(data.node_ids); // in order along the yarn
    this.count = this.nodeIds.length;
    // A warp keeps growing (every contact adds a node); a weft starts as two fixed nodes.
    let capacity = 8;
    while (capacity < (this.kind === 'warp' ? this.count * 2 : this.count)) capacity *= 2;
    this.xyz = new Float64Array(capacity * 3);
    data.nodes.forEach((p, i) => this.xyz.set(p, 3 * i));
    this.settled = 1; // nodes [0, settled) are in the settled layer, [settled - 1, count) live
  }

  /**
   * Where node `nodeId` is along the yarn (searched from the free end, where changes are).
   * @param {number} nodeId
   */
  indexOf(nodeId) {
    return this.nodeIds.lastIndexOf(nodeId);
  }

  /**
   * Insert node `nodeId` at `xyz` after node `after` (-1: at the start); its index, -1 if unknown.
   * @param {number} after
   * @param {number} nodeId
   * @param {XYZ} xyz
   */
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

  /**
   * Node `nodeId` moved to `xyz`; its index, -1 if the yarn has no such node.
   * @param {number} nodeId
   * @param {XYZ} xyz
   */
  move(nodeId, xyz) {
    const i = this.indexOf(nodeId);
    if (i >= 0) this.xyz.set(xyz, 3 * i);
    return i;
  }

  /** Length in mm along the polyline, free segment included. */
  length() {
    let total = 0;
    for (let i = 1; i < this.count; i += 1) {
      const [dx, dy, dz] = [0, 1, 2].map((k) => this.xyz[3 * i + k] - this.xyz[3 * i - 3 + k]);
      total += Math.sqrt(dx * dx + dy * dy + dz * dz);
    }
    return total;
  }

  /** The yarn as the skeleton JSON has it: {id, node_ids, nodes: [[x, y, z], ...]}. */
  dump() {
    const nodes = [];
    for (let i = 0; i < this.count; i += 1) nodes.push(Array.from(this.xyz.subarray(3 * i, 3 * i + 3)));
    return { id: this.id, node_ids: this.nodeIds.slice(), nodes };
  }
}
