// The new-run form: the conditions, networks, worlds and sensor definitions a run may
// name, what the chosen condition means, and the API's refusal beside the field it names.

import { get, post } from "../api.js";
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

/** Show `message` beside the form's field `input` (and mark it) until it is changed. */
export function fieldError(input, message) {
  if (!input || !input.closest) return;
  const labelEl = input.closest("label");
  if (!labelEl) return;
  labelEl.classList.add("invalid");
  let note = $(".field-error", labelEl);
  if (!note) {
    note = el("span", { class: "field-error", role: "alert" });
    labelEl.append(note);
  }
  note.textContent = message;
}

export function clearFieldError(input) {
  const labelEl = input && input.closest ? input.closest("label") : null;
  if (!labelEl) return;
  labelEl.classList.remove("invalid");
  const note = $(".field-error", labelEl);
  if (note) note.remove();
  if (input.setCustomValidity) input.setCustomValidity("");
}

function clearFormErrors(form) {
  for (const input of form.elements) clearFieldError(input);
  $("#new-run-error").hidden = true;
  $("#new-run-error").textContent = "";
}

/** The API's refusal on the form: a 422 names each field; anything else goes under it. */
function showCreateError(form, error) {
  const detail = error.body && error.body.detail;
  const rest = [];
  let first = null;
  if (Array.isArray(detail)) {
    for (const d of detail) {
      const name = [...(d.loc || [])].reverse().find((p) => typeof p === "string" && form.elements[p]);
      const input = name ? form.elements[name] : null;
      if (input && input.closest && input.closest("label")) {
        fieldError(input, d.msg);
        first = first || input;
      } else {
        rest.push(d.msg);
      }
    }
  } else {
    rest.push(error.message);
  }
  const box = $("#new-run-error");
  box.textContent = rest.length ? `Not created: ${rest.join("; ")}` : "Not created: see the marked field.";
  box.hidden = false;
  if (first) first.focus();
}

export async function onCreate(event) {
  event.preventDefault();
  const form = event.target;
  clearFormErrors(form);
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
    showCreateError(form, error);
    toast(`Creating the run: ${error.message}`, "error", { offline: error.status === 0 });
    return;
  }
  form.closest("details").open = false;
  let started = null;
  if (form.start.checked) started = await attempt(() => post(`/runs/${run.id}/start`), `Starting run ${run.id}`);
  toast(`Run ${run.id} created${started ? " and started" : ""}.`, "ok");
  location.hash = `#/console/${run.id}`;
}
