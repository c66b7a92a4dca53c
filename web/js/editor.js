// The S-R editor: a network's stimulus x behaviour matrix, edited by click or keyboard.
// Keystrokes on a cell make a draft; the draft is saved, as one version, when it is
// committed (Enter, leaving the cell, leaving the matrix). Undo and redo replay the inverse
// change as a new version, so the history always shows what happened. Every write says
// which version it was based on; the page polls for changes made elsewhere.

import { api, del, get, getAll, post, put, seg, ApiError } from "./api.js";
import { key, columns, neighbour, render, rows } from "./matrix.js";
import { $, $$, attempt, el, fmt, throttle, toast, typing } from "./ui.js";
import * as runpanel from "./editor_run.js";

const POLL_MS = 2000;

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
  draft: null, // {s, b, before, after, based}: keystrokes on one cell, not saved yet
  outbox: [], // changes made while the service was away: {s, b, before, after, force, note, based}
  poll: null,
  sending: [], // changes queued or being saved, oldest first
  mine: new Set(), // versions this page wrote
};

/** A strength as a cell shows it: "1", ".4", ".25", "0" (never ".00"). */
export function short(x) {
  if (x >= 0.995) return "1";
  if (x < 0.005) return "0";
  return x.toFixed(2).replace(/0+$/, "").replace(/^0/, "");
}

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
  $("#matrix").addEventListener("focusout", () => {
    // After the event: a redraw moves focus out and straight back in.
    setTimeout(() => {
      if (state.draft && !$("#matrix").contains(document.activeElement)) commitDraft();
    }, 0);
  });
  window.addEventListener("beforeunload", (e) => {
    if (state.draft || state.outbox.length) e.preventDefault();
  });
  runpanel.init(catalog, () => state.net);
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
  if (state.draft && state.net && name && name !== state.net.name) await commitDraft();
  await loadList();
  const wanted = name || (state.net && state.net.name) || firstEditable();
  if (wanted) await open(wanted);
  if (state.outbox.length) await flushOutbox();
  startPolling();
}

export function hide() {
  if (state.draft) commitDraft();
  state.active = false;
  clearTimeout(state.poll);
  state.poll = null;
}

/** After the service comes back: reload what is shown, then send what was kept. */
export async function reload() {
  if (!state.active) return;
  await loadList();
  if (state.net) await open(state.net.name, { keepSelection: true });
  await flushOutbox();
}

/** Watch the network's version, so a change made in another tab or editor shows here. */
function startPolling() {
  clearTimeout(state.poll);
  const tick = async () => {
    if (!state.active) return;
    if (!document.hidden && state.net && !state.pending && !state.outbox.length) {
      await enqueue(checkElsewhere);
    }
    state.poll = setTimeout(tick, POLL_MS);
  };
  state.poll = setTimeout(tick, POLL_MS);
}

async function checkElsewhere() {
  if (!state.net || state.outbox.length) return;
  let list;
  try {
    list = await get("/networks");
  } catch {
    return; // the banner says so; the next poll tries again
  }
  const mine = list.data.find((n) => n.name === state.net.name);
  if (!mine || mine.builtin || mine.version === state.net.version) return;
  const was = state.net.version;
  await open(state.net.name, { keepSelection: true });
  await loadList();
  toast(`${state.net.name} was changed elsewhere: v${was} → v${state.net.version}. The matrix shows it now.`);
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
    state.draft = null;
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
  showDraftNote();
  $("#readonly-note").hidden = !net.builtin;
  $("#delete-network").disabled = net.builtin;
  for (const b of $$("#cell-form button, #cell-form input, #cell-form select")) b.disabled = net.builtin;
  draw();
  fillInspector();
  updateUndo();
  runpanel.networkChanged(net);
}

function showDraftNote() {
  const d = state.draft;
  const waiting = state.outbox.length;
  const note = $("#draft-note");
  if (!note) return;
  note.hidden = !d && !waiting;
  note.textContent = [
    d ? `Unsaved: ${d.s} → ${d.b} (Enter or leaving the cell saves it).` : "",
    waiting ? `${waiting} change${waiting > 1 ? "s" : ""} kept in this page, sent when the service is back.` : "",
  ].filter(Boolean).join(" ");
}

