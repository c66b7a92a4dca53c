// The S-R editor: a network's stimulus x behaviour matrix, edited by click or keyboard.
// Every save is a version on the server; undo and redo replay the inverse change as a new
// version, so the history always shows what happened.

import { api, del, get, post, put, seg, ApiError } from "./api.js";
import { key, columns, neighbour, render, rows } from "./matrix.js";
import { $, $$, attempt, el, fmt, throttle, toast, typing } from "./ui.js";

const SOURCE_INK = {
  innate: "#6b7a90", dp: "#245fd6", learned: "#17803d", kp: "#7b3fc4", expert: "#b35c00", designed: "#0f7f86",
};

const state = {
  catalog: null,
  networks: [],
  net: null,
  cells: new Map(),
  selected: null,
  undo: [],
  redo: [],
  pending: false,
  queue: Promise.resolve(),
  active: false,
};

const same = (a, b) =>
  (a === null && b === null) ||
  (a !== null && b !== null && a.strength === b.strength && a.source === b.source && a.locked === b.locked);

/** Set up the editor once the catalogue is known. */
export function init(catalog) {
  state.catalog = catalog;
  $("#new-network-form").addEventListener("submit", onCreate);
  $("#import-form").addEventListener("submit", onImport);
  $("#undo").addEventListener("click", undo);
  $("#redo").addEventListener("click", redo);
  $("#export").addEventListener("click", onExport);
  $("#delete-network").addEventListener("click", onDelete);
  $("#copy-builtin").addEventListener("click", () => {
    const form = $("#new-network-form");
    form.base.value = state.net.name;
    form.closest("details").open = true;
    form.name.focus();
  });
  $("#cell-form").addEventListener("submit", onSaveCell);
  $("#cell-remove").addEventListener("click", () => change(null));
  const form = $("#cell-form");
  form.strength_range.addEventListener("input", () => (form.strength.value = form.strength_range.value));
  form.strength.addEventListener("input", () => (form.strength_range.value = form.strength.value));
  $("#matrix").addEventListener("click", onCellClick);
  $("#matrix").addEventListener("dblclick", (e) => {
    if (e.target.closest("td.c")) toggle();
  });
  $("#matrix").addEventListener("keydown", onMatrixKey);
  $("#diff").addEventListener("click", onDiff);
  $("#revert").addEventListener("click", onRevert);
  $("#versions").addEventListener("change", updateHistoryButtons);
  document.addEventListener("keydown", (e) => {
    if (!state.active || typing(e)) return;
    const mod = e.ctrlKey || e.metaKey;
    if (mod && e.key.toLowerCase() === "z") {
      e.preventDefault();
      if (e.shiftKey) redo();
      else undo();
    } else if (mod && e.key.toLowerCase() === "y") {
      e.preventDefault();
      redo();
    }
  });
}

/** Show the editor for network `name` (or the first one). */
export async function show(name) {
  state.active = true;
  await loadList();
  const wanted = name || (state.net && state.net.name) || firstEditable();
  if (wanted) await open(wanted);
}

export function hide() {
  state.active = false;
}

/** After the service comes back: reload what is shown, keep what was typed. */
export async function reload() {
  if (!state.active) return;
  await loadList();
  if (state.net) await open(state.net.name, { keepSelection: true });
}

function firstEditable() {
  const own = state.networks.find((n) => !n.builtin);
  return (own || state.networks[0] || {}).name;
}

async function loadList() {
  const list = await attempt(() => get("/networks"), "Loading the networks");
  if (!list) return;
  state.networks = list.data;
  const ul = $("#network-list");
  ul.replaceChildren(...state.networks.map((n) => el("li", {},
    el("a", {
      href: `#/editor/${seg(n.name)}`,
      "aria-current": state.net && state.net.name === n.name ? "true" : "false",
      title: n.description || n.name,
    }, el("span", { text: n.name }), el("span", { class: "tag", text: n.builtin ? "built-in" : `v${n.version}` })))));
  const base = $("#new-network-form").base;
  const chosen = base.value || "innate";
  base.replaceChildren(el("option", { value: "", text: "(empty)" }),
    ...state.networks.map((n) => el("option", { value: n.name, text: n.name })));
  base.value = state.networks.some((n) => n.name === chosen) ? chosen : "";
  document.dispatchEvent(new CustomEvent("srlab:networks", { detail: state.networks }));
}

