// Rewarding: a reward by button or key, the undo of the last one, and the credit each
// trainer's reward gave, summed per S-R pair (or why it gave none).

import { post } from "../api.js";
import { $, attempt, el, fmt, toast } from "../ui.js";
import { refreshMemory } from "./memory.js";
import { addReward, rememberMine, rewardKey, undoable } from "./rewards.js";
import { state } from "./state.js";
import { drawRewards, redrawRewards } from "./timeline.js";
import { RewardSource, RunStatus } from "../generated/enums.js";

export function onReward(r) {
  refreshMemory();
  const previous = [...state.rewards].reverse().find((x) => x.tick < r.tick || (x.tick === r.tick && rewardKey(x) !== rewardKey(r)));
  const seen = state.rewardIndex.has(rewardKey(r));
  const ticks = r.credits.map((c) => c.tick);
  const span = ticks.length ? [Math.min(...ticks), Math.max(...ticks)] : null;
  const kept = addReward({ uid: r.uid, tick: r.tick, episode: r.episode, value: r.value, source: r.source, note: r.note, credited: r.credited, tick_seen: r.tick_seen, window: r.window, span });
  if (!seen) state.logTotal += 1; // in the log too, not read from it yet
  redrawRewards();
  if (r.source !== RewardSource.trainer) return;
  state.lastReward = r;
  state.credited.add(rewardKey(r));
  showEffect(r, kept, previous);
}

/** The credit a reward gave, summed per S-R pair; its raw STM rows one click away. */
function showEffect(r, kept, previous) {
  const sign = r.value > 0 ? "+" : "−";
  const id = kept && kept.id !== undefined ? `#${kept.id} ` : "";
  const seen = r.tick_seen !== null && r.tick_seen !== undefined
    ? `, seen at tick ${r.tick_seen}, window ticks ${r.window[0]}–${r.window[1]},` : "";
  const head = el("div", { class: "head" },
    `${id}${sign}${Math.abs(r.value)} at tick ${r.tick} (episode ${r.episode})${seen} credited ${r.credited} STM record${r.credited === 1 ? "" : "s"}`);
  if (!r.credits.length) {
    $("#reward-effect").replaceChildren(head, el("p", { class: "muted why", text: whyNothing(r, previous) }));
    return;
  }
  const pairs = new Map();
  for (const c of r.credits) {
    const k = `${c.stimulus} → ${c.behaviour}`;
    const p = pairs.get(k) || { pair: k, count: 0, total: 0, dmin: Infinity, dmax: 0, after: c.after };
    p.count += 1;
    p.total += c.after - c.before;
    p.dmin = Math.min(p.dmin, c.d_k);
    p.dmax = Math.max(p.dmax, c.d_k);
    p.after = c.after;
    pairs.set(k, p);
  }
  const summed = [...pairs.values()].sort((a, b) => Math.abs(b.total) - Math.abs(a.total));
  // A credit that changed nothing (a punishment of a pair at 0 stays at 0) has no sign.
  const signed = (v) => (Math.abs(v) < 5e-4 ? "0.000" : `${v > 0 ? "+" : "−"}${fmt(Math.abs(v), 3)}`);
  const summary = el("table", { class: "pairs" },
    el("thead", {}, el("tr", {}, el("th", { text: "S → R" }), el("th", { text: "records" }), el("th", { text: "credit" }))),
    el("tbody", {}, summed.map((p) => el("tr", {
      class: "pair",
      title: `${p.pair}: ${p.count} STM record${p.count === 1 ? "" : "s"}, d_k ${p.dmin === p.dmax ? p.dmin : `${p.dmin}–${p.dmax}`}, reliability now ${fmt(p.after, 3)}`,
    },
      el("td", { text: p.pair }), el("td", { text: p.count }),
      el("td", { class: Math.abs(p.total) < 5e-4 ? "muted" : p.total > 0 ? "good" : "bad", text: signed(p.total), title: Math.abs(p.total) < 5e-4 ? "no change: the reliability was already at its bound" : undefined })))));
  const partial = r.credited > r.credits.length ? ` (the first ${r.credits.length} of ${r.credited})` : "";
  const raw = el("details", { class: "raw" },
    el("summary", { text: `the ${r.credits.length} raw STM rows${partial}` }),
    el("table", {},
      el("thead", {}, el("tr", {}, el("th", { text: "tick" }), el("th", { text: "S → R" }), el("th", { text: "d_k" }), el("th", { text: "reliability" }))),
      el("tbody", {}, r.credits.map((c) => el("tr", {},
        el("td", { text: c.tick }), el("td", { text: `${c.stimulus} → ${c.behaviour}` }),
        el("td", { text: c.d_k }), el("td", { text: `${fmt(c.before, 3)} → ${fmt(c.after, 3)}` }))))));
  $("#reward-effect").replaceChildren(head,
    el("p", { class: "muted small", text: `Per S-R pair${partial}: credit is the change in LTM reliability.` }), summary, raw);
}

