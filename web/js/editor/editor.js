// The S-R editor: a network's stimulus x behaviour matrix, edited by click or keyboard.
// Keystrokes on a cell make a draft, saved as one version when committed (cells.js).
// Undo and redo replay the inverse change as a new version, so the history always shows
// what happened. Every write says which version it was based on (sync.js); the page polls
// for changes made elsewhere.

import { get } from "../api.js";
import { $, toast, typing } from "../ui.js";
import * as cells from "./cells.js";
import { draw, updateUndo } from "./draw.js";
import * as files from "./files.js";
import { onDiff, onRevert } from "./history.js";
import { firstEditable, loadList, open, updateHistoryButtons } from "./network.js";
import * as runpanel from "./run.js";
import { ask, send } from "./save.js";
import { state, stored } from "./state.js";
import { SyncQueue } from "./sync.js";

const POLL_MS = 2000;

state.sync = new SyncQueue({
  network: () => state.net,
  stored,
  send,
  reload: () => open(state.net.name, { keepSelection: true }),
  ask,
  select: (s, b) => {
    state.selected = { s, b };
  },
  notify: toast,
  changed(what) {
    if (what === "undo") {
      updateUndo();
      return;
    }
    draw();
    if (what === "edit") cells.reselect({ focus: cells.matrixFocused() });
    else if (what === "flush") cells.reselect({ focus: false });
  },
});

/** Set up the editor once the catalogue is known. */
export function init(catalog) {
  state.catalog = catalog;
  $("#new-network-form").addEventListener("submit", files.onCreate);
  $("#import-form").addEventListener("submit", async (event) => {
    const name = await files.onImport(event);
    if (name) await show(name);
  });
  $("#undo").addEventListener("click", cells.undo);
  $("#redo").addEventListener("click", cells.redo);
  $("#export").addEventListener("click", files.onExport);
  $("#delete-network").addEventListener("click", async () => {
    if (await files.onDelete()) await show();
  });
  $("#copy-builtin").addEventListener("click", () => {
    const form = $("#new-network-form");
    form.base.value = state.net.name;
    form.closest("details").open = true;
    form.name.focus();
  });
  $("#cell-form").addEventListener("submit", cells.onSaveCell);
  $("#cell-remove").addEventListener("click", () => cells.change(null));
  const form = $("#cell-form");
  form.strength_range.addEventListener("input", () => (form.strength.value = form.strength_range.value));
  form.strength.addEventListener("input", () => (form.strength_range.value = form.strength.value));
  $("#matrix").addEventListener("click", cells.onCellClick);
  $("#matrix").addEventListener("dblclick", (e) => {
    if (e.target.closest("td.c")) cells.toggle();
  });
  $("#matrix").addEventListener("keydown", cells.onMatrixKey);
  $("#matrix").addEventListener("focusout", () => {
    // After the event: a redraw moves focus out and straight back in.
    setTimeout(() => {
      if (state.draft && !$("#matrix").contains(document.activeElement)) cells.commitDraft();
    }, 0);
  });
  window.addEventListener("beforeunload", (e) => {
    if (state.draft || state.sync.outbox.length) e.preventDefault();
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
      if (e.shiftKey) cells.redo();
      else cells.undo();
    } else if (mod && e.key.toLowerCase() === "y") {
      e.preventDefault();
      cells.redo();
    }
  });
}

/** Show the editor for network `name` (or the first one). */
export async function show(name) {
  state.active = true;
  if (state.draft && state.net && name && name !== state.net.name) await cells.commitDraft();
  await loadList();
  const wanted = name || (state.net && state.net.name) || firstEditable();
  if (wanted) await open(wanted);
  if (state.sync.outbox.length) await state.sync.flush();
  startPolling();
}

export function hide() {
  if (state.draft) cells.commitDraft();
  state.active = false;
  clearTimeout(state.poll);
  state.poll = null;
}

/** After the service comes back: reload what is shown, then send what was kept. */
export async function reload() {
  if (!state.active) return;
  await loadList();
  if (state.net) await open(state.net.name, { keepSelection: true });
  await state.sync.flush();
}

/** Watch the network's version, so a change made in another tab or editor shows here. */
function startPolling() {
  clearTimeout(state.poll);
  const tick = async () => {
    if (!state.active) return;
    if (!document.hidden && state.net && !state.sync.busy()) {
      await state.sync.enqueue(checkElsewhere);
    }
    state.poll = setTimeout(tick, POLL_MS);
  };
  state.poll = setTimeout(tick, POLL_MS);
}

async function checkElsewhere() {
  if (!state.net || state.sync.outbox.length) return;
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
