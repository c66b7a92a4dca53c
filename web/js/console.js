// The trainer console: a run's live state, its reliabilities as a live Table III, rewards
// by button or key with the credit they gave, run control and the learning curve.

import { get, getAll, post } from "./api.js";
import { learningCurve } from "./chart.js";
import { columns, key, render, rows } from "./matrix.js";
import { $, $$, attempt, el, fmt, heat, throttle, toast, typing } from "./ui.js";
import "./view2d.js"; // issue 18 hook: the 2D view listens for srlab:run and srlab:tick

const LIVE = new Set(["running", "paused"]);
const TICK_HZ = 10;
const POLL_MS = 2000;

const state = {
  catalog: null,
  high: new Set(),
  known: new Set(),
  runs: [],
  run: null,
  episodes: [],
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
  $("#reward-plus").addEventListener("click", () => reward(1));
  $("#reward-minus").addEventListener("click", () => reward(-1));
  $("#view3d").addEventListener("click", openView);
  $("#new-run-form").addEventListener("submit", onCreate);
  for (const radio of $$('input[name="memory"]')) radio.addEventListener("change", () => loadMemory());
  document.addEventListener("keydown", onKey);
  document.addEventListener("srlab:networks", (e) => fillNetworks(e.detail));
  window.addEventListener("resize", throttle(drawCurve, 200));
  // issue 18 hook: the 2D view's controls (pause, resume, step, rate) changed the run.
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
  await loadRuns();
  const wanted = id ? Number(id) : state.runs.length ? state.runs[state.runs.length - 1].id : null;
  await select(wanted);
  clearInterval(state.poll);
  state.poll = setInterval(poll, POLL_MS);
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
  state.episodes = [];
  state.memory = new Map();
  state.network = new Map();
  state.tick = null;
  state.lastReward = null;
  state.credited = new Set();
  $("#reward-effect").replaceChildren(el("p", { class: "muted", text: "No reward yet." }));
  $("#assoc-feed").replaceChildren();
  resetLive();
  if (id === null || Number.isNaN(id)) {
    showRun(null);
    await loadMemory();
    drawCurve();
    return;
  }
  let run;
  try {
    run = await get(`/runs/${id}`);
  } catch (error) {
    toast(`Run ${id}: ${error.message}`, "error");
    showRun(null);
    await loadMemory();
    drawCurve();
    return;
  }
  $("#run-select").value = String(id);
  showRun(run);
  await loadStored();
  if (LIVE.has(run.status)) follow();
}

/** Choose the run in the 3D view (a write: a POST), then open the view where it answers. */
async function openView(event) {
  event.preventDefault();
  const link = event.currentTarget;
  if (link.getAttribute("aria-disabled") === "true" || !link.dataset.run) return;
  const chosen = await attempt(() => post(`/runs/${link.dataset.run}/view`), "Opening the 3D view");
  if (chosen) window.open(chosen.url, "_blank", "noopener");
}