async function open(name, { keepSelection = false } = {}) {
  let net;
  try {
    net = await get(`/networks/${seg(name)}`);
  } catch (error) {
    toast(`Network ${name}: ${error.message}`, "error");
    return;
  }
  if (!state.net || state.net.name !== net.name) {
    state.undo = [];
    state.redo = [];
    if (!keepSelection) state.selected = null;
  }
  setNetwork(net);
  for (const a of $$("#network-list a")) {
    a.setAttribute("aria-current", a.getAttribute("href") === `#/editor/${seg(net.name)}` ? "true" : "false");
  }
  await loadVersions();
}

function setNetwork(net) {
  state.net = net;
  state.cells = new Map(net.associations.map((a) => [key(a.stimulus, a.behaviour), a]));
  $("#net-title").textContent = net.name;
  $("#net-meta").textContent = `${net.builtin ? "built-in · read-only" : `version ${net.version}`} · ${net.associations.length} associations${net.description ? ` · ${net.description}` : ""}`;
  $("#readonly-note").hidden = !net.builtin;
  $("#delete-network").disabled = net.builtin;
  for (const b of $$("#cell-form button, #cell-form input, #cell-form select")) b.disabled = net.builtin;
  draw();
  fillInspector();
  updateUndo();
}

function draw() {
  const { stimuli, behaviours, sensors } = state.catalog;
  const extra = state.net.associations.map((a) => a.behaviour);
  render($("#matrix"), {
    groups: rows(stimuli, sensors),
    cols: columns(behaviours, extra),
    selected: state.selected,
    readonly: state.net.builtin,
    label: `Network ${state.net.name}`,
    cell: (s, b) => {
      const a = state.cells.get(key(s, b));
      if (!a) return null;
      const t = 0.15 + 0.85 * a.strength;
      const ink = SOURCE_INK[a.source] || "#245fd6";
      return {
        text: fmt(a.strength, 1),
        bg: `color-mix(in srgb, ${ink} ${Math.round(t * 70)}%, white)`,
        ink: t > 0.6 ? "#fff" : "#1b1f27",
        source: a.source,
        locked: a.locked,
        title: `${s} → ${b}: strength ${fmt(a.strength)}, ${a.source}${a.locked ? ", locked" : ""}`,
      };
    },
  });
}

function selectedCell() {
  if (!state.selected) return null;
  return $(`#matrix td.c[data-s="${CSS.escape(state.selected.s)}"][data-b="${CSS.escape(state.selected.b)}"]`);
}

function select(s, b, { focus = true } = {}) {
  state.selected = { s, b };
  for (const td of $$("#matrix td.c[aria-selected=true]")) {
    td.setAttribute("aria-selected", "false");
    td.tabIndex = -1;
  }
  const td = selectedCell();
  if (td) {
    td.setAttribute("aria-selected", "true");
    td.tabIndex = 0;
    if (focus) td.focus({ preventScroll: false });
  }
  fillInspector();
}

function fillInspector() {
  const form = $("#cell-form");
  const sel = state.selected;
  if (!sel) {
    $("#cell-name").textContent = "Select a cell.";
    return;
  }
  const a = state.cells.get(key(sel.s, sel.b));
  $("#cell-name").textContent = `${sel.s} → ${sel.b}${a ? "" : " (none yet)"}`;
  form.strength.value = a ? a.strength : 1;
  form.strength_range.value = form.strength.value;
  form.source.value = a ? a.source : "dp";
  form.locked.checked = a ? a.locked : false;
  $("#cell-remove").disabled = !a || state.net.builtin;
  $("#cell-save").textContent = a ? "Save" : "Add";
}

function onCellClick(event) {
  const td = event.target.closest("td.c");
  if (td) select(td.dataset.s, td.dataset.b);
}

function onMatrixKey(event) {
  const td = event.target.closest("td.c");
  if (!td || event.ctrlKey || event.metaKey || event.altKey) return;
  const moves = { ArrowLeft: [-1, 0], ArrowRight: [1, 0], ArrowUp: [0, -1], ArrowDown: [0, 1] };
  const k = event.key;
  if (moves[k]) {
    event.preventDefault();
    const next = neighbour(td, ...moves[k]);
    select(next.dataset.s, next.dataset.b);
    return;
  }
  if (!state.selected) select(td.dataset.s, td.dataset.b, { focus: false });
  if (k === " " || k === "Spacebar") {
    event.preventDefault();
    toggle();
  } else if (k === "Delete" || k === "Backspace") {
    event.preventDefault();
    change((cur) => (cur ? null : undefined));
  } else if (/^[0-9]$/.test(k)) {
    event.preventDefault();
    const strength = k === "0" ? 1 : Number(k) / 10;
    change((cur) => ({ strength, source: cur ? cur.source : "dp", locked: cur ? cur.locked : false }));
  } else if (k === "l" || k === "L") {
    event.preventDefault();
    change((cur) => {
      if (cur) return { ...cur, locked: !cur.locked };
      toast("There is no association here to lock: add one first (Space).");
      return undefined;
    });
  } else if (k === "Enter") {
    event.preventDefault();
    $("#cell-form").strength.focus();
    $("#cell-form").strength.select();
  }
}

