// @ts-check
// The 3D view's camera: a perspective and an orthographic one sharing one orbit control,
// and the preset views of a textile drawing.
//
// Presets look along an axis of the preform frame: "top" along +z, up the preform from
// its start (x to the right, y down: the matrix as the FILL block writes it, row 0 at the
// top, as the Matrix panel, the section and `bwsd slice` draw it), "front" along +y (x to
// the right, z up), "side" along -x (y to the right, z up); "3d" from the front right, a
// little above. Top, front and
// side are orthographic by default (a drawing's views: lengths read true on screen), the
// 3D view in perspective; the orthographic toggle overrides either.

import * as THREE from 'three';
import { OrbitControls } from 'three/addons/controls/OrbitControls.js';

/** @typedef {THREE.PerspectiveCamera | THREE.OrthographicCamera} ViewCamera */
/** @typedef {{s: number, tx: number, ty: number}} Soft a scale and shift of the picture (NDC) */

const FOV = 35; // degrees, vertical, of the perspective camera
const TILT = 1e-4; // the top view's tilt off the vertical, for a defined "up" (-y) on screen
/** @type {Record<string, {direction: THREE.Vector3, orthographic: boolean}>} */
export const PRESETS = {
  '3d': { direction: new THREE.Vector3(1.0, -1.5, 0.8).normalize(), orthographic: false },
  top: { direction: new THREE.Vector3(0, -TILT, -1).normalize(), orthographic: true },
  front: { direction: new THREE.Vector3(0, -1, 0), orthographic: true },
  side: { direction: new THREE.Vector3(1, 0, 0), orthographic: true },
};

export class CameraRig {
  /**
   * @param {HTMLCanvasElement} canvas
   * @param {() => void} onChange called when the camera moved (by the operator or by a call here)
   */
  constructor(canvas, onChange) {
    this.perspective = new THREE.PerspectiveCamera(FOV, 1, 0.1, 10000);
    this.orthographic = new THREE.OrthographicCamera(-1, 1, 1, -1, 0.1, 10000);
    for (const camera of [this.perspective, this.orthographic]) {
      camera.up.set(0, 0, 1); // z up: the preform grows along +z
      camera.userData.target = new THREE.Vector3();
    }
    this.perspective.position.set(100, -150, 80);
    /** @type {ViewCamera} */
    this.camera = this.perspective;
    // A scale s and shift (tx, ty) of the picture, after the camera's own projection (NDC):
    // how the view follows a growing preform while updates flow without moving the camera,
    // so that the settled image stays valid, moved and scaled like the picture.
    /** @type {Soft} */
    this.soft = { s: 1, tx: 0, ty: 0 };
    this.aspect = 1;
    this.preset = '3d';
    /** @type {OrbitControls<ViewCamera>} */
    this.controls = new OrbitControls(this.camera, canvas);
    this.controls.addEventListener('change', () => {
      this.camera.userData.target.copy(this.controls.target);
      onChange();
    });
    this.onChange = onChange;
  }

  get isOrthographic() {
    return this.camera === this.orthographic;
  }

  /** @param {number} aspect */
  setAspect(aspect) {
    this.aspect = aspect;
    this.perspective.aspect = aspect;
    const o = this.orthographic;
    const half = (o.top - o.bottom) / 2;
    o.left = -half * aspect;
    o.right = half * aspect;
    this.perspective.updateProjectionMatrix();
    o.updateProjectionMatrix();
    this.applySoft();
  }

  get isSoft() {
    return this.soft.s !== 1 || this.soft.tx !== 0 || this.soft.ty !== 0;
  }

  /**
   * The camera's projection followed by `soft` (default: the rig's), on the active camera.
   * @param {Soft} [soft]
   */
  applySoft(soft = this.soft) {
    const camera = this.camera;
    camera.updateProjectionMatrix();
    if (soft.s === 1 && soft.tx === 0 && soft.ty === 0) return;
    const m = new THREE.Matrix4().set(soft.s, 0, 0, soft.tx, 0, soft.s, 0, soft.ty, 0, 0, 1, 0, 0, 0, 0, 1);
    camera.projectionMatrix.premultiply(m);
    camera.projectionMatrixInverse.copy(camera.projectionMatrix).invert();
  }

  /**
   * Frame `box` by scaling and shifting the picture only (the camera stays): false when that
   * cannot show it (a part behind a perspective camera), then the caller fits for real.
   * @param {THREE.Box3} box
   */
  softFit(box) {
    const camera = this.camera;
    camera.updateMatrixWorld();
    camera.updateProjectionMatrix(); // the plain projection, to measure in
    const v = new THREE.Vector3();
    let [x0, x1, y0, y1] = [Infinity, -Infinity, Infinity, -Infinity];
    for (const x of [box.min.x, box.max.x]) {
      for (const y of [box.min.y, box.max.y]) {
        for (const z of [box.min.z, box.max.z]) {
          v.set(x, y, z).applyMatrix4(camera.matrixWorldInverse);
          if (camera instanceof THREE.PerspectiveCamera && v.z > -camera.near) {
            this.applySoft();
            return false;
          }
          v.applyMatrix4(camera.projectionMatrix);
          [x0, x1, y0, y1] = [Math.min(x0, v.x), Math.max(x1, v.x), Math.min(y0, v.y), Math.max(y1, v.y)];
        }
      }
    }
    const s = Math.min(1.9 / (x1 - x0), 1.9 / (y1 - y0), this.soft.s);
    this.soft = { s, tx: (-s * (x0 + x1)) / 2, ty: (-s * (y0 + y1)) / 2 };
    this.applySoft();
    return true;
  }