function showRun(run) {
  state.run = run;
  document.dispatchEvent(new CustomEvent("srlab:run", { detail: run })); // issue 18 hook: the 2D view
  const status = run ? run.status : "—";
  const badge = $("#run-status");
  badge.textContent = status;
  badge.className = `badge ${status}`;
  $("#run-start").disabled = !run || !["created", "stopped", "interrupted"].includes(status);
  $("#run-start").textContent = run && status !== "created" ? "▶ Continue" : "▶ Start";
  $("#run-pause").disabled = !run || status !== "running";
  $("#run-resume").disabled = !run || status !== "paused";
  $("#run-stop").disabled = !run || !LIVE.has(status);
  const canReward = Boolean(run) && status === "running";
  $("#reward-plus").disabled = !canReward;
  $("#reward-minus").disabled = !canReward;
  const link = $("#view3d");
  if (run && state.viserPort) {
    // The click chooses the run in the view (a POST: it changes what every viewer sees),
    // and the link opens the view.
    link.href = `${location.protocol}//${location.hostname.includes(":") ? `[${location.hostname}]` : location.hostname}:${state.viserPort}/`;
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
  document.dispatchEvent(new CustomEvent("srlab:tick", { detail: t })); // issue 18 hook: the 2D view
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
  if (!state.episodes.some((x) => x.episode === e.episode)) state.episodes.push(e);
  if (state.run) {
    const ok = e.outcome === "success" ? 1 : 0;
    showRun({ ...state.run, episodes_done: state.run.episodes_done + 1, successes: state.run.successes + ok });
  }
  redrawCurve();
  refreshMemory();
}

function onReward(r) {
  refreshMemory();
  if (r.source !== "trainer") return;
  state.lastReward = r;
  state.credited.add(`${r.tick}:${r.value}`);
  const rows_ = r.credits.map((c) => el("tr", {},
    el("td", { text: c.tick }), el("td", { text: `${c.stimulus} → ${c.behaviour}` }),
    el("td", { text: c.d_k }), el("td", { text: `${fmt(c.before, 3)} → ${fmt(c.after, 3)}` })));
  const sign = r.value > 0 ? "+" : "−";
  $("#reward-effect").replaceChildren(
    el("div", { class: "head" }, `${sign}${Math.abs(r.value)} at tick ${r.tick} (episode ${r.episode}) credited ${r.credited} STM record${r.credited === 1 ? "" : "s"}`),
    r.credits.length
      ? el("table", {}, el("thead", {}, el("tr", {}, el("th", { text: "tick" }), el("th", { text: "S → R" }), el("th", { text: "d_k" }), el("th", { text: "reliability" }))), el("tbody", {}, rows_))
      : el("p", { class: "muted", text: "Nothing in STM to credit (the robot had just started, or this condition does not learn)." }));
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

/** What the store holds of the run: its episodes and its reliabilities. */
function loadStored() {
  return Promise.all([loadEpisodes(), loadMemory()]);
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
  state.episodes = list.data;
  drawCurve();
}

function drawCurve() {
  learningCurve($("#curve"), state.episodes);
}

const redrawCurve = throttle(drawCurve, 250);

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

async function reward(value) {
  const run = state.run;
  if (!run) return;
  const button = value > 0 ? $("#reward-plus") : $("#reward-minus");
  button.classList.add("pressed");
  setTimeout(() => button.classList.remove("pressed"), 150);
  if (run.status !== "running") {
    toast(`Run ${run.id} is ${run.status}: rewards go to a running run.`, "error");
    return;
  }
  const ack = await attempt(() => post(`/runs/${run.id}/rewards`, { value }), "Reward");
  if (!ack) return;
  // The stream may have shown its credit before the acknowledgement came back.
  if (state.credited.has(`${ack.tick}:${ack.value}`)) return;
  $("#reward-effect").replaceChildren(el("div", { class: "head" },
    `${value > 0 ? "+" : "−"}1 logged as reward #${ack.id} at tick ${ack.tick} (episode ${ack.episode}); crediting…`));
}

function onKey(event) {
  if (!state.active || typing(event) || event.ctrlKey || event.metaKey || event.altKey) return;
  if (event.key === "+" || event.key === "=") {
    event.preventDefault();
    reward(1);
  } else if (event.key === "-" || event.key === "_") {
    event.preventDefault();
    reward(-1);
  } else if (event.key === "P" && event.shiftKey && state.run) {
    event.preventDefault();
    if (state.run.status === "running") control("pause");
    else if (state.run.status === "paused") control("resume");
  }
}

async function onCreate(event) {
  event.preventDefault();
  const form = event.target;
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
  const run = await attempt(() => post("/runs", body), "Creating the run");
  if (!run) return; // the form stays open with what was typed
  form.closest("details").open = false;
  let started = null;
  if (form.start.checked) started = await attempt(() => post(`/runs/${run.id}/start`), `Starting run ${run.id}`);
  toast(`Run ${run.id} created${started ? " and started" : ""}.`, "ok");
  location.hash = `#/console/${run.id}`;
}
