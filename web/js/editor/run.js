// "Run this network": fast runs of the open network, one per seed, started through the
// runs API (so they are ordinary runs, in the console too), with their success rate,
// failure causes and learning curve beside the matrix; "compare with" runs another version
// or network on the same seeds and shows the paired difference with its CI, computed by
// the server (GET /api/comparisons, core.lab.stats).

import { get, post, ApiError } from "../api.js";
import { $, el, svg, toast } from "../ui.js";
import { Condition, Outcome, RunMode, RunStatus } from "../generated/enums.js";

const POLL_MS = 700;
const ENDED = new Set([RunStatus.finished, RunStatus.stopped, RunStatus.failed, RunStatus.interrupted]);
const INK = { a: "#245fd6", b: "#b35c00" };

const state = {
  current: () => null,
  conditions: [],
  batch: null, // {id, sides: [{key, label, runs: [{id, seed, status, episodes: []}]}], timer}
  serial: 0,
};

/** Set up the panel; `current()` is the network the editor shows. */
export async function init(catalog, current) {
  state.current = current;
  const form = $("#run-net-form");
  form.addEventListener("submit", onStart);
  $("#run-net-stop").addEventListener("click", onStop);
  form.condition.addEventListener("change", describeCondition);
  try {
    state.conditions = await get("/conditions");
  } catch {
    state.conditions = [];
  }
  form.condition.replaceChildren(...state.conditions.map((c) => el("option", { value: c.name, text: c.name })));
  form.condition.value = state.conditions.some((c) => c.name === Condition.dp) ? Condition.dp : (state.conditions[0] || {}).name || "";
  describeCondition();
}

function describeCondition() {
  const form = $("#run-net-form");
  const c = state.conditions.find((x) => x.name === form.condition.value);
  $("#run-net-condition").textContent = c
    ? `${c.description}${c.learning ? "" : " It does not learn."}${c.trainer ? ` A reward program (${c.trainer}) rewards it too.` : ""} This network replaces the condition's own (${c.network}).`
    : "";
}

/** The editor opened or saved a network: offer its versions and the other networks. */
export async function networkChanged(net) {
  const select = $("#run-net-form").compare;
  const chosen = select.value;
  let networks = [];
  try {
    networks = (await get("/networks")).data;
  } catch {
    return;
  }
  const versions = [];
  for (let v = net.version - 1; v >= 1 && versions.length < 30; v--) versions.push(v);
  select.replaceChildren(
    el("option", { value: "", text: "nothing (this network alone)" }),
    versions.length ? el("optgroup", { label: `${net.name}, an earlier version` },
      versions.map((v) => el("option", { value: `v:${v}`, text: `${net.name} v${v}` }))) : null,
    el("optgroup", { label: "another network (its current version)" },
      networks.filter((n) => n.name !== net.name).map((n) => el("option", { value: `n:${n.name}`, text: n.name }))),
  );
  select.value = [...select.options].some((o) => o.value === chosen) ? chosen : "";
}

async function onStart(event) {
  event.preventDefault();
  const net = state.current();
  if (!net) return;
  const form = event.target;
  const episodes = Number(form.episodes.value);
  const seeds = Number(form.seeds.value);
  if (!(Number.isInteger(episodes) && episodes >= 1 && episodes <= 1000)) {
    toast("Episodes: a whole number from 1 to 1000.", "error");
    return;
  }
  if (!(Number.isInteger(seeds) && seeds >= 1 && seeds <= 8)) {
    toast("Seeds: a whole number from 1 to 8 (one run per seed).", "error");
    return;
  }
  await onStop();
  const condition = form.condition.value;
  const sides = [{ key: "a", label: `${net.name} v${net.version}`, network: net.name, network_version: net.builtin ? undefined : net.version }];
  const other = form.compare.value;
  if (other.startsWith("v:")) {
    const v = Number(other.slice(2));
    sides.push({ key: "b", label: `${net.name} v${v}`, network: net.name, network_version: v });
  } else if (other.startsWith("n:")) {
    sides.push({ key: "b", label: other.slice(2), network: other.slice(2) });
  }
  const batch = { id: ++state.serial, condition, episodes, sides: [], timer: null, note: "" };
  state.batch = batch;
  setBusy(true);
  render();
  try {
    for (const side of sides) {
      const runs = [];
      for (let seed = 0; seed < seeds; seed++) {
        const body = { condition, mode: RunMode.fast, episodes, seed, network: side.network };
        if (side.network_version) body.network_version = side.network_version;
        const run = await post("/runs", body);
        runs.push({ id: run.id, seed, status: run.status, episodes: [], count: 0 });
      }
      batch.sides.push({ ...side, runs });
    }
  } catch (error) {
    toast(`Creating the runs: ${error.message}`, "error");
    batch.note = `Not started: ${error.message}`;
    state.batch = batch.sides.length ? batch : null;
    setBusy(false);
    render();
    return;
  }
  poll(batch);
}