/** The cell as the page shows it: the draft, else a change waiting to be sent, else stored. */
function shown(s, b) {
  const k = key(s, b);
  if (state.draft && key(state.draft.s, state.draft.b) === k) return { a: state.draft.after, kind: "draft" };
  for (let i = state.sending.length - 1; i >= 0; i--) {
    const op = state.sending[i];
    if (key(op.s, op.b) === k) return { a: op.after, kind: "draft" };
  }
  for (let i = state.outbox.length - 1; i >= 0; i--) {
    const op = state.outbox[i];
    if (key(op.s, op.b) === k) return { a: op.after, kind: "waiting" };
  }
  return { a: state.cells.get(k) || null, kind: "" };
}

const stored = (s, b) => (state.cells.has(key(s, b)) ? pick(state.cells.get(key(s, b))) : null);

function draw() {
  const { stimuli, behaviours, sensors } = state.catalog;
  const extra = state.net.associations.map((a) => a.behaviour);
  const stim = new Map(stimuli.map((x) => [x.name, x]));
  const beh = new Map(behaviours.map((x) => [x.name, x]));
  const meaning = (s) => {
    const x = stim.get(s);
    return x && x.description ? `${s}: ${x.description}` : s;
  };
  render($("#matrix"), {
    groups: rows(stimuli, sensors),
    cols: columns(behaviours, extra),
    selected: state.selected,
    readonly: state.net.builtin,
    label: `Network ${state.net.name}`,
    rowTitle: (s) => {
      const x = stim.get(s);
      return x ? `${meaning(s)}\n${x.sensor} sensor (${x.level} level), for ${x.objective.replaceAll("_", " ")}${x.rule ? `\nwhen ${x.rule}` : ""}` : s;
    },
    colTitle: (c) => {
      const x = beh.get(c.name);
      return x ? `${c.name}: ${motion(x)}, for ${x.ticks} tick${x.ticks > 1 ? "s" : ""} (${x.family})` : `${c.name}: a behaviour KP made`;
    },
    colSub: (c) => (beh.has(c.name) ? motion(beh.get(c.name), true) : ""),
    cell: (s, b) => {
      const { a, kind } = shown(s, b);
      const title = (a) => `${meaning(s)}\n→ ${b}${beh.has(b) ? ` (${motion(beh.get(b))})` : ""}\n${a ? `strength ${fmt(a.strength)}, ${a.source}${a.locked ? ", locked" : ""}` : "none"}${kind === "draft" ? "\nnot saved yet: Enter saves" : kind === "waiting" ? "\nkept in this page: sent when the service is back" : ""}`;
      if (!a) return kind ? { empty: true, draft: kind, title: title(null) } : { empty: true, title: title(null) };
      const t = 0.15 + 0.85 * a.strength;
      const ink = SOURCE_INK[a.source] || "#245fd6";
      return {
        text: short(a.strength),
        bg: `color-mix(in srgb, ${ink} ${Math.round(t * 70)}%, white)`,
        ink: t > 0.6 ? "#fff" : "#1b1f27",
        source: a.source,
        locked: a.locked,
        draft: kind,
        title: title(a),
      };
    },
  });
  showDraftNote();
}

/** A behaviour's motion: "0.45 m/s straight", "0.15 m/s, turning left 150°/s". */
function motion(b, compact = false) {
  const turn = b.turn_dps;
  if (compact) return `${b.speed_mps.toFixed(2)} m/s${turn ? ` ${turn > 0 ? "↺" : "↻"}${Math.abs(turn)}°/s` : ""}`;
  const dir = turn > 0 ? `turning left ${turn}°/s` : turn < 0 ? `turning right ${-turn}°/s` : "straight";
  return b.speed_mps === 0 && !turn ? "standing still" : `${b.speed_mps.toFixed(2)} m/s ${b.speed_mps < 0 ? "backwards, " : ""}${dir}`;
}

