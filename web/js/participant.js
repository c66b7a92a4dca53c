// A study participant's page (their link: #/study/<token>): the consent text and its
// version with "I agree", then the trainer console for their run only, then, once their
// budget is spent, the completion code or the way on. The token goes with every request
// (api.js), so whatever is not theirs answers 403, and the page says so in place.

import { participantToken, post, get } from "./api.js";
import * as console_ from "./console/console.js";
import { $, attempt, el, toast } from "./ui.js";

const POLL_MS = 2000;
let poll = null;
let me = null;
let health = null;

const body = () => $("#study-body");

/** Why a link does not work, as the participant can act on it. */
function refusal(error) {
  if (error.status === 401) {
    return `This link is not known here: ${error.message}. Check that the whole link was copied, or ask the study's organiser for a new one.`;
  }
  if (error.status === 403) return `This is not yours to see: ${error.message}.`;
  return error.message;
}

/** Show `message` in place of the page (an unknown link, another's run, the service away). */
export function fail(error, { back = false } = {}) {
  stopConsole();
  body().replaceChildren(el("p", { class: "note study-error", role: "alert", text: refusal(error) }),
    back ? el("p", {}, el("a", { href: `#/study/${participantToken()}`, text: "Back to your robot" })) : null);
}

function stopConsole() {
  console_.hide();
  $("#view-console").hidden = true;
}

/** Show the page; `asked` is a run the URL names (#/console/<id>), else their own. */
export async function show(asked, health_) {
  health = health_;
  $("#view-study").hidden = false;
  document.title = "srlab · study";
  try {
    me = await get("/participant");
  } catch (error) {
    fail(error);
    return;
  }
  await render(asked);
}

export function hide() {
  clearInterval(poll);
  poll = null;
  stopConsole();
}

async function render(asked = null) {
  $("#study-title").textContent = `Study ${me.study}`;
  if (me.status === "done") {
    done();
    return;
  }
  if (me.status !== "training" || me.run_id === null) {
    consentForm();
    return;
  }
  body().replaceChildren(el("p", { id: "study-training" },
    `You are training robot #${me.run_id}. Press `, el("kbd", { text: "+" }), " (or + good) when it does well and ",
    el("kbd", { text: "-" }), " (or − bad) when it does badly. ",
    el("span", { class: "muted", text: me.budget_episodes !== null
      ? `The study ends after ${me.budget_episodes} episode${me.budget_episodes === 1 ? "" : "s"}.`
      : `The study ends after ${Math.round(me.budget_s)} s of training.` })),
    ...(health && health.viser_port ? [viewLink()] : []));
  $("#view-console").hidden = false;
  const failed = await console_.show(asked ?? me.run_id, health, { participant: true });
  if (failed) {
    fail(failed, { back: true });
    return;
  }
  clearInterval(poll);
  poll = setInterval(check, POLL_MS);
}

/**
 * "3D view": their run's view, read-only, in a new tab. The token never goes into a URL:
 * the service answers the view's URL with a one-time ticket (good for a minute), which
 * the view trades for a cookie for this run alone.
 */
function viewLink() {
  const link = el("a", { id: "study-view3d", class: "button", href: "#", text: "3D view ↗",
    title: "Watch your robot in 3D (in a new tab)" });
  link.addEventListener("click", async (event) => {
    event.preventDefault();
    const view = await attempt(() => post("/participant/view-ticket"), "Opening the 3D view");
    if (view) window.open(view.url, "_blank", "noopener");
  });
  return el("p", {}, link);
}

/** Whether the budget is spent: the service says so on this read (and stops the run). */
async function check() {
  let now;
  try {
    now = await get("/participant");
  } catch {
    return; // the service away: the banner says so, the next poll tries again
  }
  if (now.status === "done" && me.status !== "done") {
    me = now;
    done();
  }
}

function consentForm() {
  const agree = el("button", { type: "button", id: "consent-agree", class: "primary", text: "I agree" });
  const message = el("p", { class: "form-error", role: "alert", hidden: true });
  agree.addEventListener("click", async () => {
    agree.disabled = true;
    try {
      me = await post("/participant/consent", { consent_version: me.consent_version });
    } catch (error) {
      agree.disabled = false;
      message.hidden = false;
      if (error.status === 409) {
        message.textContent = `${error.message}. The text above is read again: read it, then agree.`;
        me = await get("/participant").catch(() => me);
        $("#consent-text").textContent = me.consent_text;
        $("#consent-version").textContent = `Version ${me.consent_version}`;
      } else if (error.status === 429) {
        message.textContent = `${error.message}. Your place is kept: press "I agree" again in a moment.`;
      } else {
        message.textContent = refusal(error);
      }
      return;
    }
    await render();
  });
  body().replaceChildren(
    el("h2", { text: "Consent" }),
    el("div", { id: "consent-text", class: "consent-text", text: me.consent_text }),
    el("p", { id: "consent-version", class: "muted small", text: `Version ${me.consent_version}` }),
    agree, message);
}

/** The study's questions, asked once training is done and before the completion code. */
function questionnaire() {
  const form = el("form", { id: "questionnaire", class: "questionnaire" });
  const fields = me.questionnaire.map((question, i) => {
    const answer = el("textarea", { id: `answer-${i + 1}`, name: `answer-${i + 1}`, rows: 3, maxlength: 2000, required: true });
    form.append(el("label", { class: "question" }, el("span", { text: question }), answer));
    return answer;
  });
  const message = el("p", { class: "form-error", role: "alert", hidden: true });
  const send = el("button", { type: "submit", id: "answers-submit", class: "primary", text: "Send my answers" });
  form.append(send, message);
  form.addEventListener("submit", async (e) => {
    e.preventDefault();
    send.disabled = true;
    try {
      me = await post("/participant/answers", { answers: fields.map((f) => f.value.trim()) });
    } catch (error) {
      send.disabled = false;
      message.hidden = false;
      message.textContent = error.status === 409 && error.message.includes("already")
        ? "Your answers are in already."
        : refusal(error);
      if (error.status === 409) me = await get("/participant").catch(() => me);
      if (!me.answered) return;
    }
    done();
  });
  body().replaceChildren(el("h2", { text: "Thank you: a few questions before you finish" }), form);
  fields[0].focus();
}

function done() {
  clearInterval(poll);
  poll = null;
  stopConsole();
  if (me.questionnaire.length && !me.answered) {
    questionnaire();
    return;
  }
  const parts = [el("h2", { text: "Thank you: you have finished." })];
  if (me.completion_code) {
    const copy = el("button", { type: "button", class: "small", text: "Copy" });
    copy.addEventListener("click", async () => {
      await navigator.clipboard.writeText(me.completion_code).then(() => toast("Code copied.", "ok"), () => {});
    });
    parts.push(el("p", {}, "Your completion code: ", el("strong", { id: "completion-code", class: "code", text: me.completion_code }), " ", copy));
  }
  if (me.redirect_url) parts.push(el("p", {}, el("a", { id: "completion-link", class: "button primary", href: me.redirect_url, text: "Continue" })));
  if (!me.completion_code && !me.redirect_url) parts.push(el("p", { class: "muted", text: "You may close this page." }));
  body().replaceChildren(...parts);
}
