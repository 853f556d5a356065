// @ts-check
// The cross-section at a height z of the preform frame, by the rules of `bwsd slice`
// (pure: numbers in, numbers out; the drawing is view-section.js).
//
// Crossings follow bwsd/export/crossings.py operation for operation, so that the page and
// the Python export agree bit for bit on the same skeleton: a node on the plane counts once
// unless its yarn lies in the plane on both sides of it; a segment whose ends lie strictly
// on opposite sides crosses at a + (z - a.z) / (b.z - a.z) * (b - a). Bands follow
// bwsd/export/slice.py: a horizontal segment within half a diameter of the plane cuts it in
// a strip.

/** @import { Machine } from '../types/daemon' */

/**
 * A yarn as the view holds it: x y z per node in `xyz`, `count` nodes.
 * @typedef {{id: number, kind: string, family: string, xyz: Float64Array, count: number}} SectionYarn
 */
/**
 * Where a yarn crosses the plane: `segment` is the index i of the segment (node i to i + 1)
 * the point lies on, for a node the segment ending there (0 for the first); `free` marks a
 * warp's free segment (last fixed node to guide).
 * @typedef {{yarn: number, family: string, segment: number, x: number, y: number, free: boolean}} Crossing
 */
/**
 * A horizontal segment cut by the plane: a strip of `halfWidth` along start-end ([x, y]).
 * @typedef {{yarn: number, family: string, start: number[], end: number[], halfWidth: number}} Band
 */

/**
 * Where one yarn's centreline meets the plane z = `z`, in order along the yarn.
 *
 * @param {SectionYarn} yarn
 * @param {number} z
 * @returns {Crossing[]}
 */
export function yarnCrossings(yarn, z) {
  const { xyz, count } = yarn;
  const freeFrom = yarn.kind === 'warp' ? count - 2 : count;
  /** @param {number} i */
  const dz = (i) => xyz[3 * i + 2] - z;
  const out = [];
  for (let i = 0; i < count; i += 1) {
    const here = dz(i);
    if (here === 0 && ((i > 0 && dz(i - 1) !== 0) || (i + 1 < count && dz(i + 1) !== 0))) {
      out.push(crossing(yarn, Math.max(i - 1, 0), xyz[3 * i], xyz[3 * i + 1], i > freeFrom));
    }
    if (i + 1 < count && Math.sign(here) * Math.sign(dz(i + 1)) < 0) {
      const [ax, ay, az] = [xyz[3 * i], xyz[3 * i + 1], xyz[3 * i + 2]];
      const [bx, by, bz] = [xyz[3 * i + 3], xyz[3 * i + 4], xyz[3 * i + 5]];
      const t = (z - az) / (bz - az); // numpy: a[:2] + (z - a[2]) / (b[2] - a[2]) * (b[:2] - a[:2])
      out.push(crossing(yarn, i, ax + t * (bx - ax), ay + t * (by - ay), i >= freeFrom));
    }
  }
  return out;
}

/**
 * @param {SectionYarn} yarn
 * @param {number} segment
 * @param {number} x
 * @param {number} y
 * @param {boolean} free
 * @returns {Crossing}
 */
function crossing(yarn, segment, x, y, free) {
  return { yarn: yarn.id, family: yarn.family, segment, x, y, free };
}

/**
 * Every crossing of the plane z = `z`: yarns in id order, then along each yarn.
 * @param {Iterable<SectionYarn>} yarns
 * @param {number} z
 */
export function crossings(yarns, z) {
  const out = [];
  for (const yarn of yarns) {
    for (const c of yarnCrossings(yarn, z)) out.push(c);
  }
  return out;
}

/**
 * Horizontal segments (wefts) whose round section of `diameter` reaches the plane z = `z`:
 * [{yarn, family, start: [x, y], end: [x, y], halfWidth}] (a strip of that half-width
 * along the segment; never a crossing).
 * @param {Iterable<SectionYarn>} yarns
 * @param {number} z
 * @param {number} diameter
 */
export function bands(yarns, z, diameter) {
  const radius = diameter / 2;
  /** @type {Band[]} */
  const out = [];
  for (const yarn of yarns) {
    const { xyz, count } = yarn;
    for (let i = 0; i + 1 < count; i += 1) {
      const az = xyz[3 * i + 2];
      const dz = Math.abs(az - z);
      if (az !== xyz[3 * i + 5] || !(dz < radius)) continue;
      out.push({
        yarn: yarn.id,
        family: yarn.family,
        start: [xyz[3 * i], xyz[3 * i + 1]],
        end: [xyz[3 * i + 3], xyz[3 * i + 4]],
        halfWidth: Math.sqrt(radius * radius - dz * dz),
      });
    }
  }
  return out;
}

/**
 * The four corners of a band's strip, as `bwsd slice` draws it.
 * @param {Band} band
 */
export function bandCorners(band) {
  const [x0, y0] = band.start;
  const [x1, y1] = band.end;
  const length = Math.hypot(x1 - x0, y1 - y0) || 1;
  const nx = (-(y1 - y0) / length) * band.halfWidth;
  const ny = ((x1 - x0) / length) * band.halfWidth;
  return [[x0 + nx, y0 + ny], [x1 + nx, y1 + ny], [x1 - nx, y1 - ny], [x0 - nx, y0 - ny]];
}

/**
 * The square region `bwsd slice` shows: everything cut (crossings, strips' ends) or, when
 * nothing is, the matrix's footprint at the fell; padded by max(d, 1 mm). [cx, cy, half].
 * @param {Crossing[]} found
 * @param {Band[]} strips
 * @param {Machine | null} machine
 * @param {number} diameter
 */
export function sliceLimits(found, strips, machine, diameter) {
  const pad = Math.max(diameter, 1);
  let xs = found.map((c) => c.x).concat(strips.flatMap((b) => [b.start[0], b.end[0]]));
  let ys = found.map((c) => c.y).concat(strips.flatMap((b) => [b.start[1], b.end[1]]));
  if (xs.length === 0 && machine) {
    const [x0, y0] = fellXY(machine, 0, 0);
    const [x1, y1] = fellXY(machine, machine.rows - 1, machine.cols - 1);
    xs = [x0, x1];
    ys = [y0, y1];
  }
  if (xs.length === 0) return [0, 0, 10];
  const [xMin, xMax, yMin, yMax] = [Math.min(...xs), Math.max(...xs), Math.min(...ys), Math.max(...ys)];
  const half = Math.max(xMax - xMin, yMax - yMin) / 2 + pad;
  return [(xMax + xMin) / 2, (yMax + yMin) / 2, half];
}

/**
 * Where the twin maps guide (row, col) at the fell: O + c_mat (guide - O).
 * @param {Machine} machine
 * @param {number} row
 * @param {number} col
 */
export function fellXY(machine, row, col) {
  const ox = ((machine.cols - 1) / 2) * machine.pitch_x;
  const oy = ((machine.rows - 1) / 2) * machine.pitch_y;
  return [ox + machine.c_mat * (col * machine.pitch_x - ox), oy + machine.c_mat * (row * machine.pitch_y - oy)];
}
