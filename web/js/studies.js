// The organiser's studies page: make a study (the API's refusal beside each field), watch
// each study's progress (participants per status), invite participants (each one's link
// shown this once, with a copy button: the service keeps only its digest) and delete a
// study's recruiters' ids.

import { api, get, seg } from "./api.js";
import { clearFormErrors, showApiErrors, watchFields } from "./forms.js";
import { $, attempt, el, fmt, toast } from "./ui.js";

const POLL_MS = 3000;
const STATUSES = ["invited", "consented", "training", "done"];
const BUDGET_BRANCH = { episodes: "EpisodeBudget", seconds: "TimeBudget" };
let active = false;
let poll = null;
let studies = [];


export function init() {
  const form = $("#new-study-form");
  watchFields(form);
  form.addEventListener("submit", onCreate);
  const invite = $("#invite-form");
  watchFields(invite);
  invite.addEventListener("submit", onInvite);
  invite.study.addEventListener("change", () => loadParticipants());
}

export async function show() {
  active = true;
  if (!$("#study-conditions").textContent) {
    const list = await attempt(() => api("GET", "/conditions"));
    if (list) $("#study-conditions").textContent = `Conditions: ${list.map((c) => c.name).join(", ")}.`;
  }
  await refresh();
  clearInterval(poll);
  poll = setInterval(refresh, POLL_MS);
}

export function hide() {
  active = false;
  clearInterval(poll);
  // The links were for copying then: they are not kept on the page.
  $("#invited").replaceChildren();
  $("#invited").hidden = true;
}

/** The studies with their progress, and the chosen study's participants. */
async function refresh() {
  if (!active) return;
  const message = $("#studies-message");
  let list;
  try {
    list = await get("/studies");
  } catch (error) {
    message.textContent = error.status === 401
      ? `${error.message} (the studies are the organiser's: set the service's token with ⚙ token)`
      : error.message;
    message.hidden = false;
    return;
  }
  message.hidden = true;
  studies = list.data;
  drawStudies();
  const select = $("#invite-form").study;
  const chosen = select.value;
  select.replaceChildren(...(studies.length
    ? studies.map((s) => el("option", { value: s.name, text: s.name }))
    : [el("option", { value: "", text: "no study yet: create one" })]));
  if (studies.some((s) => s.name === chosen)) select.value = chosen;
  else if (studies.length) select.value = studies[studies.length - 1].name;
  await loadParticipants();
}

const budget = (s) => (s.budget_episodes !== null ? `${s.budget_episodes} episode${s.budget_episodes === 1 ? "" : "s"}` : `${fmt(s.budget_s, 0)} s`);

/** How much of the study's budget a participant's run has spent: "3 / 5 episodes", "120 / 600 s". */
function spent(p, study) {
  if (p.status === "done") return "budget spent";
  if (p.episodes_done === null || !study) return "—";
  return study.budget_episodes !== null
    ? `${p.episodes_done} / ${budget(study)}`
    : `${fmt(p.seconds_done, 0)} / ${budget(study)}`;
}

function drawStudies() {
  const box = $("#studies-list");
  if (!studies.length) {
    box.replaceChildren(el("p", { class: "muted", text: "No study yet: create one with the form." }));
    return;
  }
  box.replaceChildren(el("table", { class: "studies" },
    el("thead", {}, el("tr", {}, ["Study", "Conditions", "Budget", ...STATUSES, ""].map((h) => el("th", { text: h })))),
    el("tbody", {}, studies.map((s) => el("tr", { dataset: { study: s.name } },
      el("td", { text: s.name, title: `consent version ${s.consent_version}${s.completion_code ? ` · code ${s.completion_code}` : ""}${s.redirect_url ? ` · then ${s.redirect_url}` : ""}` }),
      el("td", { text: `${s.conditions.join(", ")} (${s.assignment})` }),
      el("td", { text: budget(s) }),
      STATUSES.map((k) => el("td", { class: `count ${k}`, dataset: { status: k }, text: s.progress[k] ?? 0 })),
      el("td", {}, el("button", {
        type: "button", class: "danger small", text: "Delete ids…",
        title: "Delete the recruiters' ids of this study's participants: pseudonyms, runs and rewards stay",
        onclick: () => deleteIdentities(s.name),
      })))))));
}

async function loadParticipants() {
  const name = $("#invite-form").study.value;
  $("#participants-of").textContent = name ? `of ${name}` : "";
  if (!name) {
    $("#participants").replaceChildren();
    return;
  }
  const list = await attempt(() => get(`/studies/${seg(name)}/participants`));
  if (!list || $("#invite-form").study.value !== name) return;
  const study = studies.find((s) => s.name === name);
  $("#participants").replaceChildren(list.data.length
    ? el("table", { class: "participants" },
      el("thead", {}, el("tr", {}, ["Pseudonym", "Status", "Condition", "Run", "Progress"].map((h) => el("th", { text: h })))),
      el("tbody", {}, list.data.map((p) => el("tr", { dataset: { pseudonym: p.pseudonym } },
        el("td", { class: "mono", text: p.pseudonym.slice(0, 12), title: p.pseudonym }),
        el("td", { text: p.status }),
        el("td", { text: p.condition || "—" }),
        el("td", {}, p.run_id === null ? "—" : el("a", { href: `#/console/${p.run_id}`, text: `#${p.run_id}` })),
        el("td", { class: "progress", text: spent(p, study) })))))
    : el("p", { class: "muted small", text: "None yet." }));
}

