// The KP inspector (console): what the run's RSTM holds now and how each association
// knowledge propagation made came to be (GET /api/runs/{id}/kp).
//
// Self-contained on purpose: it reads the console's run from the URL (#/console/{id}) or
// the run dropdown, and polls while the console is shown, so console.js needs no hook.

import { ApiError, get } from "./api.js";
import { $, el, fmt, svg } from "./ui.js";
import { KpResolution } from "./generated/enums.js";

const POLL_MS = 1000;
const SHOWN_RUNS = 8;
let busy = false;
/** The run whose associations the panel shows (their open blocks stay open across refreshes). */
let shownRun = null;

function runId() {
  const m = location.hash.match(/^#\/console\/(\d+)/);
  if (m) return Number(m[1]);
  const select = $("#run-select");
  const v = select ? Number(select.value) : NaN;
  return Number.isFinite(v) && v > 0 ? v : null;
}

function consoleShown() {
  const view = $("#view-console");
  return Boolean(view && !view.hidden);
}

const deg = (x) => `${x >= 0 ? "+" : "−"}${Math.abs(x).toFixed(1)}°`;

function table(head, rows) {
  return el("table", { class: "kp-table" },
    el("thead", {}, el("tr", {}, head.map((h) => el("th", { text: h })))),
    el("tbody", {}, rows.map((r) => el("tr", {}, r.map((c) => el("td", {}, c))))));
}

function rstmBlock(body) {
  const records = body.rstm.flatMap((r) => r.records.map((x) => ({ sensor: r.sensor, ...x })));
  const seen = body.percepts.map((p) =>
    el("li", {}, `${p.camera_stimulus} seen at tick ${p.tick} (${p.objective}): `,
      el("span", { class: p.open ? "good" : "muted", text: p.open ? `recording, window ${body.window_ticks} ticks` : "window closed" })));
  return el("div", { class: "kp-rstm", id: "kp-rstm" },
    el("h3", { text: `RSTM now (tick ${body.tick})` }),
    seen.length ? el("ul", { class: "kp-percepts" }, seen) : el("p", { class: "muted small", text: "No camera obstacle stimulus perceived in this episode yet." }),
    records.length
      ? table(["tick", "camera stimulus", "sonar stimulus", "response recorded"],
        records.map((r) => [String(r.tick), r.camera_stimulus, r.sonar_stimulus, r.behaviour]))
      : el("p", { class: "muted small", text: "Empty: nothing recorded since the last reward." }));
}

/**
 * The sources' unit headings laid head to tail (x ahead, y to the left), so the arrow from
 * the first tail to the last head is their vector sum; dashed, the primitive it snapped to.
 */
function vectors(p) {
  const w = 160, h = 120, pad = 8;
  const unit = (d) => [Math.cos((d * Math.PI) / 180), Math.sin((d * Math.PI) / 180)];
  const chain = [[0, 0]];
  for (const s of p.sources) {
    const [x, y] = chain[chain.length - 1];
    const [ux, uy] = unit(s.heading_deg);
    chain.push([x + ux, y + uy]);
  }
  const length = Math.hypot(p.sum_x, p.sum_y);
  const [nx, ny] = unit(p.nearest_heading_deg);
  const snap = [nx * length, ny * length];
  const points = [...chain, snap];
  const minX = Math.min(0, ...points.map((q) => q[0])), maxX = Math.max(0, ...points.map((q) => q[0]));
  const minY = Math.min(0, ...points.map((q) => q[1])), maxY = Math.max(0, ...points.map((q) => q[1]));
  const scale = Math.min((w - 2 * pad) / Math.max(maxX - minX, 1e-9), (h - 2 * pad) / Math.max(maxY - minY, 1e-9));
  const X = (x) => pad + (x - minX) * scale;
  const Y = (y) => h - pad - (y - minY) * scale;
  const root = svg("svg", {
    viewBox: `0 0 ${w} ${h}`, class: "kp-vectors", role: "img",
    "aria-label": `${p.sources.length} source headings summing to ${deg(p.heading_deg)}; snapped to ${p.nearest}`,
  });
  const line = ([x1, y1], [x2, y2], cls) => root.append(svg("line", { x1: X(x1), y1: Y(y1), x2: X(x2), y2: Y(y2), class: cls }));
  line([0, 0], snap, "snap");
  for (let i = 1; i < chain.length; i += 1) line(chain[i - 1], chain[i], "src");
  line([0, 0], [p.sum_x, p.sum_y], "sum");
  return root;
}

function history(points) {
  if (!points.length) return el("p", { class: "muted small", text: "No RLTM steps in this engine's life." });
  const w = 160, h = 40;
  const xs = points.map((_, i) => (points.length === 1 ? w / 2 : (i * (w - 4)) / (points.length - 1) + 2));
  const root = svg("svg", { viewBox: `0 0 ${w} ${h}`, class: "kp-history" });
  root.append(svg("polyline", { points: points.map((p, i) => `${xs[i]},${h - 2 - p.after * (h - 4)}`).join(" ") }));
  const last = points.slice(-6).map((p) =>
    `${fmt(p.before)}→${fmt(p.after)} (reward ${fmt(p.reward, 1)} after tick ${p.after_tick})`);
  return el("div", { class: "kp-hist" }, root, el("p", { class: "small", text: last.join("; ") }));
}

function provenanceBlock(p) {
  const made = {
    [KpResolution.snapped]: `snapped to the primitive ${p.nearest} (${deg(p.nearest_heading_deg)})`,
    [KpResolution.synthesized]: `synthesised ${p.behaviour} (nearest primitive ${p.nearest}, ${deg(p.nearest_heading_deg)})`,
    [KpResolution.reused]: `reused the synthesised ${p.behaviour} (nearest primitive ${p.nearest})`,
  }[p.resolution];
  return el("div", { class: "kp-prov" },
    table(["tick", "sonar stimulus", "source behaviour", "heading"],
      p.sources.map((s) => [String(s.tick), s.sonar_stimulus, s.behaviour, deg(s.heading_deg)])),
    el("div", { class: "kp-sum" }, vectors(p),
      el("p", {},
        `Vector sum (${fmt(p.sum_x)}, ${fmt(p.sum_y)}) heads ${deg(p.heading_deg)} at ${fmt(p.speed_mps)} m/s: `,
        el("strong", { class: "kp-made", text: made }),
        ` — reward after tick ${p.after_tick}.`)));
}

function associationBlock(a, live, open, threshold) {
  const key = `${a.stimulus} -> ${a.behaviour}`;
  const latest = a.provenance[a.provenance.length - 1];
  const runs = a.runs.slice(-SHOWN_RUNS).map((r) => (r.first_tick === r.last_tick ? `${r.first_tick}` : `${r.first_tick}–${r.last_tick}`));
  const details = el("details", { class: "kp-assoc", dataset: { pair: key }, open: open.has(key) },
    el("summary", {},
      el("strong", { text: `${a.stimulus} → ${a.behaviour}` }),
      ` RLTM ${fmt(a.reliability)}`,
      a.in_network
        ? el("span", { class: "badge kp-in", text: "in network", title: threshold === null || threshold === undefined ? undefined : `its RLTM reached the threshold ${fmt(threshold)}` })
        : el("span", { class: "badge muted", text: threshold === null || threshold === undefined ? "below threshold" : `below threshold ${fmt(threshold)}` }),
      latest ? ` · ${latest.resolution} · ${latest.sources.length} source(s)` : live ? " · made before this engine started" : "",
      a.ran_ticks ? ` · ran ${a.ran_ticks} ticks` : ""),
    latest ? provenanceBlock(latest) : el("p", { class: "muted small", text: live ? "Its provenance was kept by an earlier engine only." : "Its provenance is kept while the run runs (see above)." }),
    a.provenance.length > 1 ? el("p", { class: "muted small", text: `${a.reasoned} rewards reasoned it; the latest is shown.` }) : null,
    el("h4", { text: "RLTM history" }), history(a.history),
    el("h4", { text: "Ticks where it ran" }),
    el("p", { class: "small kp-runs", text: runs.length ? `${runs.join(", ")}${a.runs.length > SHOWN_RUNS ? ` (latest ${SHOWN_RUNS} of ${a.runs.length} runs)` : ""}` : "Not run yet." }));
  return details;
}

function render(id, body) {
  const box = $("#kp-body");
  // The blocks open now ("S -> B"), read from the page as it is: a click's "toggle" event
  // comes a task later, and never from a block this render replaces.
  const open = new Set(id === shownRun
    ? Array.from(box.querySelectorAll("details.kp-assoc[open]"), (d) => d.dataset.pair)
    : []);
  shownRun = id;
  const parts = [];
  if (body.reason) parts.push(el("p", { class: "muted small kp-reason", text: body.reason }));
  if (body.kp && body.live) parts.push(rstmBlock(body));
  if (body.kp) {
    parts.push(el("h3", { text: `Associations KP made (${body.count})` }));
    parts.push(body.associations.length
      ? el("div", { class: "kp-assocs" }, body.associations.map((a) => associationBlock(a, body.live, open, body.insert_threshold)))
      : el("p", { class: "muted small", text: "None yet: KP reasons when a reward arrives after sonar responses to a camera stimulus." }));
  }
  box.replaceChildren(...parts);
}

async function refresh() {
  const section = $("#kp-inspector");
  if (!section || busy || !consoleShown()) return;
  const id = runId();
  if (id === null) {
    section.hidden = true;
    return;
  }
  busy = true;
  try {
    const body = await get(`/runs/${id}/kp`);
    if (id !== runId()) return;
    section.hidden = false;
    $("#kp-run").textContent = `run ${id} · ${body.condition}${body.live ? " · live" : ""}`;
    render(id, body);
  } catch (error) {
    if (error instanceof ApiError && error.status !== 0) section.hidden = true;
  } finally {
    busy = false;
  }
}

function start() {
  const section = $("#kp-inspector");
  if (!section) return;
  section.replaceChildren(
    el("div", { class: "card-head" },
      el("h2", {}, "Knowledge propagation ", el("span", { class: "muted small", id: "kp-run" }))),
    el("div", { id: "kp-body", "aria-live": "off" }));
  window.addEventListener("hashchange", refresh);
  document.addEventListener("change", (e) => { if (e.target && e.target.id === "run-select") refresh(); });
  setInterval(refresh, POLL_MS);
  refresh();
}

if (document.readyState === "loading") document.addEventListener("DOMContentLoaded", start);
else start();

export { refresh };
