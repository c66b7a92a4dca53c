// The robot beside the buttons: a top-down 2D view of the console's run, drawn from the
// tick events the console already receives (pose, lamp, sonar readings, obstacle) over the
// run's fixed track (GET /api/runs/{id}/world), with the tick rate, pause/resume and a
// single-tick step beside it.
//
// It hooks into the console through two DOM events the console dispatches, so the console
// can change around it: `srlab:run` (detail: the run as GET /api/runs/{id} answers it, or
// null) and `srlab:tick` (detail: a tick event's data). It draws at most once per animation
// frame, only when a tick came, and keeps its own figures in `window.srlabView2d` (the
// bench reads the page's frame time there). Its card's place, beside the Train card, and
// its layout are style.css's (the "2D view" section).

import { get, post } from "./api.js";
import { $, attempt, el, fmt } from "./ui.js";
import { Lamp, RunMode, RunStatus } from "./generated/enums.js";

const MARGIN_PX = 12;
const LAMP = { [Lamp.red]: "#dc2626", [Lamp.yellow]: "#facc15", [Lamp.green]: "#16a34a", [Lamp.none]: "#6b7280" };
const FLOOR = "#b0b4ba";
const GROUND = "#f5f5f0"; // style.css paints the canvas the same, before its first frame
const WALL = "#475569";
const ROBOT = "#c41e24";
const OBSTACLE = "#b48048";
const STATS_KEPT = 600;

const view = {
  card: null,
  canvas: null,
  run: null,
  world: null,
  worldOf: null,
  tick: null,
  pending: false,
  arrived: 0,
  busy: false,
};

/** What the page measured, for the bench: ticks received, frames drawn, each frame's draw
 * time and the delay from its newest tick's arrival to the end of its drawing (ms). */
const stats = { ticks: 0, draws: 0, drawMs: [], delayMs: [] };
window.srlabView2d = stats;

function keep(list, value) {
  list.push(value);
  if (list.length > STATS_KEPT) list.shift();
}

function build() {
  const card = $("#view2d-card");
  if (!card || view.card) return;
  view.card = card;
  view.canvas = el("canvas", { id: "view2d", role: "img", "aria-label": "Top-down view of the run", width: 600, height: 400 });
  const rate = el("input", { id: "view2d-hz", type: "number", min: "0.5", max: "1000", step: "any", value: "10", "aria-label": "Tick rate (Hz)" });
  const form = el("form", { class: "view2d-rate", onsubmit: (e) => { e.preventDefault(); setRate(Number(rate.value)); } },
    el("label", {}, "Tick rate ", rate, " Hz"), el("button", { type: "submit", id: "view2d-rate-set", text: "Set" }));
  card.replaceChildren(
    el("div", { class: "card-head" }, el("h2", { text: "The robot" }), el("span", { id: "view2d-caption", class: "muted small", text: "Pick a run." })),
    el("div", { class: "view2d-body" },
      el("div", { class: "view2d-canvas" }, view.canvas),
      el("div", { class: "view2d-controls" },
        el("button", { type: "button", id: "view2d-toggle", text: "❚❚ Pause", onclick: toggle }),
        el("button", { type: "button", id: "view2d-step", text: "Step one tick", title: "Run exactly one tick of the paused run", onclick: step }),
        form,
        el("p", { class: "muted small", text: "Rays: the sonars' readings, red when close. The lamp shows its colour; the brown squares are the obstacles, where each is at that tick." }))));
  new ResizeObserver(() => schedule()).observe(view.canvas);
  controls();
}

// --- what the console tells us ----------------------------------------------------------

async function onRun(run) {
  build();
  if (!view.card) return;
  const changed = (run ? run.id : null) !== (view.run ? view.run.id : null);
  view.run = run;
  if (changed) {
    view.tick = null;
    view.world = null;
    view.worldOf = null;
  }
  if (run && view.worldOf !== run.id) {
    view.worldOf = run.id;
    const world = await attempt(() => get(`/runs/${run.id}/world`), "Loading the track");
    if (view.run && view.run.id === run.id && world) view.world = world;
  }
  const hz = run && run.live ? run.live.hz : run ? run.hz : null;
  if (changed && hz) $("#view2d-hz").value = String(hz);
  controls();
  schedule();
}

