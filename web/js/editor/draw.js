// The matrix as the editor draws it: each cell's strength, source and lock, coloured by
// its source, with a draft or a change kept in the page marked; and the notes and buttons
// that follow the same state (the draft note, undo and redo).

import { columns, render, rows } from "../matrix.js";
import { $, fmt } from "../ui.js";
import { shown, state } from "./state.js";
import { AssociationSource } from "../generated/enums.js";

const SOURCE_INK = {
  [AssociationSource.innate]: "#6b7a90",
  [AssociationSource.dp]: "#245fd6",
  [AssociationSource.learned]: "#17803d",
  [AssociationSource.kp]: "#7b3fc4",
  [AssociationSource.expert]: "#b35c00",
  [AssociationSource.designed]: "#0f7f86",
};

/** A strength as a cell shows it: "1", ".4", ".25", "0" (never ".00"). */
export function short(x) {
  if (x >= 0.995) return "1";
  if (x < 0.005) return "0";
  return x.toFixed(2).replace(/0+$/, "").replace(/^0/, "");
}

/** The note under the matrix: the draft, and the changes kept while the service is away. */
export function showDraftNote() {
  const d = state.draft;
  const waiting = state.sync.outbox.length;
  const note = $("#draft-note");
  if (!note) return;
  note.hidden = !d && !waiting;
  note.textContent = [
    d ? `Unsaved: ${d.s} → ${d.b} (Enter or leaving the cell saves it).` : "",
    waiting ? `${waiting} change${waiting > 1 ? "s" : ""} kept in this page, sent when the service is back.` : "",
  ].filter(Boolean).join(" ");
}

/** Draw the open network's matrix. */
export function draw() {
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

/** The undo and redo buttons, as this page's stacks of changes are. */
export function updateUndo() {
  const { undo, redo } = state.sync;
  $("#undo").disabled = !undo.length;
  $("#redo").disabled = !redo.length;
  const last = undo[undo.length - 1];
  $("#undo").title = last ? `Undo ${last.s} → ${last.b} (Ctrl+Z)` : "Nothing to undo";
}
