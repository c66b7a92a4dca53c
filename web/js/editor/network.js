// The open network and the list beside it: which networks there are, reading one, and
// its versions (the history list the diff and revert act on).

import { get, getAll, seg } from "../api.js";
import { key } from "../matrix.js";
import { $, $$, attempt, el, throttle, toast } from "../ui.js";
import { fillInspector } from "./cells.js";
import { draw, showDraftNote, updateUndo } from "./draw.js";
import * as runpanel from "./run.js";
import { state } from "./state.js";

/** The network to open when none is named: the first of the user's, else the first. */
export function firstEditable() {
  const own = state.networks.find((n) => !n.builtin);
  return (own || state.networks[0] || {}).name;
}

/** Read the list of networks again and show it. */
export async function loadList() {
  const list = await attempt(() => get("/networks"), "Loading the networks");
  if (!list) return;
  state.networks = list.data;
  const ul = $("#network-list");
  ul.replaceChildren(...state.networks.map((n) => el("li", {},
    el("a", {
      href: `#/editor/${seg(n.name)}`,
      "aria-current": state.net && state.net.name === n.name ? "true" : "false",
      title: n.description || n.name,
    }, el("span", { text: n.name }), el("span", { class: "tag", text: n.builtin ? "built-in" : `v${n.version}` })))));
  const base = $("#new-network-form").base;
  const chosen = base.value || "innate";
  base.replaceChildren(el("option", { value: "", text: "(empty)" }),
    ...state.networks.map((n) => el("option", { value: n.name, text: n.name })));
  base.value = state.networks.some((n) => n.name === chosen) ? chosen : "";
  document.dispatchEvent(new CustomEvent("srlab:networks", { detail: state.networks }));
}

/** Read network `name` and show it. */
export async function open(name, { keepSelection = false } = {}) {
  let net;
  try {
    net = await get(`/networks/${seg(name)}`);
  } catch (error) {
    toast(`Network ${name}: ${error.message}`, "error");
    return;
  }
  if (!state.net || state.net.name !== net.name) {
    state.sync.forget();
    state.draft = null;
    if (!keepSelection) state.selected = null;
  }
  setNetwork(net);
  for (const a of $$("#network-list a")) {
    a.setAttribute("aria-current", a.getAttribute("href") === `#/editor/${seg(net.name)}` ? "true" : "false");
  }
  await loadVersions();
}

/** Show `net` as the open network. */
export function setNetwork(net) {
  state.net = net;
  state.cells = new Map(net.associations.map((a) => [key(a.stimulus, a.behaviour), a]));
  $("#net-title").textContent = net.name;
  $("#net-meta").textContent = `${net.builtin ? "built-in · read-only" : `version ${net.version}`} · ${net.associations.length} associations${net.description ? ` · ${net.description}` : ""}`;
  showDraftNote();
  $("#readonly-note").hidden = !net.builtin;
  $("#delete-network").disabled = net.builtin;
  for (const b of $$("#cell-form button, #cell-form input, #cell-form select")) b.disabled = net.builtin;
  draw();
  fillInspector();
  updateUndo();
  runpanel.networkChanged(net);
}

/** The history and the list, after a write (at most every 300 ms). */
export const refreshVersions = throttle(() => Promise.all([loadVersions(), loadList()]), 300);

/** The network's versions, newest first, for the diff and revert. */
export async function loadVersions() {
  if (!state.net) return;
  const list = await attempt(() => getAll(`/networks/${seg(state.net.name)}/versions`), "Loading the history");
  if (!list) return;
  const current = state.net.version;
  $("#versions").replaceChildren(...list.data.slice().reverse().map((v) => el("li", { class: v.version === current ? "current" : "" },
    el("label", {},
      el("input", { type: "checkbox", value: v.version, "aria-label": `version ${v.version}` }),
      el("span", {}, el("b", { text: `v${v.version}` }), " ",
        el("span", { class: "when", text: new Date(v.created_at).toLocaleString() }), " · ",
        `${v.association_count} assoc.`, v.note ? ` · ${v.note}` : "", v.version === current ? " · current" : "")))));
  $("#diff-out").replaceChildren();
  updateHistoryButtons();
}

export function checkedVersions() {
  return $$("#versions input:checked").map((i) => Number(i.value)).sort((a, b) => a - b);
}

export function updateHistoryButtons() {
  const picked = checkedVersions();
  $("#diff").disabled = !(picked.length === 2 || picked.length === 1);
  $("#revert").disabled = state.net.builtin || picked.length !== 1 || picked[0] === state.net.version;
  $("#revert").textContent = picked.length === 1 ? `Revert to v${picked[0]}` : "Revert to selected";
}