function onTick(t) {
  if (!view.run) return;
  view.tick = t;
  stats.ticks += 1;
  if (!view.pending) view.arrived = performance.now(); // the oldest tick not drawn yet
  schedule();
}

function controls() {
  if (!view.card) return;
  const run = view.run;
  const live = Boolean(run) && (run.status === RunStatus.running || run.status === RunStatus.paused);
  const realtime = Boolean(run) && run.mode === RunMode.realtime;
  const toggle_ = $("#view2d-toggle");
  toggle_.disabled = view.busy || !live;
  toggle_.textContent = run && run.status === RunStatus.paused ? "▶ Resume" : "❚❚ Pause";
  $("#view2d-step").disabled = view.busy || !run || run.status !== RunStatus.paused || !realtime;
  $("#view2d-hz").disabled = !live || !realtime;
  $("#view2d-rate-set").disabled = !live || !realtime;
  const t = view.tick;
  $("#view2d-caption").textContent = !run
    ? "Pick a run."
    : t
      ? `run #${run.id} · episode ${t.episode} · tick ${t.tick} · lamp ${t.lamp}${run.status === RunStatus.paused ? " · paused" : ""}`
      : `run #${run.id} · ${run.status}: no tick seen yet`;
}

// --- the controls -----------------------------------------------------------------------

function announce(run) {
  // Tell the console too: it follows the run's status from its stream and its poll.
  document.dispatchEvent(new CustomEvent("srlab:run-changed", { detail: run }));
  onRun({ ...view.run, ...run });
}

async function toggle() {
  const run = view.run;
  if (!run) return;
  const action = run.status === RunStatus.paused ? "resume" : "pause";
  view.busy = true;
  controls();
  const updated = await attempt(() => post(`/runs/${run.id}/${action}`), `${action[0].toUpperCase()}${action.slice(1)} run ${run.id}`);
  view.busy = false;
  if (updated) announce(updated);
  else controls();
}

async function step() {
  const run = view.run;
  if (!run) return;
  view.busy = true;
  controls();
  const updated = await attempt(() => post(`/runs/${run.id}/step`), `Step run ${run.id}`);
  view.busy = false;
  if (updated) {
    view.card.dataset.stepped = String(updated.ticks);
    announce(updated);
  } else controls();
}

async function setRate(hz) {
  const run = view.run;
  if (!run || !Number.isFinite(hz)) return;
  const updated = await attempt(() => post(`/runs/${run.id}/rate`, { hz }), `Tick rate of run ${run.id}`);
  if (updated) announce(updated);
}

// --- drawing ----------------------------------------------------------------------------

function schedule() {
  if (view.pending || !view.canvas) return;
  view.pending = true;
  requestAnimationFrame(frame);
}

function frame() {
  view.pending = false;
  const started = performance.now();
  draw();
  controls();
  const done = performance.now();
  keep(stats.drawMs, done - started);
  if (view.tick && view.arrived) keep(stats.delayMs, done - view.arrived);
  view.arrived = 0;
  stats.draws += 1;
}

/** The canvas's transform: metres (y up) to CSS pixels, fitting the outer box (a corridor
 * track's: the bounding box of its walls). */
function fit(world, width) {
  const [x0, y0, x1, y1] = world.outer_box;
  const scale = (width - 2 * MARGIN_PX) / (x1 - x0);
  const height = Math.round((y1 - y0) * scale + 2 * MARGIN_PX);
  return { scale, height, px: (x) => MARGIN_PX + (x - x0) * scale, py: (y) => height - MARGIN_PX - (y - y0) * scale };
}

function draw() {
  drawTrack(view.canvas, view.world, view.tick);
}

