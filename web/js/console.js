// The trainer console: a run's live state, its reliabilities as a live Table III, rewards
// by button or key with the credit they gave (summed per S-R pair), every reward of every
// source on a timeline, the person's own rewards with an undo, run control and the
// learning curve.

import { get, getAll, post } from "./api.js";
import { learningCurve } from "./chart.js";
import { columns, key, render, rows } from "./matrix.js";
import { $, $$, attempt, el, fmt, heat, throttle, toast, typing } from "./ui.js";
import "./view2d.js"; // the 2D view listens for srlab:run and srlab:tick

const LIVE = new Set(["running", "paused"]);
const TICK_HZ = 10;
const POLL_MS = 2000;
const BACKFILL_MS = 1000;
const TIMELINE_TICKS = 2000;
const SOURCES = ["trainer", "program", "task"];
const MINE_KEY = "srlab.mine";
const LAST_KEY = "srlab.console.run"; // the run this browser's console showed last
const KEEP_REWARDS = 3000; // the newest rewards the page holds (a fast rp run logs thousands)

const state = {
  catalog: null,
  high: new Set(),
  known: new Set(),
  runs: [],
  run: null,
  episodes: new Map(),
  conditions: new Map(),
  rewards: [],
  rewardIndex: new Map(),
  logCount: 0,
  logTotal: 0,
  contiguous: 0,
  memory: new Map(),
  network: new Map(),
  flashing: new Map(),
  source: null,
  poll: null,
  active: false,
  viserPort: null,
  lastReward: null,
  credited: new Set(),
  tick: null,
};

