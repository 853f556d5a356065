// @ts-check
// Instructions and runs in words, as the program writes them.

import { signed } from './grid.js';

/** @import { Instruction, Next, ShiftMove, State } from '../types/daemon' */

/**
 * "next: line 12 — ROW 1:+1 2:-1", "next: line 14 — TAKEUP 3 mm".
 * @param {State | null} state
 * @param {Next | null} next
 * @param {number} index
 */
export function describeNext(state, next, index) {
  if (!state) return 'next: —';
  if (state.program_id === null || state.program_id === undefined) return 'next: — (no program loaded)';
  if (!next) {
    if (index >= state.count) return 'next: — (program done)';
    return state.resumable ? 'next: — (the run has ended; start with resume continues it)' : 'next: — (the run has ended)';
  }
  const where = next.line ? `line ${next.line}` : `instruction ${next.index}`;
  return `next: ${where} — ${describeInstruction(next.instruction ?? {})}`;
}

/**
 * "ROW 1:+1 3[0..3]:-1", "TAKEUP 3 mm", "WEFT at x=… mm, angle 0°, length 60 mm".
 * @param {Instruction | {kind?: undefined}} i the instruction ({} for none)
 */
export function describeInstruction(i) {
  /** @param {unknown} value */
  const number = (value) => String(Number(Number(value).toFixed(3)));
  if (i.kind === 'shift') {
    // a move is [line, k], or [line, k, first, last] on a segment
    /** @param {ShiftMove} move */
    const move = ([line, k, first, last]) => `${line}${first === undefined ? '' : `[${first}..${last}]`}:${signed(k)}`;
    return `${String(i.axis).toUpperCase()} ${i.moves.map(move).join(' ')}`;
  }
  if (i.kind === 'takeup') return `TAKEUP ${number(i.length)} mm`;
  if (i.kind === 'weft') {
    return `WEFT at x=${number(i.x)} y=${number(i.y)} z=${number(i.z)} mm, angle ${number(i.angle)}°, length ${number(i.length)} mm`;
  }
  return String(i.kind ?? 'unknown');
}

/**
 * "Execute: braid.bws (#3), 22 of 50 instructions done"
 * @param {State | null} state
 * @param {number} index
 */
export function describeRun(state, index) {
  if (!state) return '';
  if (state.program_id === null || state.program_id === undefined) return state.name;
  return `${state.name}: ${state.program_name ?? 'program'} (#${state.program_id}), ${index} of ${state.count} instructions done`;
}