/**
 * Draw `world` (GET /api/runs/{id}/world) on `canvas`, and the robot at `pose` if one is
 * given: `x`, `y`, `heading_rad` and `tick`, with the lamp's colour (`lamp`, a Lamp name),
 * the sonars' readings (`sonar_m`) and the obstacles (`obstacles`: every one's centre at
 * that tick; or `obstacle`, the first's) where known. The track is the ring's two boxes, or
 * a corridor track's floor and walls (`world.ring` false).
 * A tick event is such a pose, and so is a stored trace's row once its lamp is named (the
 * console's replay draws those). The canvas keeps what it drew in its data attributes
 * (tick, pose, pixels, walls, obstacles): tests read them back.
 */
export function drawTrack(canvas, world, pose) {
  const width = Math.max(200, Math.round(canvas.clientWidth || canvas.width));
  const ctx = canvas.getContext("2d");
  if (!world) {
    ctx.clearRect(0, 0, canvas.width, canvas.height);
    return;
  }
  const f = fit(world, width);
  const ratio = window.devicePixelRatio || 1;
  if (canvas.width !== Math.round(width * ratio) || canvas.height !== Math.round(f.height * ratio)) {
    canvas.width = Math.round(width * ratio);
    canvas.height = Math.round(f.height * ratio);
  }
  ctx.setTransform(ratio, 0, 0, ratio, 0, 0);
  ctx.fillStyle = GROUND;
  ctx.fillRect(0, 0, width, f.height);
  const rect = (box, fill, stroke) => {
    const [a, b, c, d] = box;
    const x = f.px(a);
    const y = f.py(d);
    const w = (c - a) * f.scale;
    const h = (d - b) * f.scale;
    if (fill) {
      ctx.fillStyle = fill;
      ctx.fillRect(x, y, w, h);
    }
    if (stroke) {
      ctx.strokeStyle = stroke;
      ctx.lineWidth = 3;
      ctx.strokeRect(x, y, w, h);
    }
  };
  if (world.ring) {
    rect(world.outer_box, FLOOR, WALL);
    rect(world.inner_box, GROUND, WALL);
  } else {
    corridor(ctx, f, world);
  }
  canvas.dataset.walls = String(world.ring ? 8 : world.walls.length);
  // The stop line, dark on the light floor (the 3D view's white one vanished on it).
  const [[sx0, sy0], [sx1, sy1]] = world.stopline;
  ctx.strokeStyle = "#111827";
  ctx.lineWidth = 4;
  ctx.beginPath();
  ctx.moveTo(f.px(sx0), f.py(sy0));
  ctx.lineTo(f.px(sx1), f.py(sy1));
  ctx.stroke();
  const t = pose;
  const [lx, ly] = world.lamp;
  ctx.fillStyle = LAMP[t ? t.lamp : Lamp.none] || LAMP[Lamp.none];
  ctx.strokeStyle = "#111827";
  ctx.lineWidth = 2;
  ctx.beginPath();
  ctx.arc(f.px(lx), f.py(ly), 7, 0, 2 * Math.PI);
  ctx.fill();
  ctx.stroke();
  canvas.dataset.lamp = t ? t.lamp : "";
  if (!t) {
    delete canvas.dataset.tick;
    delete canvas.dataset.obstacles;
    return;
  }
  // Every obstacle where it is at this tick (a stored trace's row or a tick event says).
  const obstacles = t.obstacles && t.obstacles.length ? t.obstacles : t.obstacle ? [t.obstacle] : [];
  const half = world.obstacle_size_m / 2;
  for (const [ox, oy] of obstacles) rect([ox - half, oy - half, ox + half, oy + half], OBSTACLE, "#5b3a1a");
  canvas.dataset.obstacles = obstacles.map(([ox, oy]) => `${fmt(ox, 3)},${fmt(oy, 3)}`).join(" ");
  const cos = Math.cos(t.heading_rad);
  const sin = Math.sin(t.heading_rad);
  const toWorld = (rx, ry) => [t.x + rx * cos - ry * sin, t.y + rx * sin + ry * cos];
  // Sonar rays: from each sonar's mount along its axis, as long as it read.
  ctx.lineWidth = 1.5;
  world.sonars.forEach((s, i) => {
    const r = t.sonar_m && t.sonar_m[i] !== undefined ? t.sonar_m[i] : null;
    if (r === null) return;
    const [ax, ay] = toWorld(s.x_m, s.y_m);
    const [bx, by] = toWorld(s.x_m + r * Math.cos(s.angle_rad), s.y_m + r * Math.sin(s.angle_rad));
    ctx.strokeStyle = rayColor(r, world.sonar_range_m);
    ctx.beginPath();
    ctx.moveTo(f.px(ax), f.py(ay));
    ctx.lineTo(f.px(bx), f.py(by));
    ctx.stroke();
  });
  // The robot: its body, and a nose showing its heading.
  const hl = world.robot_length_m / 2;
  const hw = world.robot_width_m / 2;
  const corners = [[-hl, -hw], [hl - hw, -hw], [hl, 0], [hl - hw, hw], [-hl, hw]].map(([a, b]) => toWorld(a, b));
  ctx.fillStyle = ROBOT;
  ctx.strokeStyle = "#111827";
  ctx.lineWidth = 1.5;
  ctx.beginPath();
  corners.forEach(([a, b], k) => (k ? ctx.lineTo(f.px(a), f.py(b)) : ctx.moveTo(f.px(a), f.py(b))));
  ctx.closePath();
  ctx.fill();
  ctx.stroke();
  const [nx, ny] = toWorld(hl, 0);
  ctx.strokeStyle = "#fff";
  ctx.lineWidth = 2;
  ctx.beginPath();
  ctx.moveTo(f.px(t.x), f.py(t.y));
  ctx.lineTo(f.px(nx), f.py(ny));
  ctx.stroke();
  // Where the robot was drawn, in CSS pixels of the canvas: tests read it back.
  Object.assign(canvas.dataset, {
    tick: String(t.tick), x: fmt(t.x, 3), y: fmt(t.y, 3),
    px: fmt(f.px(t.x), 1), py: fmt(f.py(t.y), 1), heading: fmt(t.heading_rad, 3),
  });
}

