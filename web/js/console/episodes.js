// The run's episodes and its learning curve: read from the store, kept from the stream,
// and any gap between the two filled from the store a page at a time.

import { get, getAll } from "../api.js";
import { learningCurve } from "../chart.js";
import { $, attempt, throttle } from "../ui.js";
import { state } from "./state.js";

const BACKFILL_MS = 1000;

export async function loadEpisodes() {
  const run = state.run;
  if (!run) return;
  const list = await attempt(() => getAll(`/runs/${run.id}/episodes`));
  if (!list || !state.run || state.run.id !== run.id) return;
  for (const e of list.data) keepEpisode(e);
  drawCurve();
}

export function keepEpisode(e) {
  state.episodes.set(e.episode, e);
  while (state.episodes.has(state.contiguous)) state.contiguous += 1;
}

/** The number of the first episode missing below the newest one known (null: none). */
export function firstGap() {
  return state.episodes.size > state.contiguous ? state.contiguous : null;
}

let backfilling = false;

/** Fetch the stored episodes from the first gap on, a page at a time (the list is by number). */
async function backfillNow() {
  const run = state.run;
  if (!run || backfilling) return;
  backfilling = true;
  try {
    let offset = firstGap() ?? state.episodes.size;
    for (;;) {
      const page = await attempt(() => get(`/runs/${run.id}/episodes`, { limit: 1000, offset }));
      if (!page || !state.run || state.run.id !== run.id) return;
      for (const e of page.data) keepEpisode(e);
      offset += page.data.length;
      if (!page.data.length || offset >= page.count || firstGap() === null) break;
    }
    drawCurve();
  } finally {
    backfilling = false;
  }
}

export const backfillEpisodes = throttle(backfillNow, BACKFILL_MS);

export function drawCurve() {
  learningCurve($("#curve"), [...state.episodes.values()]);
}

export const redrawCurve = throttle(drawCurve, 250);
