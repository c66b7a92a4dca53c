// The stimulus x behaviour matrix: rows grouped by logical sensor, columns by behaviour
// family, as in the paper's Table III. The editor and the console's heatmap both draw it.

import { el } from "./ui.js";

export const key = (stimulus, behaviour) => `${stimulus}\u0000${behaviour}`;

/** Catalogue behaviours by family, then `extra` names (e.g. KP-made behaviours) as "new". */
export function columns(behaviours, extra = []) {
  const known = new Set(behaviours.map((b) => b.name));
  const cols = behaviours.map((b) => ({ name: b.name, family: b.family, made: false }));
  for (const name of extra) {
    if (!known.has(name)) {
      known.add(name);
      cols.push({ name, family: "kp-made", made: true });
    }
  }
  const order = [];
  for (const c of cols) if (!order.includes(c.family)) order.push(c.family);
  return order.flatMap((f) => cols.filter((c) => c.family === f));
}

/** Catalogue stimuli grouped by their logical sensor, in the sensors' order. */
export function rows(stimuli, sensors) {
  const groups = sensors.map((s) => ({
    sensor: s.name,
    level: s.level,
    stimuli: stimuli.filter((x) => x.sensor === s.name).map((x) => x.name),
  }));
  return groups.filter((g) => g.stimuli.length);
}

/**
 * Draw the matrix into `container`.
 *
 * `cell(stimulus, behaviour)` returns {text, bg, ink, source, locked, inNet, draft, title}
 * or null for an empty cell. Optional `rowTitle(stimulus)`, `colTitle(col)` and
 * `colSub(col)` explain the headers (a tooltip; a second, smaller line under the name).
 * Returns the table; cells carry data-s and data-b.
 */
export function render(container, { groups, cols, cell, selected, readonly = false, label, rowTitle, colTitle, colSub }) {
  const families = [];
  for (const c of cols) {
    const last = families[families.length - 1];
    if (last && last.family === c.family) last.span += 1;
    else families.push({ family: c.family, span: 1 });
  }
  const famStart = new Set();
  let prev = null;
  for (const c of cols) {
    if (c.family !== prev) famStart.add(c.name);
    prev = c.family;
  }
  const head = el("thead", {},
    el("tr", { class: "families" },
      el("th", { class: "corner", scope: "col" }, ""),
      families.map((f) => el("th", { colspan: f.span, class: "fam-start", scope: "colgroup", text: f.family }))),
    el("tr", { class: "names" },
      el("th", { class: "corner", scope: "col" }, el("span", { class: "muted small corner-text" }, "behaviour →", el("br"), "stimulus ↓")),
      cols.map((c) => el("th", {
        class: `b${famStart.has(c.name) ? " fam-start" : ""}${c.made ? " new-b" : ""}`,
        scope: "col",
        title: (colTitle && colTitle(c)) || (c.made ? `${c.name}: a behaviour KP made` : c.name),
      }, el("span", { text: c.name }, colSub && colSub(c) ? el("small", { class: "sub", text: colSub(c) }) : null)))));
  const body = el("tbody");
  for (const g of groups) {
    body.append(el("tr", { class: "group" },
      el("th", { scope: "rowgroup" }, g.sensor, " ", el("span", { class: "level", text: `(${g.level})` })),
      el("td", { colspan: cols.length })));
    for (const s of g.stimuli) {
      const tr = el("tr", {}, el("th", { scope: "row", text: s, title: (rowTitle && rowTitle(s)) || undefined }));
      for (const c of cols) {
        const v = cell(s, c.name);
        const isSel = selected && selected.s === s && selected.b === c.name;
        const td = el("td", {
          class: `c${famStart.has(c.name) ? " fam-start" : ""}${v && v.inNet ? " in-net" : ""}${v && v.draft ? ` ${v.draft}` : ""}`,
          role: "gridcell",
          tabindex: isSel ? 0 : -1,
          "aria-selected": isSel ? "true" : "false",
          title: v && v.title ? v.title : `${s} → ${c.name}: none`,
          dataset: { s, b: c.name },
        });
        if (v && v.empty) {
          td.dataset.present = "false";
          td.title = v.title || td.title;
        } else if (v) {
          if (v.bg) td.style.background = v.bg;
          if (v.ink) td.style.color = v.ink;
          if (v.text !== undefined && v.text !== "") td.append(el("span", { class: "v", text: v.text }));
          if (v.source) td.append(el("span", { class: `s src-${v.source}`, "aria-hidden": "true" }));
          if (v.locked) td.append(el("span", { class: "lock lock-icon", "aria-hidden": "true" }));
          td.dataset.source = v.source || "";
          td.dataset.locked = v.locked ? "true" : "false";
          td.dataset.present = "true";
        } else {
          td.dataset.present = "false";
        }
        tr.append(td);
      }
      body.append(tr);
    }
  }
  const table = el("table", {
    class: `matrix${readonly ? " readonly" : ""}`,
    role: "grid",
    "aria-label": label || "stimulus by behaviour",
  }, head, body);
  if (!selected) {
    const first = table.querySelector("td.c");
    if (first) first.tabIndex = 0;
  }
  const scroll = [container.scrollLeft, container.scrollTop];
  // A redraw keeps the focus where it was: a cell that had it gets it back at once, so a
  // redraw (a poll finding a change made elsewhere) is not the user leaving the cell.
  const focused = container.contains(document.activeElement) ? document.activeElement : null;
  const at = focused && focused.matches("td.c") ? focused.dataset : null;
  container.replaceChildren(table);
  [container.scrollLeft, container.scrollTop] = scroll;
  if (at) {
    const again = table.querySelector(`td.c[data-s="${CSS.escape(at.s)}"][data-b="${CSS.escape(at.b)}"]`);
    if (again) again.focus({ preventScroll: true });
  }
  return table;
}

/** The cell next to `td` in direction dx, dy (stays put at the edges). */
export function neighbour(td, dx, dy) {
  const tr = td.parentElement;
  if (dx) {
    const cells = [...tr.querySelectorAll("td.c")];
    const i = cells.indexOf(td) + dx;
    return cells[i] || td;
  }
  const index = [...tr.querySelectorAll("td.c")].indexOf(td);
  let row = tr;
  do {
    row = dy > 0 ? row.nextElementSibling : row.previousElementSibling;
  } while (row && row.classList.contains("group"));
  if (!row) return td;
  return row.querySelectorAll("td.c")[index] || td;
}
