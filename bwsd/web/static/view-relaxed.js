// @ts-check
// The relaxed preform over the predicted one: the daemon's `GET /api/v1/skeleton?relaxed=true`
// (docs/relax.md: the tight preform the loom makes, relaxed from the twin's skeleton), every
// yarn a polyline in one colour, drawn with the live tails. Read when shown and at every new
// skeleton while shown; removed whole when hidden.

import * as THREE from 'three';

import { request } from './api.js';

export const RELAXED_COLOUR = 0xd53f8c; // magenta: no palette colour is this one
const RELAX_MS = 120000; // the first relaxation of a skeleton takes seconds

export class RelaxedLayer {
  /**
   * @param {THREE.Scene} scene where to draw it
   * @param {() => void} redraw ask for a frame
   */
  constructor(scene, redraw) {
    this.scene = scene;
    this.redraw = redraw;
    this.shown = false;
    /** @type {THREE.LineSegments<THREE.BufferGeometry, THREE.LineBasicMaterial> | null} */
    this.lines = null;
    /** @type {number | null} the instructions done in the relaxed skeleton shown */
    this.instructions = null;
    this.nodes = 0;
    /** @type {string | null} why nothing is shown (a refusal) */
    this.error = null;
    this.asks = 0;
  }

  /**
   * Show the relaxed preform (read it from the daemon) or remove it.
   * @param {boolean} shown
   */
  async setShown(shown) {
    this.shown = shown;
    this.asks += 1;
    const ask = this.asks;
    if (!shown) {
      this.clear();
      this.redraw();
      return;
    }
    try {
      const answer = await request('api/v1/skeleton?relaxed=true', { timeoutMs: RELAX_MS });
      if (ask !== this.asks) return; // hidden or asked again meanwhile
      if (!answer.ok || !Array.isArray(answer.body?.yarns)) {
        this.error = String(answer.body?.error ?? `HTTP ${answer.status}`);
        return;
      }
      this.draw(answer.body.yarns, answer.body.instructions ?? null);
    } catch (error) {
      if (ask === this.asks) this.error = String(error);
    }
  }

  /**
   * @param {{nodes: number[][]}[]} yarns
   * @param {number | null} instructions
   */
  draw(yarns, instructions) {
    this.clear();
    const positions = [];
    let nodes = 0;
    for (const yarn of yarns) {
      nodes += yarn.nodes.length;
      for (let i = 0; i + 1 < yarn.nodes.length; i += 1) positions.push(...yarn.nodes[i], ...yarn.nodes[i + 1]);
    }
    const geometry = new THREE.BufferGeometry();
    geometry.setAttribute('position', new THREE.Float32BufferAttribute(positions, 3));
    this.lines = new THREE.LineSegments(geometry, new THREE.LineBasicMaterial({ color: RELAXED_COLOUR }));
    this.lines.frustumCulled = false;
    this.lines.renderOrder = 1;
    this.scene.add(this.lines);
    this.instructions = instructions;
    this.nodes = nodes;
    this.error = null;
    this.redraw();
  }

  clear() {
    if (this.lines) {
      this.scene.remove(this.lines);
      this.lines.geometry.dispose();
      this.lines.material.dispose();
      this.lines = null;
    }
    this.instructions = null;
    this.nodes = 0;
  }
}