function toggle() {
  change((cur) => (cur ? null : { strength: 1, source: "dp", locked: false }));
}

const pick = (a) => ({ strength: a.strength, source: a.source, locked: a.locked });

function onSaveCell(event) {
  event.preventDefault();
  const form = event.target;
  const strength = Number(form.strength.value);
  if (!(strength >= 0 && strength <= 1)) {
    toast("The strength must be a number from 0 to 1.", "error");
    form.strength.focus();
    return;
  }
  change({ strength, source: form.source.value, locked: form.locked.checked }, { note: form.note.value });
}

/** Run `job` after every change queued before it: keystrokes are never dropped or reordered. */
function enqueue(job) {
  state.queue = state.queue.then(job, job);
  return state.queue;
}

/**
 * Change the selected cell to `next` (null removes it), as one saved version; `next` may be
 * a function of the cell as it is when the change's turn comes (undefined: no change).
 * A locked association only changes its lock: unlock it first, so a design is not lost to
 * a slip of the keyboard.
 */
function change(next, { note = "" } = {}) {
  const sel = state.selected;
  if (!sel || !state.net) return Promise.resolve();
  return enqueue(() => changeNow(sel, next, note));
}

async function changeNow(sel, next, note) {
  if (!state.net) return;
  const current = state.cells.has(key(sel.s, sel.b)) ? pick(state.cells.get(key(sel.s, sel.b))) : null;
  const after = typeof next === "function" ? next(current) : next;
  if (after === undefined) return;
  if (state.net.builtin) {
    toast(`${state.net.name} is built in and read-only: copy it to edit it.`, "error");
    return;
  }
  const before = current;
  if (same(before, after)) return;
  const unlockOnly = before && after && before.locked && !after.locked &&
    before.strength === after.strength && before.source === after.source;
  if (before && before.locked && !unlockOnly) {
    toast(`${sel.s} → ${sel.b} is locked: unlock it first (L, or untick "locked" and Save).`, "error");
    return;
  }
  const ok = await send(sel.s, sel.b, after, { force: Boolean(unlockOnly), note });
  if (ok) {
    state.undo.push({ s: sel.s, b: sel.b, before, after });
    state.redo = [];
    updateUndo();
    $("#cell-form").note.value = "";
  }
}

/** Write one cell; true when the server stored it. The page state follows the server. */
async function send(s, b, after, { force = false, note = "" } = {}) {
  state.pending = true;
  const name = state.net.name;
  const live = $("#live-edits").checked;
  // The version this change is based on: the server refuses it (412) if another tab or
  // editor saved meanwhile, instead of silently overwriting what they did.
  const based = state.net.version;
  const query = { force: force || undefined, live: live || undefined, note: note || undefined, expected_version: based };
  try {
    let version;
    if (after === null) {
      const response = await api("DELETE", `/networks/${seg(name)}/associations/${seg(s)}/${seg(b)}`, { query, raw: true });
      version = Number(response.headers.get("Srlab-Network-Version"));
      state.cells.delete(key(s, b));
    } else {
      const written = await put(`/networks/${seg(name)}/associations/${seg(s)}/${seg(b)}`, after, query);
      version = written.version;
      state.cells.set(key(s, b), pick(written));
      if (live && written.live_runs.length) toast(`Also applied to running run(s) ${written.live_runs.join(", ")}.`, "ok");
    }
    state.net = { ...state.net, version, associations: [...state.cells.entries()].map(([k, a]) => {
      const [stimulus, behaviour] = k.split("\u0000");
      return { stimulus, behaviour, ...a };
    }) };
    setNetwork(state.net);
    if (state.selected) select(state.selected.s, state.selected.b);
    refreshVersions();
    return true;
  } catch (error) {
    if (error instanceof ApiError && error.status === 412 && error.body) {
      state.pending = false;
      return await conflict(s, b, after, { force, note }, based, error.body.version);
    }
    const message = error instanceof ApiError && error.status === 409 && /lock/i.test(error.message)
      ? `${s} → ${b} is locked on the server: unlock it first.` : error.message;
    toast(`Saving ${s} → ${b}: ${message}`, "error");
    if (error instanceof ApiError && error.status !== 0) await open(name, { keepSelection: true });
    return false;
  } finally {
    state.pending = false;
  }
}