function selectedCell() {
  if (!state.selected) return null;
  return $(`#matrix td.c[data-s="${CSS.escape(state.selected.s)}"][data-b="${CSS.escape(state.selected.b)}"]`);
}

function select(s, b, { focus = true } = {}) {
  if (state.draft && (state.draft.s !== s || state.draft.b !== b)) commitDraft();
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
  const { a } = shown(sel.s, sel.b);
  $("#cell-name").textContent = `${sel.s} → ${sel.b}${a ? "" : " (none yet)"}`;
  const x = state.catalog.stimuli.find((t) => t.name === sel.s);
  $("#cell-meaning").textContent = x && x.description ? `${sel.s}: ${x.description}.` : "";
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
    stage((cur) => (cur ? null : undefined));
  } else if (/^[0-9]$/.test(k)) {
    event.preventDefault();
    const strength = k === "0" ? 1 : Number(k) / 10;
    stage((cur) => ({ strength, source: cur ? cur.source : "dp", locked: cur ? cur.locked : false }));
  } else if (k === "l" || k === "L") {
    event.preventDefault();
    stage((cur) => {
      if (cur) return { ...cur, locked: !cur.locked };
      toast("There is no association here to lock: add one first (Space).");
      return undefined;
    });
  } else if (k === "Enter") {
    event.preventDefault();
    if (state.draft) {
      commitDraft();
      return;
    }
    $("#cell-form").strength.focus();
    $("#cell-form").strength.select();
  } else if (k === "Escape" && state.draft) {
    event.preventDefault();
    state.draft = null;
    draw();
    select(td.dataset.s, td.dataset.b);
  }
}

function toggle() {
  stage((cur) => (cur ? null : { strength: 1, source: "dp", locked: false }));
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
  const sel = state.selected;
  // The side panel's values replace a draft of the same cell (it showed the draft).
  if (state.draft && sel && state.draft.s === sel.s && state.draft.b === sel.b) state.draft = null;
  else if (state.draft) commitDraft();
  change({ strength, source: form.source.value, locked: form.locked.checked }, { note: form.note.value });
}

/** Run `job` after every change queued before it: keystrokes are never dropped or reordered. */
function enqueue(job) {
  state.queue = state.queue.then(job, job);
  return state.queue;
}

/** The cell as the server will have it once the changes kept in this page are sent. */
function settled(s, b) {
  for (let i = state.sending.length - 1; i >= 0; i--) {
    const op = state.sending[i];
    if (op.s === s && op.b === b) return op.after;
  }
  for (let i = state.outbox.length - 1; i >= 0; i--) {
    const op = state.outbox[i];
    if (op.s === s && op.b === b) return op.after;
  }
  return stored(s, b);
}

/** Whether `before` -> `after` may be made: a locked association only changes its lock. */
function allowed(s, b, before, after) {
  const unlockOnly = before && after && before.locked && !after.locked &&
    before.strength === after.strength && before.source === after.source;
  if (before && before.locked && !unlockOnly) {
    toast(`${s} → ${b} is locked: unlock it first (L, or untick "locked" and Save).`, "error");
    return false;
  }
  return true;
}

/**
 * Change the selected cell's draft by `next` (a function of the cell as the page shows it;
 * undefined: no change). Nothing is saved until the draft is committed, so "Space, 5" on a
 * cell is one version, not two.
 */
function stage(next) {
  const sel = state.selected;
  if (!sel || !state.net) return;
  if (state.net.builtin) {
    toast(`${state.net.name} is built in and read-only: copy it to edit it.`, "error");
    return;
  }
  const d = state.draft && state.draft.s === sel.s && state.draft.b === sel.b ? state.draft : null;
  const before = d ? d.before : settled(sel.s, sel.b);
  const current = d ? d.after : before;
  const after = next(current);
  if (after === undefined || same(current, after)) return;
  if (!allowed(sel.s, sel.b, current, after)) return;
  state.draft = same(before, after) ? null : { s: sel.s, b: sel.b, before, after, based: d ? d.based : state.net.version };
  draw();
  select(sel.s, sel.b);
}

