// The reward log read and drawn: every source on a timeline, and the trainers' own
// rewards in a list.

import { get } from "../api.js";
import { $, attempt, el, svg, throttle } from "../ui.js";
import { KEEP_REWARDS, addReward, mine, undoOf, undoable } from "./rewards.js";
import { state } from "./state.js";
import { RewardSource, RunStatus } from "../generated/enums.js";

const TIMELINE_TICKS = 2000;
const SOURCES = Object.values(RewardSource); // one lane each, in this order

/** The newest `KEEP_REWARDS` of the run's reward log. */
export async function loadRewards() {
  const run = state.run;
  if (!run) return;
  const head = await attempt(() => get(`/runs/${run.id}/rewards`, { limit: 1 }));
  if (!head || !state.run || state.run.id !== run.id) return;
  state.logCount = Math.max(state.logCount, head.count - KEEP_REWARDS);
  await syncRewards();
}

/** The reward log from what was read of it on (the log only grows). */
export async function syncRewards() {
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

export function drawRewards() {
  drawTimeline();
  drawMine();
  if (state.run) $("#reward-undo").disabled = state.run.status !== RunStatus.running || !undoable();
}

export const redrawRewards = throttle(drawRewards, 300);

/** Every reward of the last `TIMELINE_TICKS` ticks, one lane per source, up good, down bad. */
export function drawTimeline() {
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
  const root = svg("svg", { viewBox: `0 0 ${width} ${height}`, role: "img", "aria-label": "Rewards by tick and source" });
  SOURCES.forEach((src, i) => {
    const mid = pad.t + lane * i + lane / 2;
    root.append(svg("line", { x1: pad.l, x2: width - pad.r, y1: mid, y2: mid, stroke: "#e3e6eb" }));
    root.append(svg("text", { x: pad.l - 8, y: mid + 4, "text-anchor": "end", "font-size": 11, fill: "#5d6675" }, src));
  });
  root.append(svg("text", { x: width - pad.r, y: height - 1, "text-anchor": "end", "font-size": 10, fill: "#5d6675" }, `ticks ${from}–${now}`));
  const marks = svg("g", { class: "marks" });
  for (const r of state.rewards) {
    if (r.tick < from) continue;
    const i = Math.max(0, SOURCES.indexOf(r.source));
    const mid = pad.t + lane * i + lane / 2;
    const h = Math.max(2, Math.abs(r.value) * (lane / 2 - 3));
    const mark = svg("rect", {
      x: x(r.tick) - 1.5, width: 3, y: r.value >= 0 ? mid - h : mid, height: h,
      fill: r.value >= 0 ? "#17803d" : "#c0262d", class: `mark ${r.source}`,
      "data-source": r.source, "data-value": r.value,
    });
    mark.append(svg("title", {}, `${r.id !== undefined ? `#${r.id} ` : ""}${r.source} ${r.value > 0 ? "+" : ""}${r.value} at tick ${r.tick}${r.note ? `: ${r.note}` : ""}${r.credited !== undefined ? ` · credited ${r.credited}` : ""}`));
    marks.append(mark);
  }
  root.append(marks);
  box.replaceChildren(root);
}

/** The trainers' rewards, newest first, with their notes; this browser's marked "you". */
/** What a reward credited: "credited 6 records, ticks 480–486" (the ticks when known). */
function credit(r) {
  const records = `credited ${r.credited} record${r.credited === 1 ? "" : "s"}`;
  if (r.span && r.credited) return `${records}, ticks ${r.span[0]}–${r.span[1]}`;
  if (r.window) return `${records} in ticks ${r.window[0]}–${r.window[1]} (seen at ${r.tick_seen})`;
  return records;
}

function drawMine() {
  const ids = mine();
  const undone = new Map(state.rewards.filter((r) => undoOf(r) !== null).map((r) => [undoOf(r), r]));
  const items = state.rewards.filter((r) => r.source === RewardSource.trainer).slice(-100).reverse();
  $("#my-rewards").replaceChildren(...items.map((r) => {
    const by = undone.get(r.id);
    return el("li", { class: by ? "undone" : "", dataset: { id: r.id ?? "", uid: r.uid ?? "" } },
      el("span", { class: `v ${r.value >= 0 ? "pos" : "neg"}`, text: `${r.value > 0 ? "+" : r.value < 0 ? "−" : ""}${Math.abs(r.value)}` }),
      el("span", { class: "what" }, `${r.id !== undefined ? `#${r.id} · ` : ""}tick ${r.tick}`,
        r.note ? el("span", { class: "reward-note", text: ` · ${r.note}` }) : null,
        r.credited !== undefined ? el("span", { class: "muted credit", text: ` · ${credit(r)}` }) : null),
      by ? el("span", { class: "muted small", text: `undone by #${by.id}` }) : null,
      r.id !== undefined && ids.has(r.id) ? el("span", { class: "muted small", text: "you" }) : null);
  }));
}