export function init(catalog) {
  state.catalog = catalog;
  state.high = new Set(catalog.stimuli.filter((s) => s.level === "high").map((s) => s.name));
  state.known = new Set(catalog.behaviours.map((b) => b.name));
  $("#run-select").addEventListener("change", (e) => {
    location.hash = `#/console/${e.target.value}`;
  });
  $("#run-start").addEventListener("click", () => control("start"));
  $("#run-pause").addEventListener("click", () => control("pause"));
  $("#run-resume").addEventListener("click", () => control("resume"));
  $("#run-stop").addEventListener("click", () => control("stop"));
  for (const button of $$(".reward-buttons button.reward")) {
    button.addEventListener("click", () => reward(Number(button.dataset.value)));
  }
  $("#reward-undo").addEventListener("click", undoLast);
  $("#view3d").addEventListener("click", openView);
  const form = $("#new-run-form");
  form.addEventListener("submit", onCreate);
  // A field the browser refuses says why beside it, even where its bubble would not show.
  form.addEventListener("invalid", (e) => fieldError(e.target, e.target.validationMessage), true);
  form.addEventListener("input", (e) => clearFieldError(e.target));
  form.condition.addEventListener("change", describeCondition);
  for (const radio of $$('input[name="memory"]')) radio.addEventListener("change", () => loadMemory());
  document.addEventListener("keydown", onKey);
  document.addEventListener("srlab:networks", (e) => fillNetworks(e.detail));
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

/** Show the console for run `id` (or the newest run). */
export async function show(id, health) {
  state.active = true;
  state.viserPort = health ? health.viser_port : state.viserPort;
  if (!$("#new-run-form").network.options.length || $("#new-run-form").network.options.length < 2) {
    const list = await attempt(() => get("/networks"));
    if (list) fillNetworks(list.data);
  }
  if ($("#new-run-form").world.options.length < 2) await fillSetup();
  if (!state.conditions.size) await fillConditions();
  await loadRuns();
  await select(id ? Number(id) : defaultRun());
  clearInterval(state.poll);
  state.poll = setInterval(poll, POLL_MS);
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
  await show(state.run ? state.run.id : null, health);
}

function fillNetworks(networks) {
  const select = $("#new-run-form").network;
  const chosen = select.value;
  select.replaceChildren(el("option", { value: "", text: "the condition's" }),
    ...networks.map((n) => el("option", { value: n.name, text: n.name })));
  select.value = networks.some((n) => n.name === chosen) ? chosen : "";
}

/** The world presets and sensor definitions a new run may name. */
async function fillSetup() {
  const [worlds, definitions] = await Promise.all([
    attempt(() => get("/worlds")), attempt(() => get("/sensor-definitions"))]);
  const form = $("#new-run-form");
  const options = (items) => items.map((x) => el("option", {
    value: x.name, text: x.default ? `${x.name} (default)` : x.name, title: x.description }));
  if (worlds) form.world.replaceChildren(el("option", { value: "", text: "the default" }), ...options(worlds));
  if (definitions) form.sensors.replaceChildren(el("option", { value: "", text: "the default" }), ...options(definitions));
}

/** The conditions the runs API takes, each with what it means for the one rewarding. */
async function fillConditions() {
  const list = await attempt(() => get("/conditions"));
  if (!list) return;
  state.conditions = new Map(list.map((c) => [c.name, c]));
  const select = $("#new-run-form").condition;
  const chosen = select.value || "trainer";
  const tag = (c) => (c.name === "trainer" ? " · you give the rewards (at the keyboard)"
    : c.trainer ? ` · a reward program (${c.trainer}) rewards too` : c.learning ? "" : " · does not learn");
  const ordered = [...list].sort((a, b) => (b.name === "trainer") - (a.name === "trainer"));
  select.replaceChildren(...ordered.map((c) => el("option", { value: c.name, text: `${c.name}${tag(c)}`, title: c.description })));
  select.value = state.conditions.has(chosen) ? chosen : "trainer";
  describeCondition();
  if (state.run) showRun(state.run);
}

/** What the chosen condition means: who rewards, whether it learns. */
function describeCondition() {
  const c = state.conditions.get($("#new-run-form").condition.value);
  $("#condition-about").textContent = c ? aboutRewards(c) : "";
}

function aboutRewards(c) {
  if (!c.learning) return `${c.description} Rewards are logged but change nothing.`;
  if (c.trainer) return `${c.description} Its reward program rewards by itself: for you alone at the keyboard, use trainer.`;
  if (c.name === "trainer") return `${c.description} Use it to train the robot yourself.`;
  return c.description;
}

function label(r) {
  const mode = r.mode === "realtime" ? `realtime ${r.hz} Hz` : "fast";
  const setup = r.world || r.sensors ? ` · ${r.world || "?"}/${r.sensors || "?"}` : "";
  return `#${r.id} · ${r.condition}${r.network ? ` (${r.network})` : ""}${setup} · ${mode} · ${r.status} · ${r.successes}/${r.episodes_done} ok`;
}

/** How a tick's behaviour came to run: "released by Corner (designed)", "default". */
function why(t) {
  const parts = t.how === "released" && t.released_by ? [] : [t.how];
  if (t.released_by) {
    const verb = t.how === "released" || t.how === "continued" ? "released by" : "answering";
    parts.push(`${verb} ${t.released_by}`);
  }
  let text = parts.join(", ");
  if (t.origin && t.origin !== t.how) text += ` (${t.origin})`;
  return text;
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

async function loadRuns() {
  const list = await attempt(() => getAll("/runs"), "Loading the runs");
  if (!list) return;
  state.runs = list.data;
  const select = $("#run-select");
  select.replaceChildren(...(state.runs.length
    ? state.runs.slice().reverse().map((r) => el("option", { value: r.id, text: label(r) }))
    : [el("option", { value: "", text: "no runs yet: create one with + New run" })]));
  if (state.run) select.value = String(state.run.id);
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
    return;
  }
  localStorage.setItem(LAST_KEY, String(id));
  let run;
  try {
    run = await get(`/runs/${id}`);
  } catch (error) {
    toast(`Run ${id}: ${error.message}`, "error", { offline: error.status === 0 });
    showRun(null);
    await loadMemory();
    drawCurve();
    drawRewards();
    return;
  }
  $("#run-select").value = String(id);
  showRun(run);
  await loadStored();
  if (LIVE.has(run.status)) follow();
}

/** Choose the run in the 3D view (a write: a POST), then open the link's /run/<id> URL. */
async function openView(event) {
  event.preventDefault();
  const link = event.currentTarget;
  if (link.getAttribute("aria-disabled") === "true" || !link.dataset.run) return;
  const chosen = await attempt(() => post(`/runs/${link.dataset.run}/view`), "Opening the 3D view");
  // The link's URL, not the answer's: a view opened on /run/<id> keeps its run when its
  // socket reconnects (after a restart of the service, say); one on / would not.
  if (chosen) window.open(link.href, "_blank", "noopener");
}

function showRun(run) {
  state.run = run;
  document.dispatchEvent(new CustomEvent("srlab:run", { detail: run })); // the 2D view listens
  const status = run ? run.status : "—";
  const badge = $("#run-status");
  badge.textContent = status;
  badge.className = `badge ${status}`;
  // One play button at a time: Resume a paused run (from the tick it paused at), Continue
  // a stopped or interrupted one (from its last stored episode's end), Start a new one.
  const paused = status === "paused";
  const going = paused || status === "running"; // Pause's counterpart is Resume
  $("#run-start").hidden = going;
  $("#run-resume").hidden = !going;
  $("#run-start").disabled = !run || !["created", "stopped", "interrupted"].includes(status);
  $("#run-start").textContent = run && status !== "created" ? "▶ Continue" : "▶ Start";
  $("#run-start").title = run && status !== "created"
    ? "Go on from the end of its last stored episode (the episode it stopped in runs again from its start)"
    : "Start the run";
  $("#run-pause").disabled = !run || status !== "running";
  $("#run-resume").disabled = !run || !paused;
  $("#run-stop").disabled = !run || !LIVE.has(status);
  const canReward = Boolean(run) && status === "running";
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

// --- the live stream ---------------------------------------------------------------------

function closeStream() {
  if (state.source) state.source.close();
  state.source = null;
}

function follow() {
  closeStream();
  const run = state.run;
  const source = new EventSource(`/api/runs/${run.id}/events?tick_hz=${TICK_HZ}`);
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

function resetLive() {
  for (const id of ["#st-lamp", "#st-progress", "#st-behaviour"]) {
    $(id).textContent = "—";
    $(id).style.color = "";
  }
  $("#st-stimuli").replaceChildren();
  $("#competition").replaceChildren();
  $("#st-threshold").textContent = "";
}

function onTick(t) {
  state.tick = t;
  document.dispatchEvent(new CustomEvent("srlab:tick", { detail: t })); // the 2D view listens
  $("#st-episode").textContent = t.episode;
  $("#st-tick").textContent = t.tick;
  const lamp = $("#st-lamp");
  lamp.textContent = t.lamp;
  lamp.style.color = { red: "#c0262d", yellow: "#a15c00", green: "#17803d" }[t.lamp] || "";
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
      const ok = e.outcome === "success" ? 1 : 0;
      showRun({ ...state.run, episodes_done: state.run.episodes_done + 1, successes: state.run.successes + ok });
    }
  }
  if (firstGap() !== null) backfillEpisodes();
  redrawCurve();
  refreshMemory();
}

/** A reward as the timeline keeps it, from the log or the stream. */
function rewardKey(r) {
  return `${r.tick}|${r.source}|${r.value}|${r.note}`;
}

function addReward(r) {
  const k = rewardKey(r);
  const known = state.rewardIndex.get(k);
  if (known) {
    for (const [name, v] of Object.entries(r)) if (v !== undefined) known[name] = v;
    return known;
  }
  const list = state.rewards;
  list.push(r);
  state.rewardIndex.set(k, r);
  if (list.length > 1 && list[list.length - 2].tick > r.tick) list.sort((a, b) => a.tick - b.tick);
  while (list.length > KEEP_REWARDS) state.rewardIndex.delete(rewardKey(list.shift()));
  return r;
}

function onReward(r) {
  refreshMemory();
  const previous = [...state.rewards].reverse().find((x) => x.tick < r.tick || (x.tick === r.tick && rewardKey(x) !== rewardKey(r)));
  const seen = state.rewardIndex.has(rewardKey(r));
  const kept = addReward({ tick: r.tick, episode: r.episode, value: r.value, source: r.source, note: r.note, credited: r.credited });
  if (!seen) state.logTotal += 1; // in the log too, not read from it yet
  redrawRewards();
  if (r.source !== "trainer") return;
  state.lastReward = r;
  state.credited.add(`${r.tick}:${r.value}`);
  showEffect(r, kept, previous);
}

/** The credit a reward gave, summed per S-R pair; its raw STM rows one click away. */
function showEffect(r, kept, previous) {
  const sign = r.value > 0 ? "+" : "−";
  const id = kept && kept.id !== undefined ? `#${kept.id} ` : "";
  const head = el("div", { class: "head" },
    `${id}${sign}${Math.abs(r.value)} at tick ${r.tick} (episode ${r.episode}) credited ${r.credited} STM record${r.credited === 1 ? "" : "s"}`);
  if (!r.credits.length) {
    $("#reward-effect").replaceChildren(head, el("p", { class: "muted why", text: whyNothing(r, previous) }));
    return;
  }
  const pairs = new Map();
  for (const c of r.credits) {
    const k = `${c.stimulus} → ${c.behaviour}`;
    const p = pairs.get(k) || { pair: k, count: 0, total: 0, dmin: Infinity, dmax: 0, after: c.after };
    p.count += 1;
    p.total += c.after - c.before;
    p.dmin = Math.min(p.dmin, c.d_k);
    p.dmax = Math.max(p.dmax, c.d_k);
    p.after = c.after;
    pairs.set(k, p);
  }
  const summed = [...pairs.values()].sort((a, b) => Math.abs(b.total) - Math.abs(a.total));
  // A credit that changed nothing (a punishment of a pair at 0 stays at 0) has no sign.
  const signed = (v) => (Math.abs(v) < 5e-4 ? "0.000" : `${v > 0 ? "+" : "−"}${fmt(Math.abs(v), 3)}`);
  const summary = el("table", { class: "pairs" },
    el("thead", {}, el("tr", {}, el("th", { text: "S → R" }), el("th", { text: "records" }), el("th", { text: "credit" }))),
    el("tbody", {}, summed.map((p) => el("tr", {
      class: "pair",
      title: `${p.pair}: ${p.count} STM record${p.count === 1 ? "" : "s"}, d_k ${p.dmin === p.dmax ? p.dmin : `${p.dmin}–${p.dmax}`}, reliability now ${fmt(p.after, 3)}`,
    },
      el("td", { text: p.pair }), el("td", { text: p.count }),
      el("td", { class: Math.abs(p.total) < 5e-4 ? "muted" : p.total > 0 ? "good" : "bad", text: signed(p.total), title: Math.abs(p.total) < 5e-4 ? "no change: the reliability was already at its bound" : undefined })))));
  const partial = r.credited > r.credits.length ? ` (the first ${r.credits.length} of ${r.credited})` : "";
  const raw = el("details", { class: "raw" },
    el("summary", { text: `the ${r.credits.length} raw STM rows${partial}` }),
    el("table", {},
      el("thead", {}, el("tr", {}, el("th", { text: "tick" }), el("th", { text: "S → R" }), el("th", { text: "d_k" }), el("th", { text: "reliability" }))),
      el("tbody", {}, r.credits.map((c) => el("tr", {},
        el("td", { text: c.tick }), el("td", { text: `${c.stimulus} → ${c.behaviour}` }),
        el("td", { text: c.d_k }), el("td", { text: `${fmt(c.before, 3)} → ${fmt(c.after, 3)}` }))))));
  $("#reward-effect").replaceChildren(head,
    el("p", { class: "muted small", text: `Per S-R pair${partial}: credit is the change in LTM reliability.` }), summary, raw);
}

/**
 * Why a reward credited nothing, from what came before it. STM holds a record for each
 * tick whose behaviour answered a stimulus (not the default behaviour's ticks); every
 * reward, of any source, takes the records before it, and STM is emptied per episode.
 */
function whyNothing(r, previous) {
  const c = state.run ? state.conditions.get(state.run.condition) : null;
  if (c && !c.learning) return `${state.run.condition} does not learn: the reward is logged and changes nothing.`;
  const recorded = "STM records only the ticks where a behaviour answered a stimulus (not the default behaviour's)";
  if (previous && previous.episode === r.episode) {
    const what = `${previous.id !== undefined ? `#${previous.id} ` : "the reward "}(${previous.source}, ${previous.value > 0 ? "+" : ""}${previous.value}) at tick ${previous.tick}`;
    const took = previous.credited ? `, which took the records before it (${previous.credited})` : "";
    const program = previous.source === "program"
      ? " In this condition a reward program rewards by itself; in trainer only you and the task do."
      : "";
    return `Nothing in STM to credit: ${recorded}, and none was recorded since ${what}${took}.${program}`;
  }
  return `Nothing in STM to credit: ${recorded}, STM is emptied when an episode starts, and none was recorded yet in episode ${r.episode}.`;
}

function onAssociation(a) {
  const li = el("li", { class: a.change },
    `${a.change === "promoted" ? "+" : "−"} ${a.stimulus} → ${a.behaviour} `,
    el("span", { class: "muted", text: `(${fmt(a.reliability)})` }));
  $("#assoc-feed").prepend(li);
  while ($("#assoc-feed").children.length > 50) $("#assoc-feed").lastElementChild.remove();
  state.flashing.set(key(a.stimulus, a.behaviour), Date.now());
  refreshMemory();
}

// --- reliabilities and the learning curve ---------------------------------------------

/** What the store holds of the run: its episodes, rewards and reliabilities. */
function loadStored() {
  return Promise.all([loadEpisodes(), loadMemory(), loadRewards()]);
}

const memoryKind = () => ($('input[name="memory"]:checked') || { value: "ltm" }).value;

async function loadMemory() {
  const run = state.run;
  if (!run) {
    $("#heatmap").replaceChildren(el("p", { class: "muted", style: "padding:12px", text: "Pick or create a run." }));
    return;
  }
  const kind = memoryKind();
  const [memory, network] = await Promise.all([
    attempt(() => get(`/runs/${run.id}/${kind}`)),
    attempt(() => get(`/runs/${run.id}/network`)),
  ]);
  if (!memory || !network || !state.run || state.run.id !== run.id) return;
  state.memory = new Map(memory.data.map((m) => [key(m.stimulus, m.behaviour), m.reliability]));
  state.network = new Map(network.data.map((a) => [key(a.stimulus, a.behaviour), a]));
  drawHeat();
  explainEmpty(kind, run);
}

/** Why the chosen memory holds nothing (an empty grid says nothing by itself). */
function explainEmpty(kind, run) {
  const note = $("#memory-empty");
  const c = state.conditions.get(run.condition);
  let why = "";
  if (state.memory.size === 0) {
    if (c && !c.learning) why = `${run.condition} does not learn: its LTM and RLTM stay empty.`;
    else if (kind === "rltm" && c && !c.kp)
      why = `RLTM is knowledge propagation's memory: ${run.condition} runs without it (a kp run fills it).`;
    else if (kind === "rltm")
      why = "Nothing propagated yet: RLTM gets a camera pair when a reward follows sonar responses recorded while the camera saw an obstacle stimulus.";
    else why = "Nothing learned yet: LTM gets a pair when a reward credits an STM record (a tick whose behaviour answered a stimulus).";
  }
  note.textContent = why;
  note.hidden = !why;
}

const refreshMemory = throttle(() => loadMemory(), 700);

function drawHeat() {
  const { stimuli, behaviours, sensors } = state.catalog;
  const extra = [...state.memory.keys(), ...state.network.keys()].map((k) => k.split("\u0000")[1]);
  const now = Date.now();
  const table = render($("#heatmap"), {
    groups: rows(stimuli, sensors),
    cols: columns(behaviours, extra),
    selected: null,
    readonly: true,
    label: `${memoryKind().toUpperCase()} reliabilities of run ${state.run.id}`,
    cell: (s, b) => {
      const k = key(s, b);
      const v = state.memory.get(k);
      const a = state.network.get(k);
      if (v === undefined && !a) return null;
      const color = heat(v || 0);
      return {
        text: v === undefined ? "" : v >= 0.995 ? "1" : fmt(v, 2).slice(1),
        bg: v === undefined ? "" : color.bg,
        ink: color.ink,
        inNet: Boolean(a),
        source: a ? a.source : "",
        locked: a ? a.locked : false,
        title: `${s} → ${b}: ${v === undefined ? "no reliability" : `reliability ${fmt(v, 3)}`}${a ? `; in the network (${a.source}, strength ${fmt(a.strength)})` : ""}`,
      };
    },
  });
  for (const [k, at] of state.flashing) {
    if (now - at > 3500) {
      state.flashing.delete(k);
      continue;
    }
    const [s, b] = k.split("\u0000");
    const td = table.querySelector(`td.c[data-s="${CSS.escape(s)}"][data-b="${CSS.escape(b)}"]`);
    if (td) td.classList.add("flash");
  }
}

async function loadEpisodes() {
  const run = state.run;
  if (!run) return;
  const list = await attempt(() => getAll(`/runs/${run.id}/episodes`));
  if (!list || !state.run || state.run.id !== run.id) return;
  for (const e of list.data) keepEpisode(e);
  drawCurve();
}

function keepEpisode(e) {
  state.episodes.set(e.episode, e);
  while (state.episodes.has(state.contiguous)) state.contiguous += 1;
}

/** The number of the first episode missing below the newest one known (null: none). */
function firstGap() {
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

const backfillEpisodes = throttle(backfillNow, BACKFILL_MS);

function drawCurve() {
  learningCurve($("#curve"), [...state.episodes.values()]);
}

const redrawCurve = throttle(drawCurve, 250);

// --- the reward log: every source on a timeline, and the person's own --------------------

/** The newest `KEEP_REWARDS` of the run's reward log. */
async function loadRewards() {
  const run = state.run;
  if (!run) return;
  const head = await attempt(() => get(`/runs/${run.id}/rewards`, { limit: 1 }));
  if (!head || !state.run || state.run.id !== run.id) return;
  state.logCount = Math.max(state.logCount, head.count - KEEP_REWARDS);
  await syncRewards();
}

/** The reward log from what was read of it on (the log only grows). */
async function syncRewards() {
  const run = state.run;
  if (!run) return;
  for (;;) {
    const page = await attempt(() => get(`/runs/${run.id}/rewards`, { limit: 1000, offset: state.logCount }));
    if (!page || !state.run || state.run.id !== run.id) return;
    for (const r of page.data) addReward({ ...r });
    state.logCount += page.data.length;
    state.logTotal = Math.max(state.logTotal, page.count);
    if (!page.data.length || state.logCount >= page.count) break;
  }
  drawRewards();
}

function mine() {
  try {
    return new Set(JSON.parse(localStorage.getItem(`${MINE_KEY}.${state.run ? state.run.id : ""}`) || "[]"));
  } catch {
    return new Set();
  }
}

function rememberMine(id) {
  if (!state.run) return;
  const ids = mine();
  ids.add(id);
  localStorage.setItem(`${MINE_KEY}.${state.run.id}`, JSON.stringify([...ids].slice(-500)));
}

const undoOf = (r) => {
  const m = /^undo of #(\d+)$/.exec(r.note || "");
  return m ? Number(m[1]) : null;
};

/** The latest reward sent from this browser that is not an undo and not undone yet. */
function undoable() {
  const ids = mine();
  const undone = new Set(state.rewards.map(undoOf).filter((x) => x !== null));
  return [...state.rewards].reverse().find((r) => r.source === "trainer" && r.id !== undefined
    && ids.has(r.id) && undoOf(r) === null && !undone.has(r.id)) || null;
}

function drawRewards() {
  drawTimeline();
  drawMine();
  if (state.run) $("#reward-undo").disabled = state.run.status !== "running" || !undoable();
}

const redrawRewards = throttle(drawRewards, 300);

const NS = "http://www.w3.org/2000/svg";
function svgEl(tag, attrs = {}, text) {
  const node = document.createElementNS(NS, tag);
  for (const [k, v] of Object.entries(attrs)) node.setAttribute(k, String(v));
  if (text !== undefined) node.textContent = text;
  return node;
}

/** Every reward of the last `TIMELINE_TICKS` ticks, one lane per source, up good, down bad. */
function drawTimeline() {
  const box = $("#reward-timeline");
  const counts = Object.fromEntries(SOURCES.map((src) => [src, 0]));
  for (const r of state.rewards) counts[r.source] = (counts[r.source] || 0) + 1;
  const shown = state.rewards.length;
  const total = Math.max(state.logTotal, shown);
  $("#reward-counts").textContent = state.run
    ? `${Object.entries(counts).map(([src, n]) => `${src} ${n}`).join(" · ")}${total > shown ? ` (the newest ${shown} of ${total})` : ""}`
    : "";
  if (!state.rewards.length) {
    box.replaceChildren(el("p", { class: "empty", text: state.run ? "No rewards yet." : "Pick or create a run." }));
    return;
  }
  const now = Math.max(state.tick ? state.tick.tick : 0, state.rewards[state.rewards.length - 1].tick);
  const from = Math.max(0, now - TIMELINE_TICKS);
  const width = Math.max(600, box.clientWidth || 1200);
  const lane = 36;
  const pad = { l: 70, r: 14, t: 4, b: 8 };
  const height = pad.t + lane * SOURCES.length + pad.b;
  const x = (t) => pad.l + ((t - from) / Math.max(1, now - from)) * (width - pad.l - pad.r);
  const root = svgEl("svg", { viewBox: `0 0 ${width} ${height}`, role: "img", "aria-label": "Rewards by tick and source" });
  SOURCES.forEach((src, i) => {
    const mid = pad.t + lane * i + lane / 2;
    root.append(svgEl("line", { x1: pad.l, x2: width - pad.r, y1: mid, y2: mid, stroke: "#e3e6eb" }));
    root.append(svgEl("text", { x: pad.l - 8, y: mid + 4, "text-anchor": "end", "font-size": 11, fill: "#5d6675" }, src));
  });
  root.append(svgEl("text", { x: width - pad.r, y: height - 1, "text-anchor": "end", "font-size": 10, fill: "#5d6675" }, `ticks ${from}–${now}`));
  const marks = svgEl("g", { class: "marks" });
  for (const r of state.rewards) {
    if (r.tick < from) continue;
    const i = Math.max(0, SOURCES.indexOf(r.source));
    const mid = pad.t + lane * i + lane / 2;
    const h = Math.max(2, Math.abs(r.value) * (lane / 2 - 3));
    const mark = svgEl("rect", {
      x: x(r.tick) - 1.5, width: 3, y: r.value >= 0 ? mid - h : mid, height: h,
      fill: r.value >= 0 ? "#17803d" : "#c0262d", class: `mark ${r.source}`,
      "data-source": r.source, "data-value": r.value,
    });
    mark.append(svgEl("title", {}, `${r.id !== undefined ? `#${r.id} ` : ""}${r.source} ${r.value > 0 ? "+" : ""}${r.value} at tick ${r.tick}${r.note ? `: ${r.note}` : ""}${r.credited !== undefined ? ` · credited ${r.credited}` : ""}`));
    marks.append(mark);
  }
  root.append(marks);
  box.replaceChildren(root);
}

/** The trainers' rewards, newest first, with their notes; this browser's marked "you". */
function drawMine() {
  const ids = mine();
  const undone = new Map(state.rewards.filter((r) => undoOf(r) !== null).map((r) => [undoOf(r), r]));
  const items = state.rewards.filter((r) => r.source === "trainer").slice(-100).reverse();
  $("#my-rewards").replaceChildren(...items.map((r) => {
    const by = undone.get(r.id);
    return el("li", { class: by ? "undone" : "", dataset: { id: r.id ?? "" } },
      el("span", { class: `v ${r.value >= 0 ? "pos" : "neg"}`, text: `${r.value > 0 ? "+" : r.value < 0 ? "−" : ""}${Math.abs(r.value)}` }),
      el("span", { class: "what" }, `${r.id !== undefined ? `#${r.id} · ` : ""}tick ${r.tick}`,
        r.note ? el("span", { class: "reward-note", text: ` · ${r.note}` }) : null,
        r.credited !== undefined ? el("span", { class: "muted", text: ` · credited ${r.credited}` }) : null),
      by ? el("span", { class: "muted small", text: `undone by #${by.id}` }) : null,
      r.id !== undefined && ids.has(r.id) ? el("span", { class: "muted small", text: "you" }) : null);
  }));
}

// --- control and rewards ---------------------------------------------------------------

async function control(action) {
  const run = state.run;
  if (!run) return;
  const updated = await attempt(() => post(`/runs/${run.id}/${action}`), `${action[0].toUpperCase()}${action.slice(1)} run ${run.id}`);
  if (!updated) return;
  showRun(updated);
  if (LIVE.has(updated.status) && !state.source) follow();
  await loadRuns();
}

async function reward(value, note) {
  const run = state.run;
  if (!run) return;
  const button = $(`.reward-buttons button[data-value="${value}"]`);
  if (button) {
    button.classList.add("pressed");
    setTimeout(() => button.classList.remove("pressed"), 150);
  }
  if (run.status !== "running") {
    toast(`Run ${run.id} is ${run.status}: rewards go to a running run.`, "error");
    return;
  }
  const input = $("#reward-note");
  const text = note ?? input.value.trim();
  const body = text ? { value, note: text } : { value };
  const ack = await attempt(() => post(`/runs/${run.id}/rewards`, body), "Reward");
  if (!ack) return;
  if (note === undefined) input.value = "";
  rememberMine(ack.id);
  // The log's id joins the stream's copy of the same reward (the stream has none).
  const logged = { id: ack.id, tick: ack.tick, episode: ack.episode, value: ack.value, source: "trainer", note: text };
  if (!state.rewardIndex.has(rewardKey(logged))) state.logTotal += 1;
  addReward(logged);
  drawRewards();
  // The stream may have shown its credit before the acknowledgement came back.
  if (state.credited.has(`${ack.tick}:${ack.value}`)) return;
  const sign = ack.value > 0 ? "+" : "−";
  $("#reward-effect").replaceChildren(el("div", { class: "head" },
    `${sign}${Math.abs(ack.value)} logged as reward #${ack.id} at tick ${ack.tick} (episode ${ack.episode}); crediting…`));
}

/**
 * "Undo my last reward": a compensating reward, never an erasure. It is a new trainer
 * reward of the opposite value noted "undo of #id", logged and applied like any other, so
 * the log still says what was given and a replay does the same. It credits what STM holds
 * now; the records the undone reward credited left STM with it.
 */
async function undoLast() {
  const last = undoable();
  if (!last) {
    toast("Nothing of yours to undo on this run.", "error");
    return;
  }
  await reward(-last.value, `undo of #${last.id}`);
}

function onKey(event) {
  if (!state.active || typing(event) || event.ctrlKey || event.metaKey || event.altKey) return;
  // A dialog (the keyboard help, the token) has the keyboard: nothing reaches the robot.
  if (document.querySelector("dialog[open]")) return;
  const plus = event.key === "+" || event.key === "=";
  const minus = event.key === "-" || event.key === "_";
  const pause = event.key === "P" && event.shiftKey;
  if (!(plus || minus || pause)) return;
  event.preventDefault();
  if (event.repeat) return; // a held key is one reward, not one per repeat
  if (plus) reward(1);
  else if (minus) reward(-1);
  else if (state.run) {
    if (state.run.status === "running") control("pause");
    else if (state.run.status === "paused") control("resume");
  }
}

/** Show `message` beside the form's field `input` (and mark it) until it is changed. */
function fieldError(input, message) {
  if (!input || !input.closest) return;
  const labelEl = input.closest("label");
  if (!labelEl) return;
  labelEl.classList.add("invalid");
  let note = $(".field-error", labelEl);
  if (!note) {
    note = el("span", { class: "field-error", role: "alert" });
    labelEl.append(note);
  }
  note.textContent = message;
}

function clearFieldError(input) {
  const labelEl = input && input.closest ? input.closest("label") : null;
  if (!labelEl) return;
  labelEl.classList.remove("invalid");
  const note = $(".field-error", labelEl);
  if (note) note.remove();
  if (input.setCustomValidity) input.setCustomValidity("");
}

function clearFormErrors(form) {
  for (const input of form.elements) clearFieldError(input);
  $("#new-run-error").hidden = true;
  $("#new-run-error").textContent = "";
}

/** The API's refusal on the form: a 422 names each field; anything else goes under it. */
function showCreateError(form, error) {
  const detail = error.body && error.body.detail;
  const rest = [];
  let first = null;
  if (Array.isArray(detail)) {
    for (const d of detail) {
      const name = [...(d.loc || [])].reverse().find((p) => typeof p === "string" && form.elements[p]);
      const input = name ? form.elements[name] : null;
      if (input && input.closest && input.closest("label")) {
        fieldError(input, d.msg);
        first = first || input;
      } else {
        rest.push(d.msg);
      }
    }
  } else {
    rest.push(error.message);
  }
  const box = $("#new-run-error");
  box.textContent = rest.length ? `Not created: ${rest.join("; ")}` : "Not created: see the marked field.";
  box.hidden = false;
  if (first) first.focus();
}

async function onCreate(event) {
  event.preventDefault();
  const form = event.target;
  clearFormErrors(form);
  const number = (input) => (input.value === "" ? undefined : Number(input.value));
  const params = {};
  if (form.eta.value !== "") params.eta = Number(form.eta.value);
  if (form.epsilon.value !== "") params.epsilon = Number(form.epsilon.value);
  const body = {
    condition: form.condition.value,
    mode: form.mode.value,
    hz: number(form.hz) ?? 10,
    seed: number(form.seed) ?? 0,
    episodes: number(form.episodes) ?? null,
    network: form.network.value || null,
    world: form.world.value || null,
    sensors: form.sensors.value || null,
    params,
  };
  let run;
  try {
    run = await post("/runs", body);
  } catch (error) {
    // The form stays open with what was typed, the refusal beside the field it names.
    showCreateError(form, error);
    toast(`Creating the run: ${error.message}`, "error", { offline: error.status === 0 });
    return;
  }
  form.closest("details").open = false;
  let started = null;
  if (form.start.checked) started = await attempt(() => post(`/runs/${run.id}/start`), `Starting run ${run.id}`);
  toast(`Run ${run.id} created${started ? " and started" : ""}.`, "ok");
  location.hash = `#/console/${run.id}`;
}