/** One line per association that changed between two versions (the diff's answer). */
function describeDiff(d) {
  const show = (a) => `${fmt(a.strength)} ${a.source}${a.locked ? " locked" : ""}`;
  return [
    ...d.added.map((a) => `+ ${a.stimulus} → ${a.behaviour} (${show(a)})`),
    ...d.removed.map((a) => `− ${a.stimulus} → ${a.behaviour}`),
    ...d.changed.map((c) => `~ ${c.stimulus} → ${c.behaviour}: ${show(c.before)} → ${show(c.after)}`),
  ];
}

/**
 * The network changed under a change of ours (412): show what the other writer did, show
 * the network as it is now, and reapply ours on top only if the user says so.
 */
async function conflict(s, b, after, options, based, current) {
  const name = state.net.name;
  const diff = await attempt(() => get(`/networks/${seg(name)}/diff`, { from: based, to: current }), "Comparing versions");
  await open(name, { keepSelection: true });
  const lines = diff ? describeDiff(diff) : [];
  const yours = after === null ? "remove it" : `set it to ${fmt(after.strength)} ${after.source}${after.locked ? " locked" : ""}`;
  const question = `${name} was saved elsewhere meanwhile (version ${based} → ${current}):\n` +
    `${lines.join("\n") || "(no association changed)"}\n\n` +
    `Reapply your change to ${s} → ${b} (${yours}) on top of version ${current}?`;
  if (!confirm(question)) {
    toast(`Your change to ${s} → ${b} was not saved: the editor shows version ${current}.`, "error");
    return false;
  }
  return send(s, b, after, options);
}

function undo() {
  return enqueue(async () => {
    const op = state.undo.pop();
    if (!op) return;
    state.selected = { s: op.s, b: op.b };
    if (await send(op.s, op.b, op.before, { force: true, note: "undo" })) state.redo.push(op);
    else state.undo.push(op);
    updateUndo();
  });
}

function redo() {
  return enqueue(async () => {
    const op = state.redo.pop();
    if (!op) return;
    state.selected = { s: op.s, b: op.b };
    if (await send(op.s, op.b, op.after, { force: true, note: "redo" })) state.undo.push(op);
    else state.redo.push(op);
    updateUndo();
  });
}

function updateUndo() {
  $("#undo").disabled = !state.undo.length;
  $("#redo").disabled = !state.redo.length;
  const last = state.undo[state.undo.length - 1];
  $("#undo").title = last ? `Undo ${last.s} → ${last.b} (Ctrl+Z)` : "Nothing to undo";
}

// --- history ---------------------------------------------------------------------------

const refreshVersions = throttle(() => Promise.all([loadVersions(), loadList()]), 300);

async function loadVersions() {
  if (!state.net) return;
  const list = await attempt(() => get(`/networks/${seg(state.net.name)}/versions`), "Loading the history");
  if (!list) return;
  const current = state.net.version;
  $("#versions").replaceChildren(...list.data.slice().reverse().map((v) => el("li", { class: v.version === current ? "current" : "" },
    el("label", {},
      el("input", { type: "checkbox", value: v.version, "aria-label": `version ${v.version}` }),
      el("span", {}, el("b", { text: `v${v.version}` }), " ",
        el("span", { class: "when", text: new Date(v.created_at).toLocaleString() }), " · ",
        `${v.association_count} assoc.`, v.note ? ` · ${v.note}` : "", v.version === current ? " · current" : "")))));
  $("#diff-out").replaceChildren();
  updateHistoryButtons();
}

function checkedVersions() {
  return $$("#versions input:checked").map((i) => Number(i.value)).sort((a, b) => a - b);
}

function updateHistoryButtons() {
  const picked = checkedVersions();
  $("#diff").disabled = !(picked.length === 2 || picked.length === 1);
  $("#revert").disabled = state.net.builtin || picked.length !== 1 || picked[0] === state.net.version;
  $("#revert").textContent = picked.length === 1 ? `Revert to v${picked[0]}` : "Revert to selected";
}

