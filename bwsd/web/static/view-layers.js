// @ts-check
// The two layers that keep a big preform smooth while it grows (see skeleton.js): the
// settled part of every yarn, drawn into an off-screen image, and the live tails, drawn
// every frame over it. The split advances by drawing only what newly settled into the
// image; it is made again from scratch only when a change reaches into a settled part or
// the colours change, and the image is drawn whole only then or when the camera moves.

import * as THREE from 'three';

import { StripBatch } from './view-batches.js';

/** @import { PreformView } from './skeleton.js' */
/** @import { ViewCamera } from './view-camera.js' */
/** @import { Yarn } from './view-yarn.js' */

const TAIL = 8; // nodes at a yarn's free end kept live
const LAYERS_FROM = 10000; // nodes and contacts: a smaller preform is drawn whole every frame

export class Layers {
  /** @param {PreformView} view the PreformView: its yarns, colours, contacts, camera rig and renderer */
  constructor(view) {
    this.view = view;
    this.settledScene = new THREE.Scene();
    this.liveScene = new THREE.Scene();
    this.yarnMaterial = new THREE.LineBasicMaterial({ vertexColors: true });
    this.settledYarns = new StripBatch(this.yarnMaterial);
    this.liveYarns = new StripBatch(this.yarnMaterial);
    this.settledScene.add(this.settledYarns.line);
    this.liveScene.add(this.liveYarns.line);
    // Highlight: one yarn drawn whole on top in its colour (the others are dimmed).
    this.highlightYarn = new StripBatch(new THREE.LineBasicMaterial({ vertexColors: true, depthTest: false }));
    this.highlightYarn.line.renderOrder = 3;
    this.liveScene.add(this.highlightYarn.line);
    // 4x MSAA as the canvas (none on software WebGL, as the canvas); its colour and depth are
    // kept between draws, so new segments go on top.
    this.settledImage = new THREE.WebGLRenderTarget(1, 1, {
      samples: view.software ? 0 : 4,
      storeMultisampledDepthBuffer: true,
    });
    // Linear: shown 1:1 it samples texel centres (exact); scaled while following, it smooths.
    this.settledImage.texture.minFilter = this.settledImage.texture.magFilter = THREE.LinearFilter;
    this.layered = false; // whether the settled image is in use
    this.imageDirty = true; // the image must be drawn whole again (camera, size, new split)
    this.splitDirty = true; // the split between settled and live must be made from scratch
    this.advanceDirty = false; // the split should advance (long tails, a pause)
    /** @type {{yarns: number, contacts: number} | null} what the last advance added, to draw into the image */
    this.increment = null;
    this.liveDirty = true; // the live batch must be rebuilt
    this.liveNodes = 0; // nodes drawn live, all yarns together
    // For diagnostics (bench/page.py): how often the costly steps ran, and when (ms).
    /** @type {{splits: number, images: number[], increments: number}} */
    this.stats = { splits: 0, images: [], increments: 0 };
    // The settled image is shown by one screen-filling quad, scaled and shifted with the
    // picture while the view follows the preform without moving the camera.
    this.imageCamera = new THREE.OrthographicCamera(-1, 1, 1, -1, 0, 1);
    this.imageScene = new THREE.Scene();
    this.imageQuad = new THREE.Mesh(
      new THREE.PlaneGeometry(2, 2),
      new THREE.MeshBasicMaterial({ map: this.settledImage.texture, depthTest: false, depthWrite: false }),
    );
    this.imageScene.add(this.imageQuad);
    this.imageSoft = view.rig.soft; // the picture's scale and shift when the image was drawn
  }

  /**
   * The drawing buffer's size in pixels.
   * @param {number} width
   * @param {number} height
   */
  setSize(width, height) {
    this.settledImage.setSize(width, height);
  }

  /** Whether long tails are worth settling now (the updates paused). */
  get tailsLong() {
    return this.layered && this.liveNodes > 2 * TAIL * Math.max(1, this.view.yarns.size);
  }

  /**
   * A yarn's node went in at index `at`, or moved there (`moved`): does it reach the settled part?
   * @param {Yarn} yarn
   * @param {number} at
   */
  touched(yarn, at, moved = false) {
    if (at < yarn.settled - (moved ? 0 : 1)) this.splitDirty = true;
  }

  /** Before drawing: the split made, advanced or undone, the live batch built. */
  prepare() {
    const view = this.view;
    const layered = view.nodeCount + view.contactCount >= LAYERS_FROM;
    if (layered !== this.layered) {
      this.layered = layered;
      this.splitDirty = true;
    }
    if (layered && this.splitDirty) this.split();
    else if (layered && this.advanceDirty) this.advance();
    if (!layered && this.splitDirty) this.unsplit();
    if (this.liveDirty) this.buildLive();
  }

