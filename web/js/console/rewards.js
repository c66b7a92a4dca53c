// The run's reward log as the page holds it: the newest rewards of every source, one
// entry per reward whether it came from the log, the stream or a POST's answer; and which
// of them this browser sent, for the undo.

import { state } from "./state.js";
import { RewardSource } from "../generated/enums.js";

const MINE_KEY = "srlab.mine";
export const KEEP_REWARDS = 3000; // the newest rewards the page holds (a fast rp run logs thousands)

/**
 * A reward as the timeline keeps it, from the log, the stream or a POST's answer: by the id
 * it got on arrival (`uid`), which all three carry; a reward logged before rewards had one
 * by what it is.
 */
export function rewardKey(r) {
  return r.uid ? r.uid : `${r.tick}|${r.source}|${r.value}|${r.note}`;
}

export function addReward(r) {
  const k = rewardKey(r);
  const known = state.rewardIndex.get(k);
  if (known) {
    for (const [name, v] of Object.entries(r)) if (v !== undefined) known[name] = v;
    return known;
  }
  const list = state.rewards;
  list.push(r);
  state.rewardIndex.set(k, r);
  if (list.length > 1 && list[list.length - 2].tick > r.tick) list.sort((a, b) => a.tick - b.tick);
  while (list.length > KEEP_REWARDS) state.rewardIndex.delete(rewardKey(list.shift()));
  return r;
}

export function mine() {
  try {
    return new Set(JSON.parse(localStorage.getItem(`${MINE_KEY}.${state.run ? state.run.id : ""}`) || "[]"));
  } catch {
    return new Set();
  }
}

export function rememberMine(id) {
  if (!state.run) return;
  const ids = mine();
  ids.add(id);
  localStorage.setItem(`${MINE_KEY}.${state.run.id}`, JSON.stringify([...ids].slice(-500)));
}

export const undoOf = (r) => {
  const m = /^undo of #(\d+)$/.exec(r.note || "");
  return m ? Number(m[1]) : null;
};

/** The latest reward sent from this browser that is not an undo and not undone yet. */
export function undoable() {
  const ids = mine();
  const undone = new Set(state.rewards.map(undoOf).filter((x) => x !== null));
  return [...state.rewards].reverse().find((r) => r.source === RewardSource.trainer && r.id !== undefined
    && ids.has(r.id) && undoOf(r) === null && !undone.has(r.id)) || null;
}