const line = (a) => `${a.stimulus} → ${a.behaviour} (${fmt(a.strength)}, ${a.source}${a.locked ? ", locked" : ""})`;

async function onDiff() {
  const picked = checkedVersions();
  const [from, to] = picked.length === 2 ? picked : [picked[0], state.net.version];
  const d = await attempt(() => get(`/networks/${seg(state.net.name)}/diff`, { from, to }), "Comparing versions");
  if (!d) return;
  const section = (title, cls, items) => items.length
    ? [el("div", { class: cls, text: `${title} (${items.length})` }), el("ul", {}, items.map((t) => el("li", { text: t })))] : [];
  const out = [
    el("div", { class: "head", text: `v${d.from_version} → v${d.to_version}` }),
    ...section("added", "added", d.added.map(line)),
    ...section("removed", "removed", d.removed.map(line)),
    ...section("changed", "changed", d.changed.map((c) => `${c.stimulus} → ${c.behaviour}: ${fmt(c.before.strength)}, ${c.before.source}${c.before.locked ? " (locked)" : ""} ⇒ ${fmt(c.after.strength)}, ${c.after.source}${c.after.locked ? " (locked)" : ""}`)),
  ];
  if (out.length === 1) out.push(el("p", { class: "muted", text: "No differences." }));
  $("#diff-out").replaceChildren(...out);
}

async function onRevert() {
  const [version] = checkedVersions();
  if (!confirm(`Make ${state.net.name} what it was at version ${version}? (A new version; the history is kept.)`)) return;
  const live = $("#live-edits").checked;
  const net = await attempt(() => post(`/networks/${seg(state.net.name)}/revert`, { version }, { force: true, live: live || undefined, note: `revert to v${version}`, expected_version: state.net.version }), "Reverting");
  if (!net) await open(state.net.name, { keepSelection: true }); // e.g. 412: show what is there now
  if (!net) return;
  state.undo = [];
  state.redo = [];
  setNetwork(net);
  await Promise.all([loadVersions(), loadList()]);
  toast(`Reverted to v${version}: now version ${net.version}.`, "ok");
}

// --- networks --------------------------------------------------------------------------

async function onCreate(event) {
  event.preventDefault();
  const form = event.target;
  const body = { name: form.name.value.trim(), base: form.base.value || null, description: form.description.value };
  const created = await attempt(() => post("/networks", body), `Creating ${body.name}`);
  if (!created) return; // the form keeps what was typed
  form.name.value = "";
  form.description.value = "";
  toast(`Created ${created.name}.`, "ok");
  location.hash = `#/editor/${seg(created.name)}`;
}

async function onImport(event) {
  event.preventDefault();
  const form = event.target;
  let text = form.text.value.trim();
  const file = form.file.files[0];
  if (!text && file) {
    text = await file.text();
    form.text.value = text; // kept on an error
  }
  if (!text) {
    toast("Choose a JSON file or paste a document first.", "error");
    return;
  }
  let doc;
  try {
    doc = JSON.parse(text);
  } catch (error) {
    toast(`That is not JSON: ${error.message}`, "error");
    return;
  }
  const query = { name: form.name.value.trim() || undefined, replace: form.replace.checked || undefined };
  const net = await attempt(() => post("/networks/import", doc, query), "Importing");
  if (!net) return;
  form.reset();
  toast(`Imported ${net.name} (version ${net.version}).`, "ok");
  location.hash = `#/editor/${seg(net.name)}`;
  await show(net.name);
}

async function onExport() {
  if (!state.net) return;
  const doc = await attempt(() => get(`/networks/${seg(state.net.name)}/export`), "Exporting");
  if (!doc) return;
  const blob = new Blob([JSON.stringify(doc, null, 2)], { type: "application/json" });
  const link = el("a", { href: URL.createObjectURL(blob), download: `${state.net.name}.json` });
  document.body.append(link);
  link.click();
  link.remove();
  setTimeout(() => URL.revokeObjectURL(link.href), 1000);
}

async function onDelete() {
  if (!state.net || state.net.builtin) return;
  const name = state.net.name;
  if (!confirm(`Delete network ${name} and its history? Runs started from it keep their copy.`)) return;
  const done = await attempt(() => del(`/networks/${seg(name)}`, { expected_version: state.net.version }), `Deleting ${name}`);
  if (done === undefined) return;
  state.net = null;
  toast(`Deleted ${name}.`, "ok");
  location.hash = "#/editor";
  await show();
}