async function onCreate(event) {
  event.preventDefault();
  const form = event.target;
  const box = $("#new-study-error");
  clearFormErrors(form, box);
  const unit = form.budget_unit.value;
  const lines = (text) => text.split("\n").map((x) => x.trim()).filter(Boolean);
  const optional = (input) => input.value.trim() || null;
  const body = {
    name: form.name.value.trim(),
    conditions: form.conditions.value.split(",").map((x) => x.trim()).filter(Boolean),
    assignment: form.assignment.value,
    budget: { [unit]: form.budget.value === "" ? null : Number(form.budget.value) },
    consent_text: form.consent_text.value,
    consent_version: form.consent_version.value.trim(),
    questionnaire: lines(form.questionnaire.value),
    completion_code: optional(form.completion_code),
    redirect_url: optional(form.redirect_url),
  };
  // The budget is one of two shapes: only the refusal of the one sent is about this form.
  const other = BUDGET_BRANCH[unit === "episodes" ? "seconds" : "episodes"];
  let study;
  try {
    study = await api("POST", "/studies", { body });
  } catch (error) {
    showApiErrors(form, box, error, { keep: (d) => !(d.loc || []).includes(other) });
    toast(`Creating the study: ${error.message}`, "error", { offline: error.status === 0 });
    return;
  }
  toast(`Study ${study.name} created.`, "ok");
  $("#invite-form").study.append(el("option", { value: study.name, text: study.name }));
  $("#invite-form").study.value = study.name;
  await refresh();
}

async function onInvite(event) {
  event.preventDefault();
  const form = event.target;
  const box = $("#invite-error");
  clearFormErrors(form, box);
  const name = form.study.value;
  const ids = form.external_ids.value.split("\n").map((x) => x.trim()).filter(Boolean);
  const body = ids.length ? { external_ids: ids } : { count: form.count.value === "" ? null : Number(form.count.value) };
  if (!name) {
    box.textContent = "Create a study first.";
    box.hidden = false;
    return;
  }
  let made;
  try {
    made = await api("POST", `/studies/${seg(name)}/participants`, { body });
  } catch (error) {
    // A body of neither shape: say which field to fill rather than the union's two refusals.
    const keep = ids.length ? (d) => !(d.loc || []).includes("ParticipantsAnonymous") : (d) => !(d.loc || []).includes("ParticipantsNamed");
    showApiErrors(form, box, error, { lead: "Not added", keep });
    return;
  }
  form.external_ids.value = "";
  form.count.value = "";
  showLinks(name, made.data, ids);
  await refresh();
}

/** The new participants' links, this once: the service keeps only their tokens' digests. */
function showLinks(study, invited, ids) {
  const box = $("#invited");
  const rows = invited.map((p, i) => {
    const link = el("input", { class: "link", readonly: true, value: p.link, "aria-label": `Link of ${ids[i] || p.pseudonym.slice(0, 12)}` });
    const copy = el("button", { type: "button", class: "small", text: "Copy" });
    copy.addEventListener("click", () => copyLink(link, copy));
    return el("li", { dataset: { pseudonym: p.pseudonym } },
      el("span", { class: "who", text: ids[i] || p.pseudonym.slice(0, 12), title: p.pseudonym }), link, copy);
  });
  box.replaceChildren(
    el("p", { class: "note", text: `${invited.length} link${invited.length === 1 ? "" : "s"} for ${study}: shown this once (the service keeps no copy), so copy them now.` }),
    el("ol", { class: "links" }, rows),
    el("button", { type: "button", class: "small", text: "I have copied them: hide", onclick: () => hide_() }));
  box.hidden = false;
  function hide_() {
    box.replaceChildren();
    box.hidden = true;
  }
}

async function copyLink(input, button) {
  try {
    await navigator.clipboard.writeText(input.value);
  } catch {
    // Without the clipboard API (a page not on a secure origin): the browser's own copy.
    input.select();
    document.execCommand("copy");
  }
  button.textContent = "Copied";
  setTimeout(() => (button.textContent = "Copy"), 1500);
}

async function deleteIdentities(name) {
  if (!confirm(`Delete the recruiters' ids of study ${name}? Pseudonyms, runs and rewards stay, but no longer lead back to a person. This cannot be undone.`)) return;
  const done = await attempt(() => api("DELETE", `/studies/${seg(name)}/identities`), `Deleting the ids of ${name}`);
  if (done) toast(`${done.deleted} recruiter id${done.deleted === 1 ? "" : "s"} of ${name} deleted.`, "ok");
}
