// @ts-check
// Picking a yarn in the 3D view: the yarn whose drawn polyline passes nearest a clicked
// pixel, within a few pixels. Every segment is projected with the camera (a few ms for a
// hundred thousand nodes, and only on a click); a segment above the section cut, when the
// cut is on, is not drawn and cannot be picked.

import * as THREE from 'three';

/** @import { ViewCamera } from './view-camera.js' */

export const PICK_PX = 6; // how near a click must fall to a yarn
const CLICK_PX = 4; // a pointer that moved further was a drag (orbit), not a click

/**
 * Screen position in CSS pixels of node `i` of `xyz` and its depth (NDC z), in `out`; false
 * when it lies behind the camera.
 * @param {THREE.Matrix4} matrix
 * @param {Float64Array} xyz
 * @param {number} i
 * @param {number} width
 * @param {number} height
 * @param {number[]} out
 */
function project(matrix, xyz, i, width, height, out) {
  const [x, y, z] = [xyz[3 * i], xyz[3 * i + 1], xyz[3 * i + 2]];
  const e = matrix.elements;
  const w = e[3] * x + e[7] * y + e[11] * z + e[15];
  if (w <= 0) return false;
  out[0] = (((e[0] * x + e[4] * y + e[8] * z + e[12]) / w + 1) / 2) * width;
  out[1] = ((1 - (e[1] * x + e[5] * y + e[9] * z + e[13]) / w) / 2) * height;
  out[2] = (e[2] * x + e[6] * y + e[10] * z + e[14]) / w;
  return true;
}

/**
 * Distance from (px, py) to segment a-b (2D), and where along it (0..1).
 * @param {number} px
 * @param {number} py
 * @param {number[]} a
 * @param {number[]} b
 */
function toSegment(px, py, a, b) {
  const [dx, dy] = [b[0] - a[0], b[1] - a[1]];
  const length2 = dx * dx + dy * dy;
  const t = length2 > 0 ? Math.min(Math.max(((px - a[0]) * dx + (py - a[1]) * dy) / length2, 0), 1) : 0;
  return [Math.hypot(a[0] + t * dx - px, a[1] + t * dy - py), t];
}

/**
 * The id of the yarn drawn nearest (px, py) within PICK_PX, or null.
 * @param {Iterable<{id: number, xyz: Float64Array, count: number}>} yarns
 * @param {ViewCamera} camera
 * @param {number} width
 * @param {number} height
 * @param {number} px
 * @param {number} py
 * @param {number} [cutZ] nothing above this height is drawn (Infinity: no cut)
 * @returns {number | null}
 */
export function pickYarn(yarns, camera, width, height, px, py, cutZ = Infinity) {
  camera.updateMatrixWorld();
  const matrix = new THREE.Matrix4().multiplyMatrices(camera.projectionMatrix, camera.matrixWorldInverse);
  /** @type {number | null} */
  let best = null;
  let bestDistance = PICK_PX;
  let bestDepth = Infinity;
  const a = [0, 0, 0];
  const b = [0, 0, 0];
  for (const yarn of yarns) {
    const { xyz, count } = yarn;
    let previous = project(matrix, xyz, 0, width, height, a);
    for (let i = 1; i < count; i += 1) {
      const current = project(matrix, xyz, i, width, height, b);
      const cut = xyz[3 * i - 1] > cutZ && xyz[3 * i + 2] > cutZ;
      if (previous && current && !cut) {
        const [distance, t] = toSegment(px, py, a, b);
        const depth = a[2] + t * (b[2] - a[2]);
        if (distance < bestDistance - 0.5 || (distance <= bestDistance + 0.5 && depth < bestDepth)) {
          [best, bestDistance, bestDepth] = [yarn.id, Math.min(distance, bestDistance), depth];
        }
      }
      a[0] = b[0];
      a[1] = b[1];
      a[2] = b[2];
      previous = current;
    }
  }
  return best;
}

/**
 * Calls `onClick(x, y)` (CSS pixels in `element`) for a press and release that did not
 * move (an orbit drag is no click).
 * @param {HTMLElement} element
 * @param {(x: number, y: number) => void} onClick
 */
export function listenForClicks(element, onClick) {
  /** @type {number[] | null} */
  let down = null;
  element.addEventListener('pointerdown', (event) => {
    down = event.button === 0 ? [event.clientX, event.clientY] : null;
  });
  element.addEventListener('pointerup', (event) => {
    if (!down || Math.hypot(event.clientX - down[0], event.clientY - down[1]) > CLICK_PX) return;
    down = null;
    const box = element.getBoundingClientRect();
    onClick(event.clientX - box.left, event.clientY - box.top);
  });
}
