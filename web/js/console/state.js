// What the console holds: the run it shows, what it read of the run's log and memory, and
// the live stream it follows.

import { RunStatus } from "../generated/enums.js";

/** The statuses in which a run ticks (or may again, from where it is): the stream is followed. */
export const LIVE = new Set([RunStatus.running, RunStatus.paused]);

export const state = {
  catalog: null,
  high: new Set(),
  known: new Set(),
  runs: [],
  run: null,
  episodes: new Map(),
  conditions: new Map(),
  rewards: [],
  rewardIndex: new Map(),
  logCount: 0,
  logTotal: 0,
  contiguous: 0,
  memory: new Map(),
  network: new Map(),
  flashing: new Map(),
  source: null,
  poll: null,
  active: false,
  participant: false, // a study participant's console: their run only, no run control
  viserPort: null,
  lastReward: null,
  credited: new Set(),
  tick: null,
  replay: null, // the replayed tick + and - reward ({episode, tick}), or null: the live robot's
};

/**
 * The bracketed source of what made a tick's behaviour run (" (designed)"), when it is not
 * its `how` already; none on a study participant's console: "kp" or "designed" would tell
 * them their condition.
 */
export function originNote(origin, how) {
  return origin && origin !== how && !state.participant ? ` (${origin})` : "";
}
