// The trainer console: a run's live state, its reliabilities as a live Table III, rewards
// by button or key with the credit they gave (summed per S-R pair), every reward of every
// source on a timeline, the person's own rewards with an undo, run control and the
// learning curve, and a stored episode replayed to reward its ticks. This module picks the
// run and controls it; the parts beside it draw.

import { get, post } from "../api.js";
import { watchFields } from "../forms.js";
import { $, $$, attempt, el, throttle, toast, typing } from "../ui.js";
import "../view2d.js"; // the 2D view listens for srlab:run and srlab:tick
import { drawCurve } from "./episodes.js";
import { loadMemory } from "./memory.js";
import * as setup from "./setup.js";
import { LIVE, state } from "./state.js";
import { initReplay, replayReward, replaying } from "./replay.js";
import { loadRuns, showRun } from "./status.js";
import { closeStream, follow, loadStored, resetLive } from "./stream.js";
import { drawRewards, drawTimeline } from "./timeline.js";
import { reward, undoLast } from "./train.js";
import { RunStatus, StimulusLevel } from "../generated/enums.js";

const POLL_MS = 2000;
const LAST_KEY = "srlab.console.run"; // the run this browser's console showed last

export function init(catalog) {
  state.catalog = catalog;
  state.high = new Set(catalog.stimuli.filter((s) => s.level === StimulusLevel.high).map((s) => s.name));
  state.known = new Set(catalog.behaviours.map((b) => b.name));
  $("#run-select").addEventListener("change", (e) => {
    location.hash = `#/console/${e.target.value}`;
  });
  $("#run-start").addEventListener("click", () => control("start"));
  $("#run-pause").addEventListener("click", () => control("pause"));
  $("#run-resume").addEventListener("click", () => control("resume"));
  $("#run-stop").addEventListener("click", () => control("stop"));
  for (const button of $$(".reward-buttons button.reward")) {
    button.addEventListener("click", () => give(Number(button.dataset.value)));
  }
  $("#reward-undo").addEventListener("click", undoLast);
  initReplay();
  $("#view3d").addEventListener("click", openView);
  const form = $("#new-run-form");
  form.addEventListener("submit", setup.onCreate);
  watchFields(form);
  form.condition.addEventListener("change", setup.describeCondition);
  for (const radio of $$('input[name="memory"]')) radio.addEventListener("change", () => loadMemory());
  document.addEventListener("keydown", onKey);
  document.addEventListener("srlab:networks", (e) => setup.fillNetworks(e.detail));
  window.addEventListener("resize", throttle(() => {
    drawCurve();
    drawTimeline();
  }, 200));
  // The 2D view's controls (pause, resume, step, rate) changed the run.
  document.addEventListener("srlab:run-changed", (e) => {
    if (!state.run || e.detail.id !== state.run.id) return;
    showRun(e.detail);
    if (LIVE.has(e.detail.status) && !state.source) follow();
  });
}

/**
 * Show the console for run `id` (or the newest run). A study participant's console
 * (`participant`) shows their run only, with no run control: what it would need (networks,
 * worlds, other runs) is not theirs to read. Resolves to the error that kept the run from
 * showing (an ApiError: a 403 for another's run), or null.
 */
export async function show(id, health, { participant = false } = {}) {
  state.active = true;
  state.participant = participant;
  state.viserPort = health ? health.viser_port : state.viserPort;
  if (!participant) {
    if (!$("#new-run-form").network.options.length || $("#new-run-form").network.options.length < 2) {
      const list = await attempt(() => get("/networks"));
      if (list) setup.fillNetworks(list.data);
    }
    if ($("#new-run-form").world.options.length < 2) await setup.fillSetup();
  }
  if (!state.conditions.size) await setup.fillConditions();
  await loadRuns();
  const failed = await select(id ? Number(id) : defaultRun());
  clearInterval(state.poll);
  state.poll = setInterval(poll, POLL_MS);
  return failed;
}

/**
 * The run the console opens on when the URL names none: the one this browser last
 * showed, if it is still there; else the newest running or paused run; else the newest.
 * (The newest run may be an unrelated finished one: an editor comparison's, say.)
 */
