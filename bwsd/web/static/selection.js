// @ts-check
// The yarn picked in the 3D view or the matrix: highlighted in both, described in the
// Selection panel (id, kind, family, contacts, length, as the 3D view knows the yarn).

import { byId as $ } from './dom.js';

/** @import { MatrixGrid } from './grid.js' */
/** @import { PreformView } from './skeleton.js' */

export class Selection {
  /**
   * @param {PreformView} view the 3D view (`onPick`, `highlight(id)`, `yarnInfo(id)`)
   * @param {MatrixGrid} grid the matrix (`onPick`, `highlight(id)`)
   * @param {(id: number | null) => void} onChange called with the yarn picked (or null)
   */
  constructor(view, grid, onChange) {
    this.view = view;
    this.grid = grid;
    this.onChange = onChange;
    /** @type {number | null} */
    this.selected = null;
    // Picking the selected yarn again clears the selection.
    /** @param {number | null} id */
    const picked = (id) => this.select(id === this.selected ? null : id);
    view.onPick = picked;
    grid.onPick = picked;
    $('selection-clear').addEventListener('click', () => this.select(null));
  }

  /**
   * Highlight yarn `id` in both views and describe it (null: no selection).
   * @param {number | null | undefined} id
   */
  select(id) {
    this.selected = id ?? null;
    if (typeof this.view.highlight === 'function') this.view.highlight(this.selected);
    if (typeof this.grid.highlight === 'function') this.grid.highlight(this.selected);
    this.draw();
    this.onChange(this.selected);
  }

  draw() {
    const id = this.selected;
    const info = id !== null && typeof this.view.yarnInfo === 'function' ? this.view.yarnInfo(id) : null;
    $('selection').hidden = id === null;
    /** @param {unknown} value */
    const mm = (value) => (typeof value === 'number' ? `${Number(value.toFixed(2))} mm` : '—');
    /** @param {unknown} value */
    const text = (value) => (value === undefined || value === null ? '—' : String(value));
    $('selection-id').textContent = text(info?.id ?? id);
    $('selection-kind').textContent = text(info?.kind);
    $('selection-family').textContent = text(info?.family);
    $('selection-contacts').textContent = text(info?.contacts);
    $('selection-length').textContent = mm(info?.length);
  }
}