/** A corridor track of any shape: its floor, a quadrilateral a segment, then its walls. */
function corridor(ctx, f, world) {
  // One path of all the quadrilaterals (all turn the same way), filled once: no seams.
  ctx.fillStyle = FLOOR;
  ctx.beginPath();
  for (const quad of world.floor) {
    quad.forEach(([x, y], k) => (k ? ctx.lineTo(f.px(x), f.py(y)) : ctx.moveTo(f.px(x), f.py(y))));
    ctx.closePath();
  }
  ctx.fill("nonzero");
  ctx.strokeStyle = WALL;
  ctx.lineWidth = 3;
  ctx.lineCap = "square";
  ctx.beginPath();
  for (const [x0, y0, x1, y1] of world.walls) {
    ctx.moveTo(f.px(x0), f.py(y0));
    ctx.lineTo(f.px(x1), f.py(y1));
  }
  ctx.stroke();
  ctx.lineCap = "butt";
  // The start: a dashed line across the corridor where each episode begins.
  const [x, y, th] = world.start_pose;
  const half = world.corridor_width_m / 2;
  const [nx, ny] = [-Math.sin(th) * half, Math.cos(th) * half];
  ctx.strokeStyle = "#f5f5f0";
  ctx.lineWidth = 2;
  ctx.setLineDash([5, 4]);
  ctx.beginPath();
  ctx.moveTo(f.px(x - nx), f.py(y - ny));
  ctx.lineTo(f.px(x + nx), f.py(y + ny));
  ctx.stroke();
  ctx.setLineDash([]);
}

function rayColor(range, max) {
  const u = Math.min(1, Math.max(0, (range / max) * 1.5));
  const mix = (a, b, k) => a.map((v, i) => Math.round(v + (b[i] - v) * k));
  const [r, g, b] = u < 0.5 ? mix([220, 38, 38], [250, 204, 21], u / 0.5) : mix([250, 204, 21], [22, 163, 74], (u - 0.5) / 0.5);
  return `rgb(${r},${g},${b})`;
}

document.addEventListener("srlab:run", (e) => onRun(e.detail));
document.addEventListener("srlab:tick", (e) => onTick(e.detail));