/**
 * Why a reward credited nothing, from what came before it. STM holds a record for each
 * tick whose behaviour answered a stimulus (not the default behaviour's ticks); every
 * reward, of any source, takes the records before it, and STM is emptied per episode.
 */
function whyNothing(r, previous) {
  // A study's participant is not told their condition: no reason below names or betrays it.
  const c = state.run && !state.participant ? state.conditions.get(state.run.condition) : null;
  if (c && !c.learning) return `${state.run.condition} does not learn: the reward is logged and changes nothing.`;
  const recorded = "STM records only the ticks where a behaviour answered a stimulus (not the default behaviour's)";
  if (previous && previous.episode === r.episode) {
    const what = `${previous.id !== undefined ? `#${previous.id} ` : "the reward "}(${previous.source}, ${previous.value > 0 ? "+" : ""}${previous.value}) at tick ${previous.tick}`;
    const took = previous.credited ? `, which took the records before it (${previous.credited})` : "";
    const program = previous.source === RewardSource.program && !state.participant
      ? " In this condition a reward program rewards by itself; in trainer only you and the task do."
      : "";
    return `Nothing in STM to credit: ${recorded}, and none was recorded since ${what}${took}.${program}`;
  }
  return `Nothing in STM to credit: ${recorded}, STM is emptied when an episode starts, and none was recorded yet in episode ${r.episode}.`;
}

export async function reward(value, note) {
  const run = state.run;
  if (!run) return;
  const button = $(`.reward-buttons button[data-value="${value}"]`);
  if (button) {
    button.classList.add("pressed");
    setTimeout(() => button.classList.remove("pressed"), 150);
  }
  if (run.status !== RunStatus.running && run.status !== RunStatus.paused) {
    toast(`Run ${run.id} is ${run.status}: rewards go to a running or paused run.`, "error");
    return;
  }
  const input = $("#reward-note");
  const text = note ?? input.value.trim();
  const body = text ? { value, note: text } : { value };
  // The tick on screen when the key or button was pressed: the reward credits the reaction
  // window before it (docs/studies.md). A realtime run's only: a fast run outruns the eye.
  const shown = state.tick;
  if (shown && run.mode === "realtime") body.tick_seen = shown.tick;
  const ack = await attempt(() => post(`/runs/${run.id}/rewards`, body), "Reward");
  if (!ack) return;
  if (note === undefined) input.value = "";
  rememberMine(ack.id);
  // The log's id joins the stream's copy of the same reward, found by the reward's uid.
  const logged = { uid: ack.uid, id: ack.id, tick: ack.tick, episode: ack.episode, value: ack.value, source: RewardSource.trainer, note: text, tick_seen: ack.tick_seen, window: ack.window };
  if (!state.rewardIndex.has(rewardKey(logged))) state.logTotal += 1;
  addReward(logged);
  drawRewards();
  // The stream may have shown its credit before the acknowledgement came back.
  if (state.credited.has(rewardKey(logged))) return;
  const sign = ack.value > 0 ? "+" : "−";
  $("#reward-effect").replaceChildren(el("div", { class: "head" },
    `${sign}${Math.abs(ack.value)} logged as reward #${ack.id} at tick ${ack.tick} (episode ${ack.episode}); crediting…`));
}

/**
 * "Undo my last reward": a compensating reward, never an erasure. It is a new trainer
 * reward of the opposite value noted "undo of #id", logged and applied like any other, so
 * the log still says what was given and a replay does the same. It credits what STM holds
 * now; the records the undone reward credited left STM with it.
 */
export async function undoLast() {
  const last = undoable();
  if (!last) {
    toast("Nothing of yours to undo on this run.", "error");
    return;
  }
  await reward(-last.value, `undo of #${last.id}`);
}
