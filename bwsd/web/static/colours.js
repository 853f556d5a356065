// @ts-check
// Yarn colours, shared by the 3D view, the section and the machine matrix so a case in the
// grid has the colour of its yarn in the preform.
//
// Four ways to colour (COLOUR_MODES):
// - "yarn": a colour per yarn such that neighbours never share one. Neighbours are yarns
//   that share a contact, and warps whose fill cells touch (side or corner) or that are
//   next to each other in a row or column of the fill with only empty cells between. The
//   graph is coloured greedily in yarn-id order, each yarn taking the colour its coloured
//   neighbours do not use that fewest yarns have so far: first among 12 hues 30 degrees
//   apart, then among the same hues darker and lighter (36 colours).
// - "family": every warp one colour, each weft insertion angle its own.
// - "zone": each warp in the colour of the section zone its carrier was filled into (the
//   program's "# section:" line), edge carriers grey, wefts brown; without a section line
//   every warp slate.
// - "contacts": the number of contacts a yarn is in, on a sequential colour map from the
//   fewest any yarn has to the most.
//
// Contacts made while a program runs do not change colours at once (a yarn keeps its
// colour while it is watched): `refresh()`, called when the updates pause with the machine
// standing, recolours the yarns that came to share a colour with a new neighbour and
// updates the contact counts.

import { zoneOf } from './view-zones.js';

/** @import { Cell, YarnData } from '../types/daemon' */
/** @import { Section } from './view-zones.js' */

/** @type {string[]} */
export const COLOUR_MODES = ['yarn', 'family', 'zone', 'contacts'];
export const WARP_COLOUR = 0x2c5282; // every warp, when colouring by family
const WEFT_COLOURS = [0xc0392b, 0x1e8449, 0xb9770e, 0x7d3c98, 0x117a8b, 0xa04000, 0x5d6d7e, 0x9a1d5a];
// 12 hues 30 degrees apart (0, 30, ..., 330), each dark enough for a thin line on the
// page's light background; listed 150 degrees apart so that the first few are far apart.
const HUES = [
  0xd32f2f, 0x00875a, 0xa21cb8, 0x5f8f00, 0x3949ab, 0xe65100,
  0x00838f, 0xc2185b, 0x2e7d32, 0x7b1fa2, 0xa68b00, 0x1565c0,
];
const YARN_COLOURS = [...HUES, ...HUES.map((c) => mix(c, 0x000000, 0.45)), ...HUES.map((c) => mix(c, 0xffffff, 0.4))];
const ZONE_COLOURS = [0x1565c0, 0x2e7d32, 0xe65100, 0xc2185b, 0x00838f, 0x6d4c41, 0x5f8f00];
const JUNCTION_COLOURS = [0x7b1fa2, 0xa21cb8];
const EDGE_COLOUR = 0x9aa3ad;
const ZONE_WEFT_COLOUR = 0x5d4037;
const NO_SECTION_COLOUR = 0x64748b; // slate: warps of a program without a section line
// Viridis, from none (dark violet) to most (yellow-green), stopped before its light end.
const SEQUENTIAL = [0x440154, 0x3b528b, 0x21918c, 0x5ec962, 0xb5de2b];
const SEQUENTIAL_STEPS = 5; // legend entries of the contacts map

/**
 * The family of a yarn: "warp" or "weft-<angle>" (as the skeleton JSON spells it).
 * @param {Pick<YarnData, 'family' | 'kind' | 'angle'>} yarn
 */
export function familyOf(yarn) {
  if (yarn.family) return yarn.family;
  if (yarn.kind === 'warp') return 'warp';
  return `weft-${formatAngle(yarn.angle ?? 0)}`;
}

/**
 * An angle in degrees as Python's "%g" writes it: 0, 90, 22.5, 33.3333.
 * @param {number} angle
 */
function formatAngle(angle) {
  return String(Number(angle.toPrecision(6)));
}

/**
 * `a` moved towards `b` by `t` (0..1), channel by channel; 0xRRGGBB.
 * @param {number} a
 * @param {number} b
 * @param {number} t
 */
export function mix(a, b, t) {
  let out = 0;
  for (const shift of [16, 8, 0]) {
    const ca = (a >> shift) & 255;
    const cb = (b >> shift) & 255;
    out |= Math.round(ca + (cb - ca) * t) << shift;
  }
  return out;
}