/** Save the draft (if any) as one version. */
function commitDraft() {
  const d = state.draft;
  if (!d) return Promise.resolve();
  state.draft = null;
  // Its lock was undone in the draft on purpose (L): the write may change a locked one.
  const op = { ...d, force: Boolean(d.before && d.before.locked), note: "" };
  state.sending.push(op);
  return enqueue(async () => {
    try {
      await write(op, "edit");
    } finally {
      state.sending.splice(state.sending.indexOf(op), 1);
    }
    draw();
    if (state.selected) select(state.selected.s, state.selected.b, { focus: document.activeElement === document.body || $("#matrix").contains(document.activeElement) });
  });
}

/**
 * Change the selected cell to `next` (null removes it), as one saved version: the side
 * panel's Save and Remove.
 */
function change(next, { note = "" } = {}) {
  const sel = state.selected;
  if (!sel || !state.net) return Promise.resolve();
  return enqueue(async () => {
    if (!state.net) return;
    if (state.net.builtin) {
      toast(`${state.net.name} is built in and read-only: copy it to edit it.`, "error");
      return;
    }
    const before = settled(sel.s, sel.b);
    if (same(before, next) || !allowed(sel.s, sel.b, before, next)) return;
    const unlockOnly = Boolean(before && before.locked);
    if (await write({ s: sel.s, b: sel.b, before, after: next, force: unlockOnly, note, based: state.net.version }, "edit") === true) {
      $("#cell-form").note.value = "";
    }
  });
}

/**
 * Store one change `op` = {s, b, before, after, force, note, based}: `before` is the cell
 * the change was made on, `based` the network's version then. It is written only while
 * the cell is still `before` on the server (a change of another cell elsewhere is kept
 * and ours goes on top of it); if the cell itself changed, an edit asks first and an undo
 * or redo is refused, so neither deletes another writer's change.
 * Answers true (stored), "kept" (the service is away: kept in this page), "refused" or false.
 */
async function write(op, kind) {
  if (!state.net) return false;
  if (state.outbox.length && kind !== "flush") return keep(op);
  for (let attempt = 0; attempt < 4; attempt++) {
    const now = stored(op.s, op.b);
    if (!same(now, op.before)) return clash(op, kind, now);
    const result = await send(op.s, op.b, op.after, { force: op.force, note: op.note });
    if (result === "ok") {
      const elsewhere = [];
      for (let v = op.based + 1; v < state.net.version; v++) if (!state.mine.has(v)) elsewhere.push(v);
      state.mine.add(state.net.version);
      if (elsewhere.length && kind === "edit") {
        toast(`Saved ${op.s} → ${op.b} on top of the change${elsewhere.length > 1 ? "s" : ""} made elsewhere (v${elsewhere.join(", v")}); that cell had not changed.`);
      }
      if (kind === "edit" || kind === "flush") {
        state.undo.push({ s: op.s, b: op.b, before: op.before, after: op.after });
        state.redo = [];
        updateUndo();
      }
      return true;
    }
    if (result === "offline") return kind === "flush" ? "offline" : keep(op);
    if (result !== "stale") return false;
    await open(state.net.name, { keepSelection: true }); // then look at the cell again
  }
  return false;
}

function keep(op) {
  if (!state.outbox.length) toast(`The service is away: your change to ${op.s} → ${op.b} is kept in this page and sent when it is back.`);
  state.outbox.push(op);
  draw();
  return "kept";
}

/** Send the changes kept while the service was away, in order, each version-checked. */
function flushOutbox() {
  return enqueue(async () => {
    while (state.outbox.length && state.net) {
      const op = state.outbox[0];
      const result = await write(op, "flush");
      if (result === "offline") return;
      state.outbox.shift();
    }
    if (state.net) {
      draw();
      if (state.selected) select(state.selected.s, state.selected.b, { focus: false });
    }
  });
}

