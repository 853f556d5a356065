// @ts-check
// The run in the top bar: how far it is and the time left, in view at every window size
// and scroll position (the Job panel, which says more, may be out of view).

import { optionalById } from './dom.js';

/**
 * Show `index` of `count` instructions done and `left` ("time left: about 3 min 05 s",
 * "time left: estimating…", or "" while the machine stands); `count` 0: no program, nothing shown.
 * @param {number} index
 * @param {number} count
 * @param {string} left
 */
export function showRun(index, count, left) {
  const box = optionalById('run');
  const bar = optionalById('run-progress', HTMLProgressElement);
  const done = optionalById('run-count');
  const time = optionalById('run-left');
  if (!box || !bar || !done || !time) return;
  box.hidden = count <= 0;
  bar.max = Math.max(count, 1);
  bar.value = Math.min(index, count);
  done.textContent = `${index} / ${count}`;
  time.textContent = left;
  time.hidden = left === '';
}