  clearSoft() {
    this.soft = { s: 1, tx: 0, ty: 0 };
    this.applySoft();
  }

  /**
   * Switch projection, keeping the direction, the target and the scale at the target.
   * @param {boolean} on
   */
  setOrthographic(on) {
    if (on === this.isOrthographic) return;
    const target = this.controls.target.clone();
    const from = this.camera;
    const offset = from.position.clone().sub(target);
    const tan = Math.tan(THREE.MathUtils.degToRad(FOV / 2));
    if (on) {
      const half = offset.length() * tan;
      this.frame(this.orthographic, target, offset, half, offset.length());
    } else {
      const o = this.orthographic;
      const half = (o.top - o.bottom) / 2 / o.zoom;
      const distance = half / tan;
      this.frame(this.perspective, target, offset.normalize().multiplyScalar(distance), half, distance);
    }
    this.use(on ? this.orthographic : this.perspective);
  }

  /** @param {ViewCamera} camera */
  use(camera) {
    this.soft = { s: 1, tx: 0, ty: 0 }; // a real fit or a switch ends any soft framing
    this.camera = camera;
    this.controls.object = camera;
    this.controls.update();
    this.onChange();
  }

  /**
   * Place `camera` at target + offset, showing `half` mm above and below the target.
   * @param {ViewCamera} camera
   * @param {THREE.Vector3} target
   * @param {THREE.Vector3} offset
   * @param {number} half
   * @param {number} depth
   */
  frame(camera, target, offset, half, depth) {
    camera.position.copy(target).add(offset);
    camera.userData.target.copy(target);
    camera.near = depth / 100;
    camera.far = depth * 10;
    if (camera instanceof THREE.OrthographicCamera) {
      camera.zoom = 1;
      camera.top = half;
      camera.bottom = -half;
      camera.left = -half * this.aspect;
      camera.right = half * this.aspect;
      camera.near = 0;
      camera.far = depth * 3;
    }
    camera.lookAt(target);
    camera.updateProjectionMatrix();
  }

  /**
   * Look along a preset (`PRESETS`) in its projection, framing `box`.
   * @param {string} preset
   * @param {THREE.Box3} box
   */
  view(preset, box) {
    this.preset = PRESETS[preset] ? preset : '3d';
    this.fit(box, PRESETS[this.preset].orthographic);
  }

  /**
   * Frame `box` along the current preset's direction (`orthographic`: which camera).
   * @param {THREE.Box3} box
   */
  fit(box, orthographic = this.isOrthographic) {
    const direction = PRESETS[this.preset].direction;
    const centre = box.getCenter(new THREE.Vector3());
    const radius = Math.max(box.getSize(new THREE.Vector3()).length() / 2, 1);
    const camera = orthographic ? this.orthographic : this.perspective;
    if (orthographic) {
      const half = this.halfExtent(box, centre, direction) * 1.05;
      this.frame(camera, centre, direction.clone().multiplyScalar(2 * radius), half, 2 * radius);
    } else {
      const halfFov = THREE.MathUtils.degToRad(FOV / 2);
      const halfAcross = Math.atan(Math.tan(halfFov) * this.aspect);
      const distance = (radius / Math.sin(Math.min(halfFov, halfAcross))) * 1.02;
      this.frame(camera, centre, direction.clone().multiplyScalar(distance), distance * Math.tan(halfFov), distance);
    }
    this.controls.target.copy(centre);
    this.use(camera);
  }

  /**
   * Half the height an orthographic view along `direction` needs to show all of `box`.
   * @param {THREE.Box3} box
   * @param {THREE.Vector3} centre
   * @param {THREE.Vector3} direction
   */
  halfExtent(box, centre, direction) {
    const probe = new THREE.Object3D();
    probe.up.set(0, 0, 1);
    probe.position.copy(centre).add(direction);
    probe.lookAt(centre);
    probe.updateMatrixWorld();
    const right = new THREE.Vector3().setFromMatrixColumn(probe.matrixWorld, 0);
    const up = new THREE.Vector3().setFromMatrixColumn(probe.matrixWorld, 1);
    let [across, along] = [0, 0];
    for (const x of [box.min.x, box.max.x]) {
      for (const y of [box.min.y, box.max.y]) {
        for (const z of [box.min.z, box.max.z]) {
          const v = new THREE.Vector3(x, y, z).sub(centre);
          across = Math.max(across, Math.abs(v.dot(right)));
          along = Math.max(along, Math.abs(v.dot(up)));
        }
      }
    }
    return Math.max(along, across / this.aspect, 1);
  }

  /**
   * Millimetres per CSS pixel at the target (orthographic: everywhere).
   * @param {number} heightPx
   */
  mmPerPixel(heightPx) {
    const camera = this.camera;
    if (camera instanceof THREE.OrthographicCamera) return (camera.top - camera.bottom) / camera.zoom / heightPx / this.soft.s;
    const distance = camera.position.distanceTo(this.controls.target);
    return (2 * distance * Math.tan(THREE.MathUtils.degToRad(FOV / 2))) / heightPx / this.soft.s;
  }

  /** For tests and diagnostics: the preset, the projection and where the camera looks. */
  info() {
    const camera = this.camera;
    const direction = camera.getWorldDirection(new THREE.Vector3());
    const up = new THREE.Vector3().setFromMatrixColumn(camera.matrixWorld, 1);
    return {
      preset: this.preset,
      orthographic: this.isOrthographic,
      type: camera.type,
      direction: direction.toArray(),
      up: up.toArray(),
      target: this.controls.target.toArray(),
    };
  }
}