  /**
   * Draw the frame: the settled image (drawn again or added to first), then the live scene.
   * @param {THREE.WebGLRenderer} renderer
   * @param {ViewCamera} camera
   */
  draw(renderer, camera) {
    renderer.setRenderTarget(null);
    renderer.clear();
    if (this.layered) {
      if (this.imageDirty) this.drawImage(renderer, camera);
      else if (this.increment) this.drawIncrement(renderer, camera, this.increment);
      this.placeImage();
      renderer.render(this.imageScene, this.imageCamera);
    }
    this.increment = null;
    renderer.render(this.liveScene, camera);
  }

  /** Settle every yarn but its last TAIL nodes, and rebuild the settled batch. */
  split() {
    const view = this.view;
    this.stats.splits += 1;
    const batch = this.settledYarns;
    batch.begin();
    this.liveNodes = 0;
    for (const yarn of view.yarns.values()) {
      yarn.settled = Math.max(1, yarn.count - TAIL);
      this.liveNodes += yarn.count - yarn.settled + 1;
      batch.add(yarn.xyz, 0, yarn.settled, view.shownColour(yarn.id));
    }
    batch.end();
    view.contactPoints?.settle();
    this.splitDirty = false;
    this.advanceDirty = false;
    this.imageDirty = true;
    this.liveDirty = true;
  }

  /** Move every yarn's split up to its last TAIL nodes: the new settled parts are appended. */
  advance() {
    const view = this.view;
    const batch = this.settledYarns;
    const increment = { yarns: batch.mark(), contacts: view.contactPoints?.settled ?? 0 };
    this.liveNodes = 0;
    for (const yarn of view.yarns.values()) {
      const settled = Math.max(yarn.settled, yarn.count - TAIL);
      if (settled > yarn.settled) batch.add(yarn.xyz, yarn.settled - 1, settled, view.shownColour(yarn.id));
      yarn.settled = settled;
      this.liveNodes += yarn.count - yarn.settled + 1;
    }
    batch.end();
    view.contactPoints?.settle();
    this.increment = increment;
    this.advanceDirty = false;
    this.liveDirty = true;
  }

  /** A small preform: nothing settled, all live. */
  unsplit() {
    const view = this.view;
    this.settledYarns.begin();
    this.settledYarns.end();
    for (const yarn of view.yarns.values()) yarn.settled = 1;
    this.liveNodes = view.nodeCount;
    view.contactPoints?.settle(false);
    this.splitDirty = false;
    this.advanceDirty = false;
    this.liveDirty = true;
  }

  /** The live tails of every yarn, in one batch; and the highlighted yarn, whole, on top. */
  buildLive() {
    const view = this.view;
    const batch = this.liveYarns;
    batch.begin();
    for (const yarn of view.yarns.values()) {
      batch.add(yarn.xyz, yarn.settled - 1, yarn.count, view.shownColour(yarn.id));
    }
    batch.end();
    const picked = view.highlighted === null ? undefined : view.yarns.get(view.highlighted);
    this.highlightYarn.begin();
    if (picked) this.highlightYarn.add(picked.xyz, 0, picked.count, view.palette.colour(picked.id));
    this.highlightYarn.end();
    this.liveDirty = false;
  }

  /**
   * Draw the settled layer into its image (the costly part of a big preform).
   * @param {THREE.WebGLRenderer} renderer
   * @param {ViewCamera} camera
   */
  drawImage(renderer, camera) {
    this.stats.images.push(Math.round(performance.now()));
    this.imageSoft = this.view.rig.soft;
    renderer.setRenderTarget(this.settledImage);
    renderer.clear();
    renderer.render(this.settledScene, camera);
    renderer.setRenderTarget(null);
    this.imageDirty = false;
  }

  /** Show the image where the picture is now: scaled and shifted as it was since it was drawn. */
  placeImage() {
    const [now, then] = [this.view.rig.soft, this.imageSoft];
    const r = now.s / then.s;
    this.imageQuad.scale.set(r, r, 1);
    this.imageQuad.position.set(now.tx - r * then.tx, now.ty - r * then.ty, 0);
  }

  /**
   * Draw what the last advance settled into the image (`increment`), over what it holds.
   * @param {THREE.WebGLRenderer} renderer
   * @param {ViewCamera} camera
   * @param {{yarns: number, contacts: number}} increment
   */
  drawIncrement(renderer, camera, increment) {
    const { rig, contactPoints } = this.view;
    this.stats.increments += 1;
    const { yarns, contacts } = increment;
    this.settledYarns.drawFrom(yarns);
    contactPoints?.setRanges(contacts);
    rig.applySoft(this.imageSoft); // drawn as the image was
    renderer.setRenderTarget(this.settledImage);
    renderer.render(this.settledScene, camera);
    renderer.setRenderTarget(null);
    rig.applySoft();
    this.settledYarns.drawAll();
    contactPoints?.setRanges();
  }
}