/**
 * 0xRRGGBB as CSS "#rrggbb".
 * @param {number} colour
 */
export function css(colour) {
  return `#${colour.toString(16).padStart(6, '0')}`;
}

/**
 * Dark text on light colours, white on dark ones (for the grid's yarn ids).
 * @param {number} colour
 */
export function textOn(colour) {
  const r = (colour >> 16) & 255;
  const g = (colour >> 8) & 255;
  const b = colour & 255;
  return 0.299 * r + 0.587 * g + 0.114 * b > 150 ? '#111' : '#fff';
}

/**
 * The colour of `value` in [0, top] on the sequential map.
 * @param {number} value
 * @param {number} top
 */
export function sequential(value, top) {
  const t = top > 0 ? Math.min(Math.max(value / top, 0), 1) : 0;
  const at = t * (SEQUENTIAL.length - 1);
  const i = Math.min(Math.floor(at), SEQUENTIAL.length - 2);
  return mix(SEQUENTIAL[i], SEQUENTIAL[i + 1], at - i);
}

/** The colour of every yarn, by the mode chosen (COLOUR_MODES). */
export class Palette {
  // What `clear` sets (and `add`, `noteContact`, `recolour`, `refresh` fill in).
  /** @type {Map<number, string>} yarn id -> family */
  families;
  /** @type {Map<string, number>} weft family -> colour, in the order they appear */
  weftColours;
  /** @type {Map<number, Cell>} warp id -> [row, col] it was filled into */
  cells;
  /** @type {Map<number, Set<number>>} yarn id -> its neighbours' ids */
  neighbours;
  /** @type {Map<number, number>} yarn id -> index into YARN_COLOURS */
  graphColour;
  /** @type {number[]} yarns per colour index */
  uses;
  /** @type {Map<number, number>} yarn id -> contacts it is in, now */
  contacts;
  /** @type {Map<number, number>} the counts the colours show (taken at refresh) */
  shownContacts;
  /** @type {number} */
  mostContacts;
  /** @type {number} */
  fewestContacts;

  constructor(mode = 'family') {
    this.mode = COLOUR_MODES.includes(mode) ? mode : 'family';
    /** @type {Section | null} the braided section (view-zones.js), for "zone" */
    this.section = null;
    this.clear();
  }

  /** Forget every yarn (a new skeleton). */
  clear() {
    this.families = new Map(); // yarn id -> family
    this.weftColours = new Map(); // weft family -> colour, in the order they appear
    this.cells = new Map(); // warp id -> [row, col] it was filled into
    this.neighbours = new Map(); // yarn id -> Set of neighbour ids
    this.graphColour = new Map(); // yarn id -> index into YARN_COLOURS
    this.uses = new Array(YARN_COLOURS.length).fill(0); // yarns per colour index
    this.contacts = new Map(); // yarn id -> contacts it is in, now
    this.shownContacts = new Map(); // the counts the colours show (taken at refresh)
    this.mostContacts = 0;
    this.fewestContacts = 0;
  }

  /**
   * Choose a colour mode (an unknown one is "family").
   * @param {string} mode
   */
  setMode(mode) {
    this.mode = COLOUR_MODES.includes(mode) ? mode : 'family';
  }

  /**
   * Note a yarn (a warp with its fill `cell`); returns its family.
   * @param {YarnData} yarn
   */
  add(yarn) {
    const family = familyOf(yarn);
    this.families.set(yarn.id, family);
    if (family !== 'warp' && !this.weftColours.has(family)) {
      this.weftColours.set(family, WEFT_COLOURS[this.weftColours.size % WEFT_COLOURS.length]);
    }
    if (yarn.kind === 'warp' && Array.isArray(yarn.cell)) this.cells.set(yarn.id, yarn.cell);
    if (!this.neighbours.has(yarn.id)) this.neighbours.set(yarn.id, new Set());
    if (!this.contacts.has(yarn.id)) this.contacts.set(yarn.id, 0);
    this.pick(yarn.id); // a yarn added while a program runs (a weft) gets a colour at once
    return family;
  }

