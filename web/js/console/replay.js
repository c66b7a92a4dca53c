// Feedback on replay: a stored episode of the console's run, scrubbed a tick at a time (or
// played at the run's rate) and drawn on the track as the 2D view draws the live robot.
// While it replays, + and - (keys and the Train card's buttons) reward the tick on screen
// of that episode: the service credits that episode's records in the reaction window
// before the tick, as it does for a live reward. Leaving the replay gives the keys back to
// the live robot. It fills the console's replay card and listens for `srlab:run`.

import { get, post } from "../api.js";
import { $, attempt, el, typing } from "../ui.js";
import { drawTrack } from "../view2d.js";
import { originNote, state } from "./state.js";
import { showRun } from "./status.js";
import { How, Lamp } from "../generated/enums.js";

/** The trace's lamp is its number on the camera channel (core's LampColor). */
const LAMPS = [Lamp.none, Lamp.red, Lamp.yellow, Lamp.green];
const LISTED = 500; // the newest episodes the picker lists
const FRAME_HZ = 30; // playing faster than this shows every few ticks, not every one

const replay = {
  canvas: null,
  world: null,
  worldOf: null,
  trace: [],
  episode: null,
  timer: null,
  runId: null,
};

/** Whether + and - go to the replay's tick rather than to the live robot. */
export function replaying() {
  return state.replay !== null;
}

export function initReplay() {
  const card = $("#replay-card");
  replay.canvas = el("canvas", { id: "replay-canvas", role: "img", "aria-label": "The robot at the replayed tick", width: 480, height: 320 });
  const pick = el("select", { id: "replay-episode", "aria-label": "Episode to replay" });
  pick.addEventListener("pointerdown", listEpisodes);
  pick.addEventListener("focus", listEpisodes);
  const slider = el("input", { id: "replay-tick", type: "range", min: "0", max: "0", value: "0", step: "1", "aria-label": "Tick of the episode" });
  slider.addEventListener("input", () => show(Number(slider.value)));
  card.tabIndex = -1;
  card.replaceChildren(
    el("div", { class: "card-head" },
      el("h2", { text: "Replay" }),
      el("span", { class: "muted small", text: "reward what the robot did in a stored episode" })),
    el("div", { class: "replay-pick" },
      el("label", {}, "Episode ", pick),
      el("button", { type: "button", id: "replay-open", text: "▶ Replay", onclick: open }),
      el("button", { type: "button", id: "replay-leave", text: "Leave replay", hidden: true, onclick: leave })),
    el("div", { id: "replay-body", class: "replay-body", hidden: true },
      el("div", { class: "replay-canvas" }, replay.canvas),
      el("div", { class: "replay-side" },
        el("div", { class: "replay-scrub" },
          el("button", { type: "button", id: "replay-play", text: "▶ Play", onclick: togglePlay }),
          slider),
        el("p", { id: "replay-at", class: "replay-at" }),
        el("p", { id: "replay-what", class: "behaviour" }),
        el("p", { id: "replay-why", class: "muted small" }),
        el("p", { class: "muted small" },
          "While replaying, ", el("kbd", { text: "+" }), " and ", el("kbd", { text: "-" }),
          " (and the Train card's buttons) reward the tick shown; ", el("kbd", { text: "←" }),
          " ", el("kbd", { text: "→" }), " step a tick, ", el("kbd", { text: "Esc" }), " leaves."),
        el("div", { id: "replay-answer", class: "effect", "aria-live": "polite" }))));
  card.addEventListener("keydown", onKey);
  new ResizeObserver(() => draw()).observe(replay.canvas);
  document.addEventListener("srlab:run", (e) => onRun(e.detail));
  listEpisodes();
}

function onRun(run) {
  const id = run ? run.id : null;
  if (id === replay.runId) {
    listEpisodes(); // the console's poll: episodes may have been stored since
    return;
  }
  replay.runId = id;
  close(); // another run: its buttons are being set for it
  replay.world = null;
  replay.worldOf = null;
  listEpisodes();
}

/** The picker: the run's stored episodes the console knows, newest first. */
function listEpisodes() {
  const pick = $("#replay-episode");
  const chosen = pick.value;
  const numbers = [...state.episodes.keys()].sort((a, b) => b - a).slice(0, LISTED);
  const listed = `${numbers.length}|${numbers[0]}`;
  if (pick.dataset.listed === listed) return; // unchanged: an open picker stays as it is
  pick.dataset.listed = listed;
  pick.replaceChildren(...(numbers.length
    ? numbers.map((n) => {
      const e = state.episodes.get(n);
      return el("option", { value: n, text: `#${n} · ${e.outcome}${e.cause ? ` (${e.cause})` : ""} · ${e.ticks} ticks` });
    })
    : [el("option", { value: "", text: "no stored episode yet" })]));
  if (numbers.includes(Number(chosen)) && chosen !== "") pick.value = chosen;
}

async function open() {
  listEpisodes();
  const run = state.run;
  const n = Number($("#replay-episode").value);
  if (!run || $("#replay-episode").value === "") return;
  const [episode, world] = await Promise.all([
    attempt(() => get(`/runs/${run.id}/episodes/${n}`), `Episode ${n}`),
    replay.worldOf === run.id ? replay.world : attempt(() => get(`/runs/${run.id}/world`), "Loading the track"),
  ]);
  if (!episode || !world || !state.run || state.run.id !== run.id) return;
  if (!episode.trace.length) {
    $("#replay-answer").replaceChildren(el("p", { class: "muted", text: `Episode ${n} has no stored trace to replay.` }));
    return;
  }
  stopPlaying();
  replay.world = world;
  replay.worldOf = run.id;
  replay.trace = episode.trace;
  replay.episode = n;
  const slider = $("#replay-tick");
  slider.max = String(episode.trace.length - 1);
  slider.value = "0";
  $("#replay-body").hidden = false;
  $("#replay-leave").hidden = false;
  $("#replay-answer").replaceChildren();
  document.body.classList.add("replaying");
  show(0);
  showRun(state.run); // the reward buttons as a replay's rewards want them
  slider.focus();
}

