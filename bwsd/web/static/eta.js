// @ts-check
// The time left of a run, from the recent instruction rate.
//
// The window holds the daemon's time stamps (`at`, seconds) of the last WINDOW instructions
// done while the machine ran without a pause; a hold, a stop or another program empties
// it. The rate is the instructions between the oldest and the newest stamp over the time
// between them, so it follows a program whose instructions take longer or shorter; the
// time left is the instructions left over that rate. Nothing is said before MIN_SAMPLES
// stamps are in.

export const WINDOW = 20;
export const MIN_SAMPLES = 3;

export class RateWindow {
  constructor(size = WINDOW) {
    this.size = size;
    /** @type {{index: number, at: number}[]} oldest first */
    this.samples = [];
  }

  /** Forget every stamp (the run paused or another program was loaded). */
  clear() {
    this.samples = [];
  }

  /**
   * Instruction `index` was done at `at` (seconds); an older or repeated one is ignored.
   * @param {number} index
   * @param {number} at
   */
  add(index, at) {
    const last = this.samples[this.samples.length - 1];
    if (last && (index <= last.index || at < last.at)) return;
    this.samples.push({ index, at });
    if (this.samples.length > this.size) this.samples.shift();
  }

  /** Instructions per second over the window, or null while it holds too few stamps. */
  rate() {
    if (this.samples.length < MIN_SAMPLES) return null;
    const first = this.samples[0];
    const last = this.samples[this.samples.length - 1];
    const seconds = last.at - first.at;
    return seconds > 0 ? (last.index - first.index) / seconds : null;
  }

  /**
   * `{seconds, rate, over}` for `left` instructions still to do, or null when unknown.
   * @param {number} left
   */
  estimate(left) {
    const rate = this.rate();
    if (rate === null || rate <= 0) return null;
    return { seconds: left / rate, rate, over: this.samples.length };
  }
}

/**
 * "45 s", "3 min 05 s", "2 h 07 min".
 * @param {number} seconds
 */
export function duration(seconds) {
  const s = Math.max(0, Math.round(seconds));
  if (s < 60) return `${s} s`;
  if (s < 3600) return `${Math.floor(s / 60)} min ${String(s % 60).padStart(2, '0')} s`;
  return `${Math.floor(s / 3600)} h ${String(Math.floor((s % 3600) / 60)).padStart(2, '0')} min`;
}

/**
 * A wall-clock time as HH:MM:SS (the browser's time zone).
 * @param {Date} date
 */
export function clock(date) {
  /** @param {number} n */
  const two = (n) => String(n).padStart(2, '0');
  return `${two(date.getHours())}:${two(date.getMinutes())}:${two(date.getSeconds())}`;
}