  /**
   * A contact between yarns `a` and `b` (they become neighbours).
   * @param {number} a
   * @param {number} b
   */
  noteContact(a, b) {
    for (const [one, other] of [[a, b], [b, a]]) {
      this.contacts.set(one, (this.contacts.get(one) ?? 0) + 1);
      const neighbours = this.neighbours.get(one);
      if (neighbours) neighbours.add(other);
      else this.neighbours.set(one, new Set([other]));
    }
  }

  /**
   * The braided section (or null): the zones of "zone".
   * @param {Section | null} section
   */
  setSection(section) {
    this.section = section;
  }

  /**
   * Colour every yarn again from scratch (after loading a whole skeleton): the fill
   * neighbours are found, the graph coloured greedily in yarn-id order, the contact counts
   * taken.
   */
  recolour() {
    this.linkFill();
    this.graphColour.clear();
    this.uses.fill(0);
    for (const id of [...this.families.keys()].sort((a, b) => a - b)) this.pick(id);
    this.takeCounts();
  }

  /**
   * The updates paused: recolour only the yarns that share a colour with a neighbour (the
   * higher id of each such pair), and take the contact counts. True if a colour changed.
   */
  refresh() {
    let changed = false;
    for (const id of [...this.families.keys()].sort((a, b) => a - b)) {
      const mine = this.graphColour.get(id);
      const clash = [...(this.neighbours.get(id) ?? [])].some((n) => n < id && this.graphColour.get(n) === mine);
      if (clash) {
        this.pick(id);
        changed = changed || this.graphColour.get(id) !== mine;
      }
    }
    const before = this.mostContacts;
    const counts = [...this.shownContacts];
    this.takeCounts();
    const countsChanged = before !== this.mostContacts || counts.some(([id, n]) => this.shownContacts.get(id) !== n);
    return (this.mode === 'yarn' && changed) || (this.mode === 'contacts' && countsChanged);
  }

  takeCounts() {
    this.shownContacts = new Map(this.contacts);
    const counts = [...this.shownContacts.values()];
    this.mostContacts = Math.max(0, ...counts);
    this.fewestContacts = Math.min(this.mostContacts, ...counts);
  }

  /**
   * A contact count's colour: the map spans the fewest to the most any yarn has.
   * @param {number} count
   */
  countColour(count) {
    return sequential(count - this.fewestContacts, this.mostContacts - this.fewestContacts);
  }

  /** Warps whose fill cells touch, or that face each other across empty cells of a row or column. */
  linkFill() {
    const at = new Map([...this.cells].map(([id, [r, c]]) => [`${r},${c}`, id]));
    /**
     * @param {number} a
     * @param {number} b
     */
    const link = (a, b) => {
      this.neighbours.get(a)?.add(b);
      this.neighbours.get(b)?.add(a);
    };
    for (const [id, [r, c]] of this.cells) {
      for (const [dr, dc] of [[0, 1], [1, -1], [1, 0], [1, 1]]) {
        const other = at.get(`${r + dr},${c + dc}`);
        if (other !== undefined) link(id, other);
      }
    }
    for (const axis of [0, 1]) {
      /** @type {Map<number, [number, number][]>} row (or column) -> [[position, id]...] */
      const lines = new Map();
      for (const [id, cell] of this.cells) {
        const key = cell[axis];
        const line = lines.get(key);
        if (line) line.push([cell[1 - axis], id]);
        else lines.set(key, [[cell[1 - axis], id]]);
      }
      for (const line of lines.values()) {
        line.sort((p, q) => p[0] - q[0]);
        for (let i = 1; i < line.length; i += 1) link(line[i - 1][1], line[i][1]);
      }
    }
  }

