// The learning curve: each episode's outcome and the success rate of the last `window`.

import { svg } from "./ui.js";
import { Outcome } from "./generated/enums.js";

/**
 * Draw `episodes` ([{episode, outcome}], any order) into `container` as an SVG, each at
 * its episode number: an episode not loaded yet leaves a gap, never shifts the others.
 * The line is the success rate of the last `window` episodes by number (those loaded).
 */
export function learningCurve(container, episodes, { window = 10 } = {}) {
  if (!episodes.length) {
    const empty = document.createElement("p");
    empty.className = "empty";
    empty.textContent = "No episodes yet.";
    container.replaceChildren(empty);
    return;
  }
  const sorted = [...episodes].sort((a, b) => a.episode - b.episode);
  const first = sorted[0].episode;
  const last = sorted[sorted.length - 1].episode;
  const span = last - first;
  const width = Math.max(600, container.clientWidth || 1200);
  const height = 190;
  const pad = { l: 40, r: 14, t: 10, b: 28 };
  const n = sorted.length;
  const x = (ep) => pad.l + (span === 0 ? 0.5 : (ep - first) / span) * (width - pad.l - pad.r);
  const y = (v) => pad.t + (1 - v) * (height - pad.t - pad.b);
  const root = svg("svg", { viewBox: `0 0 ${width} ${height}`, role: "img", "aria-label": "Learning curve" });
  for (const v of [0, 0.5, 1]) {
    root.append(svg("line", { x1: pad.l, x2: width - pad.r, y1: y(v), y2: y(v), stroke: "#e3e6eb" }));
    root.append(svg("text", { x: pad.l - 6, y: y(v) + 4, "text-anchor": "end", "font-size": 11, fill: "#5d6675" }, `${v * 100}%`));
  }
  const step = Math.max(1, Math.ceil((span + 1) / 10));
  for (let ep = first; ep <= last; ep += step) {
    root.append(svg("text", { x: x(ep), y: height - 8, "text-anchor": "middle", "font-size": 11, fill: "#5d6675", class: "tick-label" }, ep));
  }
  const dots = svg("g", { class: "dots" });
  const r = span > 300 ? 1.5 : 3;
  for (const e of sorted) {
    const ok = e.outcome === Outcome.success;
    const dot = svg("circle", {
      cx: x(e.episode), cy: y(ok ? 1 : 0) + (ok ? 6 : -6), r,
      fill: ok ? "#17803d" : "#c0262d", opacity: 0.55, "data-episode": e.episode,
    });
    dot.append(svg("title", {}, `episode ${e.episode}: ${e.outcome}${e.cause ? ` (${e.cause})` : ""}`));
    dots.append(dot);
  }
  root.append(dots);
  // The rate over the episodes numbered within the last `window` (gaps count as unknown).
  let wins = 0;
  let lo = 0;
  const points = sorted.map((e, i) => {
    wins += e.outcome === Outcome.success ? 1 : 0;
    while (sorted[lo].episode <= e.episode - window) {
      wins -= sorted[lo].outcome === Outcome.success ? 1 : 0;
      lo += 1;
    }
    const rate = wins / (i - lo + 1);
    return `${x(e.episode).toFixed(1)},${y(rate).toFixed(1)}`;
  });
  root.append(svg("polyline", { points: points.join(" "), fill: "none", stroke: "#245fd6", "stroke-width": 2.5, class: "rate" }));
  const total = sorted.filter((e) => e.outcome === Outcome.success).length;
  const recent = sorted.slice(lo);
  const recentWins = recent.filter((e) => e.outcome === Outcome.success).length;
  const missing = span + 1 - n;
  root.append(svg("text", { x: width - pad.r, y: pad.t + 12, "text-anchor": "end", "font-size": 12, fill: "#1b1f27", class: "summary" },
    `${total}/${n} successes · last ${recent.length}: ${Math.round((recentWins / recent.length) * 100)}%${missing > 0 ? ` · ${missing} not loaded yet` : ""}`));
  container.replaceChildren(root);
}