async function onStop() {
  const batch = state.batch;
  if (!batch) return;
  clearTimeout(batch.timer);
  batch.stopped = true;
  const live = batch.sides.flatMap((s) => s.runs).filter((r) => r.status === RunStatus.running || r.status === RunStatus.paused);
  await Promise.all(live.map((r) => post(`/runs/${r.id}/stop`).catch(() => null)));
  setBusy(false);
}

function setBusy(busy) {
  $("#run-net-start").disabled = busy;
  $("#run-net-stop").disabled = !busy;
}

/** Start what waits for a slot, read what is new, ask for the comparison; again until done. */
async function poll(batch) {
  if (batch !== state.batch || batch.stopped) return;
  const runs = batch.sides.flatMap((s) => s.runs);
  let waiting = 0;
  try {
    const created = runs.filter((r) => r.status === RunStatus.created);
    // After a refusal (SRLAB_MAX_RUNS, or the write rate) wait a while before asking again.
    if (created.length && Date.now() >= (batch.retryAt || 0)) {
      for (const r of created) {
        try {
          const started = await post(`/runs/${r.id}/start`);
          r.status = started.status;
        } catch (error) {
          if (!(error instanceof ApiError && error.status === 429)) throw error;
          batch.retryAt = Date.now() + 3000;
          break;
        }
      }
    }
    waiting = runs.filter((r) => r.status === RunStatus.created).length;
    batch.note = waiting
      ? `${waiting} run${waiting > 1 ? "s" : ""} waiting for a free run slot (the service runs at most SRLAB_MAX_RUNS at once); they start as others end.`
      : "";
    await Promise.all(runs.filter((r) => r.status !== RunStatus.created).map(async (r) => {
      if (ENDED.has(r.status) && r.count >= batch.episodes) return;
      const run = await get(`/runs/${r.id}`);
      r.status = run.status;
      r.error = run.error;
      if (run.episodes_done > r.episodes.length) {
        const page = await get(`/runs/${r.id}/episodes`, { offset: r.episodes.length, limit: 1000 });
        r.episodes.push(...page.data);
      }
      r.count = r.episodes.length;
    }));
    const query = new URLSearchParams();
    for (const s of batch.sides) for (const r of s.runs) query.append(s.key, String(r.id));
    batch.stats = await get(`/comparisons?${query}`);
  } catch (error) {
    batch.note = `Reading the runs: ${error.message}`;
  }
  if (batch !== state.batch) return;
  render();
  if (runs.every((r) => ENDED.has(r.status)) && batch.stats && batch.stats.complete) {
    setBusy(false);
    $("#run-net-out").dataset.state = "done";
    return;
  }
  batch.timer = setTimeout(() => poll(batch), POLL_MS);
}

const pct = (x) => (x === null || x === undefined ? "—" : `${Math.round(100 * x)}%`);
const pts = (x) => `${x >= 0 ? "+" : "−"}${Math.abs(Math.round(100 * x))}`;

function interval(e, diff = false) {
  if (!e || e.mean === null) return "—";
  const mean = diff ? `${pts(e.mean)} points` : pct(e.mean);
  if (e.low === null) return mean;
  return diff ? `${mean} [${pts(e.low)}, ${pts(e.high)}]` : `${mean} [${pct(e.low)}, ${pct(e.high)}]`;
}

function render() {
  const out = $("#run-net-out");
  const batch = state.batch;
  out.dataset.state = batch ? "running" : "";
  if (!batch) {
    out.replaceChildren(el("p", { class: "muted small", text: "No run yet: pick a condition and Run." }));
    return;
  }
  const stats = batch.stats;
  const parts = [];
  if (batch.note) parts.push(el("p", { class: "note small", text: batch.note }));
  for (const side of batch.sides) {
    const done = side.runs.reduce((n, r) => n + r.count, 0);
    const total = side.runs.length * batch.episodes;
    const failed = side.runs.filter((r) => r.status === RunStatus.failed);
    const e = stats && stats[side.key];
    parts.push(el("div", { class: `run-side side-${side.key}`, dataset: { side: side.key } },
      el("div", { class: "run-side-head" },
        el("span", { class: "swatch", style: `background:${INK[side.key]}` }),
        el("b", { text: side.label }),
        el("span", { class: "muted small", text: ` · runs ${side.runs.map((r) => r.id).join(", ")} · ${done}/${total} episodes` })),
      el("div", { class: "rate" },
        el("span", { class: "big", dataset: { rate: e && e.mean !== null ? String(e.mean) : "" }, text: e ? pct(e.mean) : "—" }),
        el("span", { class: "muted small", text: e && e.mean !== null
          ? ` success over ${stats.episodes} episode${stats.episodes > 1 ? "s" : ""} × ${e.n} seed${e.n > 1 ? "s" : ""}${e.low !== null ? `, 95% CI ${pct(e.low)}–${pct(e.high)}` : " (one seed: no interval)"}`
          : " success: no episode yet" })),
      causes(side),
      failed.length ? el("p", { class: "bad small", text: `Run ${failed[0].id} failed: ${failed[0].error || "see the console"}` }) : null));
  }
  if (stats && stats.diff) {
    const d = stats.diff;
    const [a, b] = batch.sides;
    parts.push(el("div", { class: "run-diff" },
      el("b", { text: `${a.label} − ${b.label}: ` }),
      el("span", { class: "diff-value", text: interval(d, true) }),
      el("span", { class: "muted small", text: d.mean === null ? " (no episode yet)"
        : d.low === null ? " a plain difference: one seed gives no interval, run 2 or more to get one"
          : ` paired by seed (95% Student-t CI), sign-flip p = ${stats.p === null ? "—" : stats.p.toFixed(2)}${stats.complete ? "" : "; so far"}${floorNote(d.n)}` })));
  }
  parts.push(curve(batch));
  if (batch.sides.length) parts.push(commandLine(batch));
  out.replaceChildren(...parts);
}

