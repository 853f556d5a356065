// @ts-check
// The job history: the last programs with their outcome, instructions done and run time
// (`GET /api/v1/programs`), and the totals over every program the journal holds: how many
// ended each way and the run time in all (`GET /api/v1/programs/totals`). Read again when a
// program is loaded or the state changes.

import { request } from './api.js';
import { Coalesced } from './coalesced.js';
import { byId as $ } from './dom.js';

/** @import { Totals } from '../types/daemon' */
/** @import { Answer } from './api.js' */

const SHOWN = 10; // the newest programs listed
const ORDER = ['running', 'held', 'suspended', 'complete', 'aborted', 'stopped', 'loaded'];

/**
 * A program of `GET /api/v1/programs`, as the job history reads it.
 * @typedef {object} Job
 * @property {number} id
 * @property {string} name
 * @property {string} outcome
 * @property {number} done
 * @property {number} instructions
 * @property {number | null} started Unix time of its first start
 * @property {number | null} finished Unix time of its end
 */

/**
 * What the job history needs of the page.
 * @typedef {object} JobsPage
 * @property {(answer: Answer) => void} answered a refused answer (a 401 logs out)
 * @property {(error: unknown) => void} unreachable
 */

/**
 * A duration in words: "2 h 3 min", "3 min 24 s", "8.2 s".
 * @param {number} seconds
 */
export function duration(seconds) {
  if (seconds < 60) return `${seconds.toFixed(1)} s`;
  const s = Math.round(seconds);
  const h = Math.floor(s / 3600);
  const m = Math.floor((s % 3600) / 60);
  return h ? `${h} h ${m} min` : `${m} min ${s % 60} s`;
}

/**
 * A job's run time: from its first start to its end, or to now while it has not ended.
 * @param {Job} job
 */
export function runTime(job) {
  if (job.started === null || job.started === undefined) return '—';
  if (job.finished === null || job.finished === undefined) return `${duration(Math.max(0, Date.now() / 1000 - job.started))} so far`;
  return duration(Math.max(0, job.finished - job.started));
}

export class JobsPanel {
  /** @param {JobsPage} page */
  constructor(page) {
    this.page = page;
    this.generation = 0;
    this.fetch = new Coalesced(() => this.read(), { onError: (error) => page.unreachable(error) });
  }

  refresh() {
    return this.fetch.run();
  }

  async read() {
    const asked = this.generation;
    const [jobs, totals] = await Promise.all([request(`api/v1/programs?limit=${SHOWN}`), request('api/v1/programs/totals')]);
    if (asked !== this.generation) return;
    if (!jobs.ok || !totals.ok) {
      this.page.answered(jobs.ok ? totals : jobs);
      return;
    }
    this.drawTotals(totals.body);
    $('jobs-body').replaceChildren(...jobs.body.map((/** @type {Job} */ job) => row(job)));
  }

  /** @param {Totals} totals */
  drawTotals(totals) {
    const outcomes = Object.keys(totals.outcomes).sort((a, b) => ORDER.indexOf(a) - ORDER.indexOf(b));
    const counts = outcomes.map((outcome) => {
      const chip = document.createElement('span');
      chip.className = `outcome outcome-${outcome}`;
      chip.dataset.outcome = outcome;
      chip.textContent = `${outcome} ${totals.outcomes[outcome].programs}`;
      return chip;
    });
    const all = document.createElement('span');
    all.className = 'jobs-all';
    all.textContent = totals.programs
      ? `${totals.programs} program${totals.programs === 1 ? '' : 's'}, run time ${duration(totals.run_s)}`
      : 'no program yet';
    $('jobs-totals').replaceChildren(all, ...counts);
  }

  clear() {
    this.generation += 1;
    $('jobs-totals').replaceChildren();
    $('jobs-body').replaceChildren();
  }
}

/** @param {Job} job */
function row(job) {
  const tr = document.createElement('tr');
  tr.dataset.id = String(job.id);
  const outcome = document.createElement('span');
  outcome.className = `outcome outcome-${job.outcome}`;
  outcome.textContent = job.outcome;
  const cells = [`#${job.id}`, job.name, outcome, `${job.done} / ${job.instructions}`, runTime(job)];
  for (const cell of cells) {
    const td = document.createElement('td');
    td.append(cell);
    tr.append(td);
  }
  return tr;
}
