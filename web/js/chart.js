// The learning curve: each episode's outcome and the success rate of the last `window`.

const NS = "http://www.w3.org/2000/svg";

function svg(tag, attrs = {}, text) {
  const node = document.createElementNS(NS, tag);
  for (const [k, v] of Object.entries(attrs)) node.setAttribute(k, String(v));
  if (text !== undefined) node.textContent = text;
  return node;
}

/** Draw `episodes` ([{episode, outcome}], in order) into `container` as an SVG. */
export function learningCurve(container, episodes, { window = 10 } = {}) {
  if (!episodes.length) {
    const empty = document.createElement("p");
    empty.className = "empty";
    empty.textContent = "No episodes yet.";
    container.replaceChildren(empty);
    return;
  }
  const width = Math.max(600, container.clientWidth || 1200);
  const height = 190;
  const pad = { l: 40, r: 14, t: 10, b: 28 };
  const n = episodes.length;
  const x = (i) => pad.l + (n === 1 ? 0.5 : i / (n - 1)) * (width - pad.l - pad.r);
  const y = (v) => pad.t + (1 - v) * (height - pad.t - pad.b);
  const root = svg("svg", { viewBox: `0 0 ${width} ${height}`, role: "img", "aria-label": "Learning curve" });
  for (const v of [0, 0.5, 1]) {
    root.append(svg("line", { x1: pad.l, x2: width - pad.r, y1: y(v), y2: y(v), stroke: "#e3e6eb" }));
    root.append(svg("text", { x: pad.l - 6, y: y(v) + 4, "text-anchor": "end", "font-size": 11, fill: "#5d6675" }, `${v * 100}%`));
  }
  const step = Math.max(1, Math.ceil(n / 10));
  for (let i = 0; i < n; i += step) {
    root.append(svg("text", { x: x(i), y: height - 8, "text-anchor": "middle", "font-size": 11, fill: "#5d6675" }, episodes[i].episode));
  }
  const dots = svg("g", { class: "dots" });
  const r = n > 300 ? 1.5 : 3;
  episodes.forEach((e, i) => {
    const ok = e.outcome === "success";
    dots.append(svg("circle", {
      cx: x(i), cy: y(ok ? 1 : 0) + (ok ? 6 : -6), r,
      fill: ok ? "#17803d" : "#c0262d", opacity: 0.55,
    }, undefined));
  });
  root.append(dots);
  let wins = 0;
  const points = episodes.map((e, i) => {
    wins += e.outcome === "success" ? 1 : 0;
    if (i >= window) wins -= episodes[i - window].outcome === "success" ? 1 : 0;
    const rate = wins / Math.min(i + 1, window);
    return `${x(i).toFixed(1)},${y(rate).toFixed(1)}`;
  });
  root.append(svg("polyline", { points: points.join(" "), fill: "none", stroke: "#245fd6", "stroke-width": 2.5, class: "rate" }));
  const total = episodes.filter((e) => e.outcome === "success").length;
  root.append(svg("text", { x: width - pad.r, y: pad.t + 12, "text-anchor": "end", "font-size": 12, fill: "#1b1f27" },
    `${total}/${n} successes · last ${Math.min(window, n)}: ${Math.round((wins / Math.min(window, n)) * 100)}%`));
  container.replaceChildren(root);
}
