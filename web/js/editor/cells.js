// One cell at a time: the selection, the side panel's inspector, the keyboard on the
// matrix, and the draft. Keystrokes on a cell make a draft; the draft is saved, as one
// version, when it is committed (Enter, leaving the cell, leaving the matrix), through the
// sync queue (sync.js).

import { neighbour } from "../matrix.js";
import { $, $$, toast } from "../ui.js";
import { draw } from "./draw.js";
import { shown, state } from "./state.js";
import { lockRefusal, same } from "./sync.js";
import { AssociationSource } from "../generated/enums.js";

function selectedCell() {
  if (!state.selected) return null;
  return $(`#matrix td.c[data-s="${CSS.escape(state.selected.s)}"][data-b="${CSS.escape(state.selected.b)}"]`);
}

/** Whether the matrix (or nothing in particular) has the keyboard, so a redraw may take it. */
export const matrixFocused = () =>
  document.activeElement === document.body || $("#matrix").contains(document.activeElement);

/** Select cell `s` -> `b` (committing a draft of another cell first). */
export function select(s, b, { focus = true } = {}) {
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

/** Select the selected cell again after a redraw. */
export function reselect({ focus }) {
  if (state.selected) select(state.selected.s, state.selected.b, { focus });
}

/** The side panel: the selected cell as the page shows it. */
export function fillInspector() {
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
  form.source.value = a ? a.source : AssociationSource.dp;
  form.locked.checked = a ? a.locked : false;
  $("#cell-remove").disabled = !a || state.net.builtin;
  $("#cell-save").textContent = a ? "Save" : "Add";
}

export function onCellClick(event) {
  const td = event.target.closest("td.c");
  if (td) select(td.dataset.s, td.dataset.b);
}

export function onMatrixKey(event) {
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
    stage((cur) => ({ strength, source: cur ? cur.source : AssociationSource.dp, locked: cur ? cur.locked : false }));
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

/** Add a full-strength association to the selected cell, or remove the one there. */
export function toggle() {
  stage((cur) => (cur ? null : { strength: 1, source: AssociationSource.dp, locked: false }));
}

export function onSaveCell(event) {
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
  const before = d ? d.before : state.sync.settled(sel.s, sel.b);
  const current = d ? d.after : before;
  const after = next(current);
  if (after === undefined || same(current, after)) return;
  const refusal = lockRefusal(sel.s, sel.b, current, after);
  if (refusal) {
    toast(refusal, "error");
    return;
  }
  state.draft = same(before, after) ? null : { s: sel.s, b: sel.b, before, after, based: d ? d.based : state.net.version };
  draw();
  select(sel.s, sel.b);
}

/** Save the draft (if any) as one version. */
export function commitDraft() {
  const d = state.draft;
  if (!d) return Promise.resolve();
  state.draft = null;
  // Its lock was undone in the draft on purpose (L): the write may change a locked one.
  return state.sync.commit({ ...d, force: Boolean(d.before && d.before.locked), note: "" });
}

/**
 * Change the selected cell to `next` (null removes it), as one saved version: the side
 * panel's Save and Remove.
 */
export function change(next, { note = "" } = {}) {
  const sel = state.selected;
  if (!sel || !state.net) return Promise.resolve();
  return state.sync.change(sel.s, sel.b, next, { note }).then((saved) => {
    if (saved) $("#cell-form").note.value = "";
  });
}

/** Undo (or redo) the last change of this page; a draft is undone by dropping it. */
function replay(kind) {
  if (state.draft) {
    if (kind === "undo") {
      state.draft = null;
      draw();
      if (state.selected) select(state.selected.s, state.selected.b);
      return Promise.resolve();
    }
    commitDraft();
  }
  return state.sync.replay(kind);
}

export const undo = () => replay("undo");
export const redo = () => replay("redo");
