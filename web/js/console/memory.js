// The run's reliabilities as a live Table III: LTM or RLTM over the S-R matrix, with the
// network's associations marked and the pairs just promoted or demoted flashing.

import { get } from "../api.js";
import { columns, key, render, rows } from "../matrix.js";
import { $, attempt, el, fmt, heat, throttle } from "../ui.js";
import { state } from "./state.js";

const memoryKind = () => ($('input[name="memory"]:checked') || { value: "ltm" }).value;

export async function loadMemory() {
  const run = state.run;
  if (!run) {
    $("#heatmap").replaceChildren(el("p", { class: "muted", style: "padding:12px", text: "Pick or create a run." }));
    return;
  }
  const kind = memoryKind();
  const [memory, network] = await Promise.all([
    attempt(() => get(`/runs/${run.id}/${kind}`)),
    attempt(() => get(`/runs/${run.id}/network`)),
  ]);
  if (!memory || !network || !state.run || state.run.id !== run.id) return;
  state.memory = new Map(memory.data.map((m) => [key(m.stimulus, m.behaviour), m.reliability]));
  state.network = new Map(network.data.map((a) => [key(a.stimulus, a.behaviour), a]));
  drawHeat();
  explainEmpty(kind, run);
}

/** Why the chosen memory holds nothing (an empty grid says nothing by itself). */
function explainEmpty(kind, run) {
  const note = $("#memory-empty");
  // A study's participant is not told their condition: the reasons that name it are not theirs.
  const c = state.participant ? null : state.conditions.get(run.condition);
  let why = "";
  if (state.memory.size === 0) {
    if (c && !c.learning) why = `${run.condition} does not learn: its LTM and RLTM stay empty.`;
    else if (kind === "rltm" && c && !c.kp)
      why = `RLTM is knowledge propagation's memory: ${run.condition} runs without it (a kp run fills it).`;
    else if (kind === "rltm")
      why = "Nothing propagated yet: RLTM gets a camera pair when a reward follows sonar responses recorded while the camera saw an obstacle stimulus.";
    else why = "Nothing learned yet: LTM gets a pair when a reward credits an STM record (a tick whose behaviour answered a stimulus).";
  }
  note.textContent = why;
  note.hidden = !why;
}

export const refreshMemory = throttle(() => loadMemory(), 700);

function drawHeat() {
  const { stimuli, behaviours, sensors } = state.catalog;
  const extra = [...state.memory.keys(), ...state.network.keys()].map((k) => k.split("\u0000")[1]);
  const now = Date.now();
  const table = render($("#heatmap"), {
    groups: rows(stimuli, sensors),
    cols: columns(behaviours, extra),
    selected: null,
    readonly: true,
    label: `${memoryKind().toUpperCase()} reliabilities of run ${state.run.id}`,
    cell: (s, b) => {
      const k = key(s, b);
      const v = state.memory.get(k);
      const a = state.network.get(k);
      if (v === undefined && !a) return null;
      const color = heat(v || 0);
      return {
        text: v === undefined ? "" : v >= 0.995 ? "1" : fmt(v, 2).slice(1),
        bg: v === undefined ? "" : color.bg,
        ink: color.ink,
        inNet: Boolean(a),
        source: a ? a.source : "",
        locked: a ? a.locked : false,
        title: `${s} → ${b}: ${v === undefined ? "no reliability" : `reliability ${fmt(v, 3)}`}${a ? `; in the network (${a.source}, strength ${fmt(a.strength)})` : ""}`,
      };
    },
  });
  for (const [k, at] of state.flashing) {
    if (now - at > 3500) {
      state.flashing.delete(k);
      continue;
    }
    const [s, b] = k.split("\u0000");
    const td = table.querySelector(`td.c[data-s="${CSS.escape(s)}"][data-b="${CSS.escape(b)}"]`);
    if (td) td.classList.add("flash");
  }
}
