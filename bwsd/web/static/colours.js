// Yarn colours, shared by the 3D view and the machine matrix so a case in the grid has
// the colour of its yarn in the preform.
//
// Two ways to colour: by family (every warp one colour, each weft insertion angle its
// own) or by yarn (a distinct hue per yarn id, to follow one carrier through the braid).

export const WARP_COLOUR = 0x2c5282; // every warp, when colouring by family
const WEFT_COLOURS = [0xc0392b, 0x1e8449, 0xb9770e, 0x7d3c98, 0x117a8b, 0xa04000, 0x5d6d7e, 0x9a1d5a];
const GOLDEN_ANGLE = 137.508; // degrees: consecutive ids land far apart on the hue circle

/** The family of a yarn: "warp" or "weft-<angle>" (as the skeleton JSON spells it). */
export function familyOf(yarn) {
  if (yarn.family) return yarn.family;
  if (yarn.kind === 'warp') return 'warp';
  return `weft-${formatAngle(yarn.angle ?? 0)}`;
}

/** An angle in degrees as Python's "%g" writes it: 0, 90, 22.5, 33.3333. */
function formatAngle(angle) {
  return String(Number(angle.toPrecision(6)));
}

/** A colour 0xRRGGBB from hue (degrees), saturation and lightness (0..1). */
function hsl(hue, saturation, lightness) {
  const a = saturation * Math.min(lightness, 1 - lightness);
  const channel = (n) => {
    const k = (n + hue / 30) % 12;
    const value = lightness - a * Math.max(-1, Math.min(k - 3, 9 - k, 1));
    return Math.round(value * 255);
  };
  return (channel(0) << 16) | (channel(8) << 8) | channel(4);
}

/** 0xRRGGBB as CSS "#rrggbb". */
export function css(colour) {
  return `#${colour.toString(16).padStart(6, '0')}`;
}

/** Dark text on light colours, white on dark ones (for the grid's yarn ids). */
export function textOn(colour) {
  const r = (colour >> 16) & 255;
  const g = (colour >> 8) & 255;
  const b = colour & 255;
  return 0.299 * r + 0.587 * g + 0.114 * b > 150 ? '#111' : '#fff';
}

/** The colour of every yarn, by the mode chosen ("family" or "yarn"). */
export class Palette {
  constructor(mode = 'family') {
    this.mode = mode;
    this.families = new Map(); // yarn id -> family
    this.weftColours = new Map(); // weft family -> colour, in the order they appear
  }

  /** Forget every yarn (a new skeleton). */
  clear() {
    this.families.clear();
    this.weftColours.clear();
  }

  /** Note a yarn's family; returns it. */
  add(yarn) {
    const family = familyOf(yarn);
    this.families.set(yarn.id, family);
    if (family !== 'warp' && !this.weftColours.has(family)) {
      this.weftColours.set(family, WEFT_COLOURS[this.weftColours.size % WEFT_COLOURS.length]);
    }
    return family;
  }

  /** The colour of the yarn with this id, 0xRRGGBB. */
  colour(yarnId) {
    if (this.mode === 'yarn') return hsl((yarnId * GOLDEN_ANGLE) % 360, 0.7, 0.42);
    const family = this.families.get(yarnId) ?? 'warp';
    return family === 'warp' ? WARP_COLOUR : this.weftColours.get(family);
  }

  /** The legend of the family mode: [[family, colour], ...], warp first. */
  legend() {
    const entries = [];
    if ([...this.families.values()].includes('warp')) entries.push(['warp', WARP_COLOUR]);
    for (const [family, colour] of this.weftColours) entries.push([family, colour]);
    return entries;
  }
}