function defaultRun() {
  const last = Number(localStorage.getItem(LAST_KEY));
  if (state.runs.some((r) => r.id === last)) return last;
  const live = state.runs.filter((r) => LIVE.has(r.status));
  const pick = live.length ? live : state.runs;
  return pick.length ? pick[pick.length - 1].id : null;
}

export function hide() {
  state.active = false;
  clearInterval(state.poll);
  closeStream();
}

/** After the service comes back: reload everything and follow the run again. */
export async function reload(health) {
  if (!state.active) return;
  await show(state.run ? state.run.id : null, health, { participant: state.participant });
}

async function select(id) {
  closeStream();
  state.run = null;
  state.episodes = new Map();
  state.contiguous = 0;
  state.rewards = [];
  state.rewardIndex = new Map();
  state.logCount = 0;
  state.logTotal = 0;
  state.memory = new Map();
  state.network = new Map();
  state.tick = null;
  state.lastReward = null;
  state.credited = new Set();
  $("#reward-effect").replaceChildren(el("p", { class: "muted", text: "No reward yet." }));
  $("#assoc-feed").replaceChildren();
  $("#my-rewards").replaceChildren();
  resetLive();
  if (id === null || Number.isNaN(id)) {
    showRun(null);
    await loadMemory();
    drawCurve();
    drawRewards();
    return null;
  }
  // A participant's run is not the one the organiser's console should open on next.
  if (!state.participant) localStorage.setItem(LAST_KEY, String(id));
  let run;
  try {
    run = await get(`/runs/${id}`);
  } catch (error) {
    // A participant's page says why in place of the console, not in a corner.
    if (!state.participant) toast(`Run ${id}: ${error.message}`, "error", { offline: error.status === 0 });
    showRun(null);
    await loadMemory();
    drawCurve();
    drawRewards();
    return error;
  }
  $("#run-select").value = String(id);
  showRun(run);
  await loadStored();
  if (LIVE.has(run.status)) follow();
  return null;
}

/** Choose the run in the 3D view (a write: a POST), then open the answer's URL. */
async function openView(event) {
  event.preventDefault();
  const link = event.currentTarget;
  if (link.getAttribute("aria-disabled") === "true" || !link.dataset.run) return;
  const chosen = await attempt(() => post(`/runs/${link.dataset.run}/view`), "Opening the 3D view");
  // The answer's URL is the link's /run/<id> with a one-time ticket, which the view trades
  // for a cookie (what opens it when reads need a token) and then drops from the URL: a
  // view on /run/<id> keeps its run when its socket reconnects (after a restart, say).
  if (chosen) window.open(chosen.url, "_blank", "noopener");
}

async function poll() {
  if (!state.active || !state.run) return;
  const run = await attempt(() => get(`/runs/${state.run.id}`));
  if (!run || !state.run || run.id !== state.run.id) return;
  const wasLive = LIVE.has(state.run.status);
  showRun(run);
  if (LIVE.has(run.status)) {
    if (!state.source) follow();
    loadMemory();
  } else if (wasLive) {
    closeStream();
    await loadStored();
  }
}

async function control(action) {
  const run = state.run;
  if (!run) return;
  const updated = await attempt(() => post(`/runs/${run.id}/${action}`), `${action[0].toUpperCase()}${action.slice(1)} run ${run.id}`);
  if (!updated) return;
  showRun(updated);
  if (LIVE.has(updated.status) && !state.source) follow();
  await loadRuns();
}

/** A reward by key or button: to the replayed tick while the replay is open, else live. */
function give(value) {
  return replaying() ? replayReward(value) : reward(value);
}

function onKey(event) {
  if (!state.active || typing(event) || event.ctrlKey || event.metaKey || event.altKey) return;
  // A dialog (the keyboard help, the token) has the keyboard: nothing reaches the robot.
  if (document.querySelector("dialog[open]")) return;
  const plus = event.key === "+" || event.key === "=";
  const minus = event.key === "-" || event.key === "_";
  const pause = event.key === "P" && event.shiftKey && !state.participant; // run control is the organiser's
  if (!(plus || minus || pause)) return;
  event.preventDefault();
  if (event.repeat) return; // a held key is one reward, not one per repeat
  if (plus) give(1);
  else if (minus) give(-1);
  else if (state.run) {
    if (state.run.status === RunStatus.running) control("pause");
    else if (state.run.status === RunStatus.paused) control("resume");
  }
}