/** Back to live rewards: the keys and buttons reward what the live robot does. */
function leave() {
  close();
  if (state.run) showRun(state.run); // the reward buttons as live rewards want them
}

function close() {
  stopPlaying();
  state.replay = null;
  replay.trace = [];
  replay.episode = null;
  document.body.classList.remove("replaying");
  $("#replay-body").hidden = true;
  $("#replay-leave").hidden = true;
}

function show(i) {
  const row = replay.trace[i];
  if (!row) return;
  $("#replay-tick").value = String(i);
  state.replay = { episode: replay.episode, tick: row.tick };
  $("#replay-at").textContent = `episode ${replay.episode} · tick ${row.tick} (${i + 1} of ${replay.trace.length})`;
  $("#replay-what").textContent = row.behaviour ?? "no behaviour";
  $("#replay-why").textContent = released(row);
  draw();
}

/** What made the row's behaviour run: "released by Corner (designed)", "default". */
function released(row) {
  const by = !row.released_by ? row.how
    : row.how === How.released ? `released by ${row.released_by}` : `${row.how}, answering ${row.released_by}`;
  return by + originNote(row.origin, row.how);
}

function draw() {
  const row = replay.trace[Number($("#replay-tick").value)];
  drawTrack(replay.canvas, replay.world, row ? { ...row, lamp: LAMPS[row.lamp] ?? Lamp.none } : null);
}

function togglePlay() {
  if (replay.timer !== null) {
    stopPlaying();
    return;
  }
  const slider = $("#replay-tick");
  if (Number(slider.value) >= replay.trace.length - 1) show(0);
  const hz = state.run ? (state.run.live ? state.run.live.hz : state.run.hz) : FRAME_HZ;
  const every = Math.max(1, Math.round(hz / FRAME_HZ));
  replay.timer = setInterval(() => {
    const next = Math.min(replay.trace.length - 1, Number(slider.value) + every);
    show(next);
    if (next >= replay.trace.length - 1) stopPlaying();
  }, (1000 * every) / hz);
  $("#replay-play").textContent = "❚❚ Pause";
}

function stopPlaying() {
  clearInterval(replay.timer);
  replay.timer = null;
  $("#replay-play").textContent = "▶ Play";
}

/** The card's keys: ← → step a tick, Esc leaves; + and - from its slider or picker too. */
function onKey(event) {
  if (!replaying() || event.ctrlKey || event.metaKey || event.altKey) return;
  const at = Number($("#replay-tick").value);
  if (event.key === "ArrowLeft" || event.key === "ArrowRight") {
    event.preventDefault();
    stopPlaying();
    show(Math.max(0, Math.min(replay.trace.length - 1, at + (event.key === "ArrowLeft" ? -1 : 1))));
  } else if (event.key === "Escape") {
    leave();
  } else if (typing(event) && ["+", "=", "-", "_"].includes(event.key)) {
    // The console's keys leave form fields alone; the slider and the picker are the replay's.
    event.preventDefault();
    if (!event.repeat) replayReward(event.key === "+" || event.key === "=" ? 1 : -1);
  }
}

/**
 * Reward the replayed tick: `tick_seen` is the tick on screen, `episode` the replayed one.
 * The panel shows the answer: the records it credited, or the API's refusal.
 */
export async function replayReward(value) {
  const run = state.run;
  const seen = state.replay;
  if (!run || !seen) return;
  stopPlaying();
  const answer = $("#replay-answer");
  const body = { value, tick_seen: seen.tick, episode: seen.episode };
  let ack;
  try {
    ack = await post(`/runs/${run.id}/rewards`, body);
  } catch (error) {
    answer.replaceChildren(el("p", { class: "bad", text: error.message }));
    return;
  }
  const sign = value > 0 ? "+" : "−";
  const head = `${sign}${Math.abs(value)} at tick ${seen.tick} of episode ${seen.episode} (reward #${ack.id})`;
  answer.replaceChildren(el("p", { class: "head", text: `${head}: crediting…` }));
  // The log says what it credited once it is applied (the answer may come before that).
  const credited = ack.applied === true ? ack.credited : await creditOf(run.id, ack.id);
  answer.replaceChildren(el("p", { class: "head", text: credited === null
    ? `${head}: logged, not applied yet (the reward log will say what it credited)`
    : `${head}: credited ${credited} record${credited === 1 ? "" : "s"}` }));
}

const CREDIT_TRIES = 20;
const CREDIT_WAIT_MS = 500;
const LOG_TAIL = 200;

/**
 * The records reward `id` credited, read from the log once it is applied (null: not yet).
 * The log is in log order and the reward is in it (its answer is its log entry), so it lies
 * among the entries the log held at the first look: those are read each time, not the log's
 * tail, which a running run's own rewards move past it.
 */
async function creditOf(runId, id) {
  let at = null;
  for (let i = 0; i < CREDIT_TRIES; i += 1) {
    if (at === null) {
      const head = await attempt(() => get(`/runs/${runId}/rewards`, { limit: 1 }));
      if (!head) return null;
      at = Math.max(0, head.count - LOG_TAIL);
    }
    const page = await attempt(() => get(`/runs/${runId}/rewards`, { limit: LOG_TAIL, offset: at }));
    const row = page ? page.data.find((r) => r.id === id) : null;
    if (row && row.applied) return row.credited;
    await new Promise((resolve) => setTimeout(resolve, CREDIT_WAIT_MS));
  }
  return null;
}
