// The editor's two calls the sync queue makes into the page (sync.js): write one cell to
// the service, and ask the person whether to reapply an edit whose cell changed elsewhere.

import { api, get, put, seg, ApiError } from "../api.js";
import { key } from "../matrix.js";
import { $, attempt, toast } from "../ui.js";
import { matrixFocused, reselect } from "./cells.js";
import { draw } from "./draw.js";
import { describeDiff } from "./history.js";
import { open, refreshVersions, setNetwork } from "./network.js";
import { pick, state } from "./state.js";
import { describeCell } from "./sync.js";

/**
 * Write `op.after` to its cell: "ok" when the server stored it, "stale" (412: the network
 * moved on), "offline" or "error". The page state follows the server.
 */
export async function send({ s, b, after, force = false, note = "" }) {
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
    reselect({ focus: matrixFocused() });
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
  }
}

/** `op`'s cell changed elsewhere (it is `now`): show what changed and ask to reapply `op`. */
export async function ask(op, now) {
  const name = state.net.name;
  const current = state.net.version;
  const diff = current !== op.based
    ? await attempt(() => get(`/networks/${seg(name)}/diff`, { from: op.based, to: current }), "Comparing versions") : null;
  draw();
  const lines = diff ? describeDiff(diff) : [];
  const yours = op.after === null ? "remove it" : `set it to ${describeCell(op.after)}`;
  const question = `${name} was saved elsewhere meanwhile (version ${op.based} → ${current}):\n` +
    `${lines.join("\n") || `~ ${op.s} → ${op.b}: now ${describeCell(now)}`}\n\n` +
    `Reapply your change to ${op.s} → ${op.b} (${yours}) on top of version ${current}?`;
  return confirm(question);
}
