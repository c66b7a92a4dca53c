// The run's live event stream: each tick's state and behaviour competition, episodes,
// rewards and associations as they happen; and what the store holds, read again when the
// stream starts or the run ends.

import { EventStream } from "../eventstream.js";
import { key } from "../matrix.js";
import { $, el, fmt, toast } from "../ui.js";
import { backfillEpisodes, firstGap, keepEpisode, loadEpisodes, redrawCurve } from "./episodes.js";
import { loadMemory, refreshMemory } from "./memory.js";
import { LIVE, originNote, state } from "./state.js";
import { showRun } from "./status.js";
import { loadRewards, syncRewards } from "./timeline.js";
import { onReward } from "./train.js";
import { AssociationChange, How, Lamp, Outcome } from "../generated/enums.js";

const TICK_HZ = 10;

export function closeStream() {
  if (state.source) state.source.close();
  state.source = null;
}

export function follow() {
  closeStream();
  const run = state.run;
  // Read with fetch, not EventSource: it carries the tab's token (`../eventstream.js`).
  const source = new EventStream(`/api/runs/${run.id}/events?tick_hz=${TICK_HZ}`);
  state.source = source;
  const data = (e) => JSON.parse(e.data);
  source.addEventListener("tick", (e) => onTick(data(e)));
  source.addEventListener("episode", (e) => onEpisode(data(e)));
  source.addEventListener("reward", (e) => onReward(data(e)));
  source.addEventListener("association", (e) => onAssociation(data(e)));
  source.addEventListener("status", (e) => {
    const d = data(e);
    // The stream's first event: what happened between the first load and now is in the
    // store, not in the stream, so it is fetched (the stream brings what follows).
    if (d.run !== undefined && d.run !== null) {
      backfillEpisodes();
      syncRewards();
    }
    if (state.run && state.run.id === run.id && d.status !== state.run.status) {
      const wasLive = LIVE.has(state.run.status);
      showRun({ ...state.run, status: d.status, error: d.error });
      if (d.error) toast(`Run ${run.id} ${d.status}: ${d.error}`, "error");
      // The engine commits learning behind the ticks; once the run has ended all of it is
      // stored, so the final state is read again rather than left as the last refresh saw it.
      if (wasLive && !LIVE.has(d.status)) loadStored();
    }
  });
  source.onerror = () => {
    // The stream ended (the run finished) or the service went away: the poll and the
    // reconnect logic decide what comes next.
    if (state.source === source) closeStream();
  };
}

export function resetLive() {
  for (const id of ["#st-lamp", "#st-progress", "#st-behaviour"]) {
    $(id).textContent = "—";
    $(id).style.color = "";
  }
  $("#st-stimuli").replaceChildren();
  $("#competition").replaceChildren();
  $("#st-threshold").textContent = "";
}

/** How a tick's behaviour came to run: "released by Corner (designed)", "default". */
function why(t) {
  const parts = t.how === How.released && t.released_by ? [] : [t.how];
  if (t.released_by) {
    const verb = t.how === How.released || t.how === How.continued ? "released by" : "answering";
    parts.push(`${verb} ${t.released_by}`);
  }
  return parts.join(", ") + originNote(t.origin, t.how);
}

function onTick(t) {
  state.tick = t;
  document.dispatchEvent(new CustomEvent("srlab:tick", { detail: t })); // the 2D view listens
  $("#st-episode").textContent = t.episode;
  $("#st-tick").textContent = t.tick;
  const lamp = $("#st-lamp");
  lamp.textContent = t.lamp;
  lamp.style.color = { [Lamp.red]: "#c0262d", [Lamp.yellow]: "#a15c00", [Lamp.green]: "#17803d" }[t.lamp] || "";
  $("#st-progress").textContent = `${fmt(t.progress_m, 1)} m`;
  $("#st-stimuli").replaceChildren(...(t.stimuli.length
    ? t.stimuli.map((s) => el("span", { class: `chip${state.high.has(s) ? " high" : ""}`, text: s }))
    : [el("span", { class: "muted small", text: "none" })]));
  const made = t.behaviour && !state.known.has(t.behaviour);
  const b = $("#st-behaviour");
  b.className = `behaviour${made ? " kp-made" : ""}`;
  const how = `· ${why(t)}`;
  b.replaceChildren(t.behaviour || "—", el("span", { class: "how", text: made ? `${how} · KP-made` : how }));
  drawCompetition(t.competition, t.behaviour);
}

function drawCompetition(comp, chosen) {
  const box = $("#competition");
  if (!comp) return;
  $("#st-threshold").textContent = `threshold ${fmt(comp.threshold)}`;
  if (!comp.values.length) {
    box.replaceChildren(el("p", { class: "muted small", text: "Nothing released: the default behaviour runs." }));
    return;
  }
  const top = Math.max(1, ...comp.values.map((v) => v.value));
  box.replaceChildren(...comp.values.map((v) => {
    const cls = v.behaviour === chosen ? "winner" : v.value < comp.threshold ? "below" : "";
    return el("div", { class: `bar-row ${cls}`, title: `${v.stimulus} releases ${v.behaviour} at ${fmt(v.value, 3)}` },
      el("span", { class: "name", text: v.behaviour }),
      el("span", { class: "bar-track" },
        el("span", { class: "bar-fill", style: `width:${(100 * v.value) / top}%` }),
        el("span", { class: "bar-thresh", style: `left:${(100 * comp.threshold) / top}%` })),
      el("span", { class: "val", text: fmt(v.value) }));
  }));
}

function onEpisode(e) {
  if (!state.episodes.has(e.episode)) {
    keepEpisode(e);
    if (state.run) {
      const ok = e.outcome === Outcome.success ? 1 : 0;
      showRun({ ...state.run, episodes_done: state.run.episodes_done + 1, successes: state.run.successes + ok });
    }
  }
  if (firstGap() !== null) backfillEpisodes();
  redrawCurve();
  refreshMemory();
}

function onAssociation(a) {
  const li = el("li", { class: a.change },
    `${a.change === AssociationChange.promoted ? "+" : "−"} ${a.stimulus} → ${a.behaviour} `,
    el("span", { class: "muted", text: `(${fmt(a.reliability)})` }));
  $("#assoc-feed").prepend(li);
  while ($("#assoc-feed").children.length > 50) $("#assoc-feed").lastElementChild.remove();
  state.flashing.set(key(a.stimulus, a.behaviour), Date.now());
  refreshMemory();
}

/** What the store holds of the run: its episodes, rewards and reliabilities. */
export function loadStored() {
  return Promise.all([loadEpisodes(), loadMemory(), loadRewards()]);
}
