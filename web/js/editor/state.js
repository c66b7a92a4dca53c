// What the editor holds: the open network, its cells, the selection and the draft, and
// the queue its writes go through (sync.js; editor.js wires it to the page).

import { key } from "../matrix.js";

export const state = {
  catalog: null,
  networks: [],
  net: null,
  cells: new Map(),
  selected: null,
  active: false,
  draft: null, // {s, b, before, after, based}: keystrokes on one cell, not saved yet
  poll: null,
  sync: null, // the SyncQueue
};

/** An association as a cell holds it. */
export const pick = (a) => ({ strength: a.strength, source: a.source, locked: a.locked });

/** The cell as the page last read it from the server, or null. */
export const stored = (s, b) => (state.cells.has(key(s, b)) ? pick(state.cells.get(key(s, b))) : null);

/** The cell as the page shows it: the draft, else a change waiting to be sent, else stored. */
export function shown(s, b) {
  if (state.draft && state.draft.s === s && state.draft.b === b) return { a: state.draft.after, kind: "draft" };
  const waiting = state.sync.unsaved(s, b);
  if (waiting) return { a: waiting.op.after, kind: waiting.kind };
  return { a: state.cells.get(key(s, b)) || null, kind: "" };
}
