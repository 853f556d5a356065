// @ts-check
// The machine in the 3D view: the converged matrix at the fell (outlined and lightly
// filled), the outline of the guide matrix and its guides, occupied ones in their yarn's
// colour. Drawn on top of the yarns, the same whether those are settled or live.

import * as THREE from 'three';

/** @import { Machine } from '../types/daemon' */

const FELL_COLOUR = 0xb7791f; // amber: the fell plane
const MATRIX_COLOUR = 0xa0aec0;
const EMPTY_GUIDE_COLOUR = 0xb8bec8;

/**
 * A closed rectangle centred on (ox, oy) at height z, half sizes hx × hy.
 * @param {number} ox
 * @param {number} oy
 * @param {number} hx
 * @param {number} hy
 * @param {number} z
 */
export function rectangle(ox, oy, hx, hy, z) {
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

export class MachineMarks {
  constructor() {
    this.fell = new THREE.LineLoop(new THREE.BufferGeometry(), new THREE.LineBasicMaterial({ color: FELL_COLOUR }));
    this.fellPlane = new THREE.Mesh(new THREE.BufferGeometry(), new THREE.MeshBasicMaterial({
      color: FELL_COLOUR, transparent: true, opacity: 0.18, depthWrite: false, side: THREE.DoubleSide,
    }));
    this.matrixOutline = new THREE.LineLoop(new THREE.BufferGeometry(), new THREE.LineBasicMaterial({ color: MATRIX_COLOUR }));
    this.guides = new THREE.Points(new THREE.BufferGeometry(), new THREE.PointsMaterial({ vertexColors: true }));
    this.objects = [this.fellPlane, this.fell, this.matrixOutline, this.guides];
    this.fillFell = true; // off while the section is shown: its plane takes the place
    for (const object of this.objects) {
      object.frustumCulled = false;
      object.visible = false;
      object.material.depthTest = false;
      object.renderOrder = 1;
    }
  }

  /** The materials a section cut clips (what lies above the fell). */
  get clipped() {
    return [this.matrixOutline.material, this.guides.material];
  }

  /**
   * Redraw for `machine` (or hide: null), the take-up and the occupancy; cheap (rows × cols points).
   * @param {Machine | null} machine
   * @param {number} takeup
   * @param {number[][] | null} occupancy
   * @param {(yarnId: number) => number} colourOf
   */
  draw(machine, takeup, occupancy, colourOf) {
    const shown = Boolean(machine);
    for (const object of this.objects) object.visible = shown;
    this.fellPlane.visible = shown && this.fillFell;
    if (!machine) return;
    const { rows, cols, c_mat: cMat, d_mat: dMat, pitch_x: px, pitch_y: py } = machine;
    const [xMax, yMax] = [(cols - 1) * px, (rows - 1) * py];
    const [ox, oy] = [xMax / 2, yMax / 2]; // O, the centre of the matrix
    const guideZ = dMat + takeup;
    this.fell.geometry.dispose();
    this.fell.geometry = rectangle(ox, oy, cMat * (xMax / 2), cMat * (yMax / 2), takeup);
    this.fellPlane.geometry.dispose();
    this.fellPlane.geometry = this.fell.geometry.clone().setIndex([0, 1, 2, 0, 2, 3]);
    this.matrixOutline.geometry.dispose();
    this.matrixOutline.geometry = rectangle(ox, oy, xMax / 2, yMax / 2, guideZ);

    const positions = new Float32Array(rows * cols * 3);
    const colours = new Float32Array(rows * cols * 3);
    const colour = new THREE.Color();
    for (let r = 0; r < rows; r += 1) {
      for (let c = 0; c < cols; c += 1) {
        const i = r * cols + c;
        positions.set([c * px, r * py, guideZ], 3 * i);
        const yarn = occupancy?.[r]?.[c] ?? -1;
        colour.setHex(yarn >= 0 ? colourOf(yarn) : EMPTY_GUIDE_COLOUR);
        colours.set([colour.r, colour.g, colour.b], 3 * i);
      }
    }
    const geometry = new THREE.BufferGeometry();
    geometry.setAttribute('position', new THREE.BufferAttribute(positions, 3));
    geometry.setAttribute('color', new THREE.BufferAttribute(colours, 3));
    this.guides.material.size = 0.35 * Math.min(px, py); // mm: a case, roughly
    this.guides.geometry.dispose();
    this.guides.geometry = geometry;
  }
}