/** The same runs of the network as it is now, from the command line (docs/conditions.md). */
function commandLine(batch) {
  const [a] = batch.sides;
  const seeds = a.runs.length;
  const cmd = `srlab simulate --condition ${batch.condition} --network ${a.network} --episodes ${batch.episodes} --seed 0`;
  return el("p", { class: "muted small run-cli" },
    "The same from the command line: ", el("code", { text: cmd }),
    seeds > 1 ? ` (and --seed 1${seeds > 2 ? ` to ${seeds - 1}` : ""} for the other runs)` : "",
    a.network_version ? "; it runs the network as stored now, its latest version." : ".");
}

/**
 * With n seeds the two-sided sign-flip test's p is at least 2 / 2^n (every seed's
 * difference with the same sign): said when that floor keeps p above 0.05.
 */
function floorNote(n) {
  if (!n) return "";
  const floor = 2 / 2 ** n;
  return floor > 0.05 ? `; with ${n} seed${n > 1 ? "s" : ""} p cannot go below ${floor.toFixed(n > 3 ? 3 : 2)}: run ${Math.ceil(Math.log2(2 / 0.05))} or more to test at 5%` : "";
}

function causes(side) {
  const counts = new Map();
  for (const r of side.runs) {
    for (const e of r.episodes) {
      if (e.outcome !== Outcome.success) counts.set(e.cause || e.outcome, (counts.get(e.cause || e.outcome) || 0) + 1);
    }
  }
  if (!counts.size) return el("p", { class: "muted small causes", text: "No failures yet." });
  const sorted = [...counts.entries()].sort((x, y) => y[1] - x[1]);
  return el("table", { class: "causes" },
    el("caption", { class: "muted small", text: "failures by cause" }),
    sorted.map(([cause, n]) => el("tr", {}, el("td", { text: cause.replaceAll("_", " ") }), el("td", { class: "n", text: String(n) }))));
}

/** Success per episode number, as the share of seeds that succeeded, smoothed over 5. */
function curve(batch) {
  const width = 260;
  const height = 120;
  const pad = { l: 30, r: 6, t: 8, b: 18 };
  const n = batch.episodes;
  const x = (i) => pad.l + (n === 1 ? 0.5 : i / (n - 1)) * (width - pad.l - pad.r);
  const y = (v) => pad.t + (1 - v) * (height - pad.t - pad.b);
  const root = svg("svg", { viewBox: `0 0 ${width} ${height}`, role: "img", "aria-label": "Learning curve of the runs", class: "run-curve" });
  for (const v of [0, 0.5, 1]) {
    root.append(svg("line", { x1: pad.l, x2: width - pad.r, y1: y(v), y2: y(v), stroke: "#e3e6eb" }));
    root.append(svg("text", { x: pad.l - 4, y: y(v) + 4, "text-anchor": "end", "font-size": 10, fill: "#5d6675" }, `${v * 100}%`));
  }
  root.append(svg("text", { x: pad.l, y: height - 4, "font-size": 10, fill: "#5d6675" }, "episode 1"));
  root.append(svg("text", { x: width - pad.r, y: height - 4, "text-anchor": "end", "font-size": 10, fill: "#5d6675" }, String(n)));
  for (const side of batch.sides) {
    const rates = [];
    for (let i = 0; i < n; i++) {
      const seen = side.runs.map((r) => r.episodes[i]).filter(Boolean);
      if (!seen.length) break;
      rates.push(seen.filter((e) => e.outcome === Outcome.success).length / seen.length);
    }
    const points = rates.map((_, i) => {
      const from = Math.max(0, i - 4);
      const win = rates.slice(from, i + 1);
      return `${x(i).toFixed(1)},${y(win.reduce((a, b) => a + b, 0) / win.length).toFixed(1)}`;
    });
    if (points.length === 1) points.push(points[0]);
    root.append(svg("polyline", { points: points.join(" "), fill: "none", stroke: INK[side.key], "stroke-width": 2, class: `line-${side.key}`, "data-points": rates.length }));
  }
  const box = el("figure", { class: "run-curve-box" });
  box.append(root, el("figcaption", { class: "muted small", text: "success per episode, share of seeds, mean of the last 5" }));
  return box;
}