const describe1 = (a) => (a === null ? "none" : `${fmt(a.strength)} ${a.source}${a.locked ? " locked" : ""}`);

/** The cell changed elsewhere after `op` was made on it (`now` is how it is stored). */
async function clash(op, kind, now) {
  const name = state.net.name;
  if (kind === "undo" || kind === "redo") {
    toast(`${op.s} → ${op.b} was changed elsewhere (now ${describe1(now)}): ${kind === "undo" ? "undoing" : "redoing"} would overwrite that change, so it was not ${kind === "undo" ? "undone" : "redone"}.`, "error");
    return "refused";
  }
  const current = state.net.version;
  const diff = current !== op.based
    ? await attempt(() => get(`/networks/${seg(name)}/diff`, { from: op.based, to: current }), "Comparing versions") : null;
  draw();
  const lines = diff ? describeDiff(diff) : [];
  const yours = op.after === null ? "remove it" : `set it to ${describe1(op.after)}`;
  const question = `${name} was saved elsewhere meanwhile (version ${op.based} → ${current}):\n` +
    `${lines.join("\n") || `~ ${op.s} → ${op.b}: now ${describe1(now)}`}\n\n` +
    `Reapply your change to ${op.s} → ${op.b} (${yours}) on top of version ${current}?`;
  if (!confirm(question)) {
    toast(`Your change to ${op.s} → ${op.b} was not saved: the editor shows version ${current}.`, "error");
    return false;
  }
  if (same(now, op.after)) return true;
  return write({ ...op, before: now, force: true, based: current }, kind);
}

/**
 * Write one cell: "ok" when the server stored it, "stale" (412: the network moved on),
 * "offline" or "error". The page state follows the server.
 */
async function send(s, b, after, { force = false, note = "" } = {}) {
  state.pending = true;
  const name = state.net.name;
  const live = $("#live-edits").checked;
  // The version this change is based on: the server refuses it (412) if another tab or
  // editor saved meanwhile, instead of silently overwriting what they did.
  const query = { force: force || undefined, live: live || undefined, note: note || undefined, expected_version: state.net.version };
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
    if (state.selected) select(state.selected.s, state.selected.b, { focus: $("#matrix").contains(document.activeElement) || document.activeElement === document.body });
    refreshVersions();
    return "ok";
  } catch (error) {
    if (error instanceof ApiError && error.status === 412) return "stale";
    if (error instanceof ApiError && error.status === 0) return "offline";
    const message = error instanceof ApiError && error.status === 409 && /lock/i.test(error.message)
      ? `${s} → ${b} is locked on the server: unlock it first.` : error.message;
    toast(`Saving ${s} → ${b}: ${message}`, "error");
    if (error instanceof ApiError) await open(name, { keepSelection: true });
    return "error";
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

/** Undo (or redo) the last change of this page, only while its cell is as the change left it. */
function replay(from, to, kind) {
  if (state.draft) { // a draft is undone by dropping it
    if (kind === "undo") {
      state.draft = null;
      draw();
      if (state.selected) select(state.selected.s, state.selected.b);
      return Promise.resolve();
    }
    commitDraft();
  }
  return enqueue(async () => {
    const op = from.pop();
    if (!op || !state.net) return;
    state.selected = { s: op.s, b: op.b };
    const [before, after] = kind === "undo" ? [op.after, op.before] : [op.before, op.after];
    const result = await write({ s: op.s, b: op.b, before, after, force: true, note: kind, based: state.net.version }, kind);
    if (result === true || result === "kept") to.push(op);
    else if (result !== "refused") from.push(op);
    updateUndo();
  });
}

const undo = () => replay(state.undo, state.redo, "undo");
const redo = () => replay(state.redo, state.undo, "redo");

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
  const list = await attempt(() => getAll(`/networks/${seg(state.net.name)}/versions`), "Loading the history");
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
  state.mine.add(net.version);
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
  // reset(), not emptied fields: an emptied required field the user typed in is
  // :user-invalid, and the Name field showed red after a Create that worked.
  const base = form.base.value;
  form.reset();
  form.base.value = base;
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
