// The new-run form: the conditions, networks, worlds and sensor definitions a run may
// name, what the chosen condition means, and the API's refusal beside the field it names.

import { get, post } from "../api.js";
import { clearFormErrors, showApiErrors } from "../forms.js";
import { $, attempt, el, toast } from "../ui.js";
import { state } from "./state.js";
import { aboutRewards, showRun } from "./status.js";
import { Condition } from "../generated/enums.js";

export function fillNetworks(networks) {
  const select = $("#new-run-form").network;
  const chosen = select.value;
  select.replaceChildren(el("option", { value: "", text: "the condition's" }),
    ...networks.map((n) => el("option", { value: n.name, text: n.name })));
  select.value = networks.some((n) => n.name === chosen) ? chosen : "";
}

/** The world presets and sensor definitions a new run may name. */
export async function fillSetup() {
  const [worlds, definitions] = await Promise.all([
    attempt(() => get("/worlds")), attempt(() => get("/sensor-definitions"))]);
  const form = $("#new-run-form");
  const options = (items) => items.map((x) => el("option", {
    value: x.name, text: x.default ? `${x.name} (default)` : x.name, title: x.description }));
  if (worlds) form.world.replaceChildren(el("option", { value: "", text: "the default" }), ...options(worlds));
  if (definitions) form.sensors.replaceChildren(el("option", { value: "", text: "the default" }), ...options(definitions));
}

/** The conditions the runs API takes, each with what it means for the one rewarding. */
export async function fillConditions() {
  const list = await attempt(() => get("/conditions"));
  if (!list) return;
  state.conditions = new Map(list.map((c) => [c.name, c]));
  const select = $("#new-run-form").condition;
  const chosen = select.value || Condition.trainer;
  const tag = (c) => (c.name === Condition.trainer ? " · you give the rewards (at the keyboard)"
    : c.trainer ? ` · a reward program (${c.trainer}) rewards too` : c.learning ? "" : " · does not learn");
  const ordered = [...list].sort((a, b) => (b.name === Condition.trainer) - (a.name === Condition.trainer));
  select.replaceChildren(...ordered.map((c) => el("option", { value: c.name, text: `${c.name}${tag(c)}`, title: c.description })));
  select.value = state.conditions.has(chosen) ? chosen : Condition.trainer;
  describeCondition();
  if (state.run) showRun(state.run);
}

/** What the chosen condition means: who rewards, whether it learns. */
export function describeCondition() {
  const c = state.conditions.get($("#new-run-form").condition.value);
  $("#condition-about").textContent = c ? aboutRewards(c) : "";
}

export async function onCreate(event) {
  event.preventDefault();
  const form = event.target;
  clearFormErrors(form, $("#new-run-error"));
  const number = (input) => (input.value === "" ? undefined : Number(input.value));
  const params = {};
  if (form.eta.value !== "") params.eta = Number(form.eta.value);
  if (form.epsilon.value !== "") params.epsilon = Number(form.epsilon.value);
  const body = {
    condition: form.condition.value,
    mode: form.mode.value,
    hz: number(form.hz) ?? 10,
    seed: number(form.seed) ?? 0,
    episodes: number(form.episodes) ?? null,
    network: form.network.value || null,
    world: form.world.value || null,
    sensors: form.sensors.value || null,
    params,
  };
  let run;
  try {
    run = await post("/runs", body);
  } catch (error) {
    // The form stays open with what was typed, the refusal beside the field it names.
    showApiErrors(form, $("#new-run-error"), error);
    toast(`Creating the run: ${error.message}`, "error", { offline: error.status === 0 });
    return;
  }
  form.closest("details").open = false;
  let started = null;
  if (form.start.checked) started = await attempt(() => post(`/runs/${run.id}/start`), `Starting run ${run.id}`);
  toast(`Run ${run.id} created${started ? " and started" : ""}.`, "ok");
  location.hash = `#/console/${run.id}`;
}