  /**
   * Give yarn `id` the colour its coloured neighbours use least (see the top of the file).
   * @param {number} id
   */
  pick(id) {
    const old = this.graphColour.get(id);
    if (old !== undefined) this.uses[old] -= 1;
    const taken = new Array(YARN_COLOURS.length).fill(0);
    for (const n of this.neighbours.get(id) ?? []) {
      const k = this.graphColour.get(n);
      if (k !== undefined && n !== id) taken[k] += 1;
    }
    // The least used of the free colours in [from, to); with `any`, the least clashing.
    /**
     * @param {number} from
     * @param {number} to
     */
    const least = (from, to, any = false) => {
      let best = -1;
      for (let k = from; k < to; k += 1) {
        if (!any && taken[k] > 0) continue;
        if (best < 0 || taken[k] < taken[best] || (taken[k] === taken[best] && this.uses[k] < this.uses[best])) best = k;
      }
      return best;
    };
    let best = least(0, HUES.length);
    if (best < 0) best = least(HUES.length, YARN_COLOURS.length);
    if (best < 0) best = least(0, YARN_COLOURS.length, true); // more neighbours than colours
    this.graphColour.set(id, best);
    this.uses[best] += 1;
  }

  /**
   * The zone of a yarn: its fill cell's zone, "edge", "weft", or null without a section.
   * @param {number} yarnId
   */
  zone(yarnId) {
    if ((this.families.get(yarnId) ?? 'warp') !== 'warp') return 'weft';
    if (!this.section) return null;
    const cell = this.cells.get(yarnId);
    return cell ? zoneOf(this.section, cell[0], cell[1]) ?? 'edge' : 'edge';
  }

  /**
   * The colour of the yarn with this id, 0xRRGGBB.
   * @param {number} yarnId
   * @returns {number}
   */
  colour(yarnId) {
    if (this.mode === 'yarn') return YARN_COLOURS[this.graphColour.get(yarnId) ?? 0];
    if (this.mode === 'contacts') return this.countColour(this.shownContacts.get(yarnId) ?? 0);
    const family = this.families.get(yarnId) ?? 'warp';
    if (this.mode === 'zone') return this.zoneColour(this.zone(yarnId));
    // (every weft family has its colour from `add`; an unknown yarn is a warp, as above)
    return family === 'warp' ? WARP_COLOUR : this.weftColours.get(family) ?? WARP_COLOUR;
  }

  /**
   * @param {string | null} zone
   * @returns {number}
   */
  zoneColour(zone) {
    if (zone === null) return NO_SECTION_COLOUR;
    if (zone === 'edge') return EDGE_COLOUR;
    if (zone === 'weft') return ZONE_WEFT_COLOUR;
    const names = (this.section?.zones ?? []).map(([name]) => name); // a zone: there is a section
    const junctions = names.filter((name) => name.includes('junction'));
    if (junctions.includes(zone)) return JUNCTION_COLOURS[junctions.indexOf(zone) % JUNCTION_COLOURS.length];
    const others = names.filter((name) => !name.includes('junction'));
    return ZONE_COLOURS[others.indexOf(zone) % ZONE_COLOURS.length];
  }

  /**
   * The legend of the mode: [[label, colour], ...].
   * @returns {[string, number][]}
   */
  legend() {
    if (this.mode === 'yarn') return [];
    if (this.mode === 'contacts') return this.contactsLegend();
    if (this.mode === 'zone') return this.zoneLegend();
    /** @type {[string, number][]} */
    const entries = [];
    if ([...this.families.values()].includes('warp')) entries.push(['warp', WARP_COLOUR]);
    for (const [family, colour] of this.weftColours) entries.push([family, colour]);
    return entries;
  }

  /** @returns {[string, number][]} */
  contactsLegend() {
    const [low, high] = [this.fewestContacts, this.mostContacts];
    /** @param {number} i */
    const at = (i) => Math.round(low + (i * (high - low)) / (SEQUENTIAL_STEPS - 1));
    const values = [...new Set(Array.from({ length: SEQUENTIAL_STEPS }, (_, i) => at(i)))];
    return values.map((v, i) => [`${v}${i === values.length - 1 ? ' contacts' : ''}`, this.countColour(v)]);
  }

  /** @returns {[string, number][]} */
  zoneLegend() {
    const zones = new Set([...this.families.keys()].map((id) => this.zone(id)));
    /** @type {[string, number][]} */
    const entries = this.section ? this.section.zones.map(([name]) => [name, this.zoneColour(name)]) : [['no section line', NO_SECTION_COLOUR]];
    if (zones.has('edge')) entries.push(['edge carrier', EDGE_COLOUR]);
    if (zones.has('weft')) entries.push(['weft', ZONE_WEFT_COLOUR]);
    return entries;
  }
}
