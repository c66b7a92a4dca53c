// A network's history: what changed between two versions, and going back to one (a new
// version; the history is kept).

import { get, post, seg } from "../api.js";
import { $, attempt, el, fmt, toast } from "../ui.js";
import { checkedVersions, loadList, loadVersions, open, setNetwork } from "./network.js";
import { state } from "./state.js";
import { describeCell } from "./sync.js";

/** One line per association that changed between two versions (the diff's answer). */
export function describeDiff(d) {
  return [
    ...d.added.map((a) => `+ ${a.stimulus} → ${a.behaviour} (${describeCell(a)})`),
    ...d.removed.map((a) => `− ${a.stimulus} → ${a.behaviour}`),
    ...d.changed.map((c) => `~ ${c.stimulus} → ${c.behaviour}: ${describeCell(c.before)} → ${describeCell(c.after)}`),
  ];
}

const line = (a) => `${a.stimulus} → ${a.behaviour} (${fmt(a.strength)}, ${a.source}${a.locked ? ", locked" : ""})`;

export async function onDiff() {
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

export async function onRevert() {
  const [version] = checkedVersions();
  if (!confirm(`Make ${state.net.name} what it was at version ${version}? (A new version; the history is kept.)`)) return;
  const live = $("#live-edits").checked;
  const net = await attempt(() => post(`/networks/${seg(state.net.name)}/revert`, { version }, { force: true, live: live || undefined, note: `revert to v${version}`, expected_version: state.net.version }), "Reverting");
  if (!net) await open(state.net.name, { keepSelection: true }); // e.g. 412: show what is there now
  if (!net) return;
  state.sync.forget();
  state.sync.mine.add(net.version);
  setNetwork(net);
  await Promise.all([loadVersions(), loadList()]);
  toast(`Reverted to v${version}: now version ${net.version}.`, "ok");
}
