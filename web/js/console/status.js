// The run's status as the console shows it: the run list, the status badge, the control
// buttons that fit it, the 3D view's link and the run's totals.

import { getAll } from "../api.js";
import { $, $$, attempt, el } from "../ui.js";
import { undoable } from "./rewards.js";
import { LIVE, state } from "./state.js";
import { Condition, RunMode, RunStatus } from "../generated/enums.js";

export function aboutRewards(c) {
  if (!c.learning) return `${c.description} Rewards are logged but change nothing.`;
  if (c.trainer) return `${c.description} Its reward program rewards by itself: for you alone at the keyboard, use trainer.`;
  if (c.name === Condition.trainer) return `${c.description} Use it to train the robot yourself.`;
  return c.description;
}

function label(r) {
  const mode = r.mode === RunMode.realtime ? `realtime ${r.hz} Hz` : "fast";
  const setup = r.world || r.sensors ? ` · ${r.world || "?"}/${r.sensors || "?"}` : "";
  return `#${r.id} · ${r.condition}${r.network ? ` (${r.network})` : ""}${setup} · ${mode} · ${r.status} · ${r.successes}/${r.episodes_done} ok`;
}

/** A run's ticks by origin, most first: "designed 70% · kp 12% · default 10%". */
function origins(counts) {
  const total = Object.values(counts || {}).reduce((a, b) => a + b, 0);
  if (!total) return "";
  return Object.entries(counts)
    .filter(([, n]) => n > 0)
    .sort((a, b) => b[1] - a[1])
    .map(([origin, n]) => {
      const pct = (100 * n) / total;
      return `${origin} ${pct < 1 ? "<1" : Math.round(pct)}%`;
    })
    .join(" · ");
}

export async function loadRuns() {
  const list = await attempt(() => getAll("/runs"), "Loading the runs");
  if (!list) return;
  state.runs = list.data;
  const select = $("#run-select");
  select.replaceChildren(...(state.runs.length
    ? state.runs.slice().reverse().map((r) => el("option", { value: r.id, text: label(r) }))
    : [el("option", { value: "", text: "no runs yet: create one with + New run" })]));
  if (state.run) select.value = String(state.run.id);
}

export function showRun(run) {
  state.run = run;
  document.dispatchEvent(new CustomEvent("srlab:run", { detail: run })); // the 2D view listens
  const status = run ? run.status : "—";
  const badge = $("#run-status");
  badge.textContent = status;
  badge.className = `badge ${status}`;
  // One play button at a time: Resume a paused run (from the tick it paused at), Continue
  // a stopped or interrupted one (from its last stored episode's end), Start a new one.
  const paused = status === RunStatus.paused;
  const going = paused || status === RunStatus.running; // Pause's counterpart is Resume
  $("#run-start").hidden = going;
  $("#run-resume").hidden = !going;
  $("#run-start").disabled = !run || ![RunStatus.created, RunStatus.stopped, RunStatus.interrupted].includes(status);
  $("#run-start").textContent = run && status !== RunStatus.created ? "▶ Continue" : "▶ Start";
  $("#run-start").title = run && status !== RunStatus.created
    ? "Go on from the end of its last stored episode (the episode it stopped in runs again from its start)"
    : "Start the run";
  $("#run-pause").disabled = !run || status !== RunStatus.running;
  $("#run-resume").disabled = !run || !paused;
  $("#run-stop").disabled = !run || !LIVE.has(status);
  // A replay's rewards go to a paused run too: the person scrubs while the robot waits.
  const canReward = Boolean(run) && (status === RunStatus.running || (state.replay !== null && paused));
  for (const button of $$(".reward-buttons button.reward")) button.disabled = !canReward;
  $("#reward-undo").disabled = !canReward || !undoable();
  const condition = run ? state.conditions.get(run.condition) : null;
  $("#train-about").textContent = !run ? "" : condition ? `${run.condition}: ${aboutRewards(condition)}` : run.condition;
  const link = $("#view3d");
  if (run && state.viserPort) {
    // The click chooses the run in the view (a POST: the API's way, kept for scripts), and
    // the link opens the view on a URL naming the run: the view's gate chooses it again
    // for every socket the page opens, so a reconnect (a restart) does not switch runs.
    link.href = `${location.protocol}//${location.hostname.includes(":") ? `[${location.hostname}]` : location.hostname}:${state.viserPort}/run/${run.id}`;
    link.dataset.run = String(run.id);
    link.setAttribute("aria-disabled", "false");
    link.title = `Open run #${run.id} in the 3D view`;
  } else {
    link.removeAttribute("href");
    link.setAttribute("aria-disabled", "true");
    link.title = state.viserPort ? "Pick a run first" : "The 3D view is not running on this service";
  }
  const tally = run && run.live ? origins(run.live.ticks_by_origin) : "";
  $("#st-origins").textContent = tally ? `Ticks by origin: ${tally}` : "";
  $("#st-success").textContent = run ? run.successes : "—";
  $("#st-failure").textContent = run ? run.episodes_done - run.successes : "—";
  if (!state.tick) {
    $("#st-episode").textContent = run ? run.episodes_done : "—";
    $("#st-tick").textContent = run ? run.ticks : "—";
  }
  const option = $(`#run-select option[value="${run ? run.id : ""}"]`);
  if (run && option) option.textContent = label(run);
}
