// The page: routing between the editor, the console and the organiser's studies, a study
// participant's page (their link), the connection to the service, and recovery when the
// service restarts.

import { get, onReachability, participantToken, setParticipantToken, setToken, token } from "./api.js";
import * as console_ from "./console/console.js";
import * as editor from "./editor/editor.js";
import * as participant from "./participant.js";
import * as studies from "./studies.js";
import { $, $$, toast, typing } from "./ui.js";

const RETRY_MS = 1500;
const HEARTBEAT_MS = 2000;
let health = null;
let online = null;
let ready = false;

function setOnline(up) {
  if (up === online) return;
  const wasOffline = online === false;
  online = up;
  const conn = $("#conn");
  conn.className = `conn ${up ? "online" : "offline"}`;
  $(".conn-text", conn).textContent = up ? `online${health ? ` · v${health.version} · ${health.database}` : ""}` : "offline";
  if (health) conn.title = `Connection to the service (data files ${health.data_version})`;
  $("#offline").hidden = up;
  if (up && wasOffline && ready) recover();
}

/** Say so when data files changed under the running service: it keeps what it read. */
function showData() {
  const changed = health?.data_changed ?? [];
  const banner = $("#data-stale");
  banner.hidden = changed.length === 0;
  banner.textContent = changed.length
    ? `Data files changed since the service started (core/data/${changed.join(", core/data/")}). ` +
      "It keeps using them as they were: restart srlab serve to use the changes."
    : "";
}

/** Ask the service how it is now and then, so a restart shows even on an idle page. */
async function heartbeat() {
  try {
    health = await get("/health");
    showData();
  } catch {
    // get() reported it: the banner is up and the next beat tries again
  }
  setTimeout(heartbeat, online ? HEARTBEAT_MS : RETRY_MS);
}

/** Reload what the page shows; the page is busy (aria-busy) until it matches the service. */
async function recover() {
  document.body.setAttribute("aria-busy", "true");
  try {
    toast("The service is back.", "ok");
    try {
      health = await get("/health");
      showData();
    } catch {
      return;
    }
    if (participantToken()) {
      await route();
      return;
    }
    await editor.reload();
    await console_.reload(health);
  } finally {
    document.body.removeAttribute("aria-busy");
  }
}

function parseHash() {
  const [, view, arg] = location.hash.match(/^#\/(editor|console|studies|study)(?:\/(.+))?$/) || [];
  return { view: view || "editor", arg: arg ? decodeURIComponent(arg) : null };
}

/** A participant's link keeps its token for this tab: from then on the tab is theirs. */
function keepParticipant() {
  const { view, arg } = parseHash();
  if (view === "study" && arg) setParticipantToken(arg);
  document.body.classList.toggle("participant", Boolean(participantToken()));
}

const TITLES = { editor: "S-R editor", console: "trainer console", studies: "studies" };

async function route() {
  keepParticipant();
  const { view, arg } = parseHash();
  if (participantToken()) {
    // Their page only; a run the URL names (#/console/<id>) is shown if it is theirs.
    for (const v of ["#view-editor", "#view-studies"]) $(v).hidden = true;
    participant.hide();
    await participant.show(view === "console" && arg ? Number(arg) : null, health);
    return;
  }
  for (const tab of $$(".tabs a")) tab.setAttribute("aria-selected", tab.dataset.view === view ? "true" : "false");
  $("#view-editor").hidden = view !== "editor";
  $("#view-console").hidden = view !== "console";
  $("#view-studies").hidden = view !== "studies";
  $("#view-study").hidden = true;
  document.title = `srlab · ${TITLES[view] || view}`;
  if (view !== "editor") editor.hide();
  if (view !== "console") console_.hide();
  if (view !== "studies") studies.hide();
  if (view === "editor") await editor.show(arg);
  else if (view === "console") await console_.show(arg, health);
  else if (view === "studies") await studies.show();
}

async function boot() {
  onReachability(setOnline);
  $("#token-button").addEventListener("click", () => {
    $("#token-form").token.value = token();
    $("#token-dialog").showModal();
  });
  $("#token-dialog").addEventListener("close", () => {
    if ($("#token-dialog").returnValue === "save") {
      setToken($("#token-form").token.value.trim());
      toast(token() ? "Token saved in this browser." : "Token cleared.", "ok");
    }
  });
  $("#help-button").addEventListener("click", () => $("#help-dialog").showModal());
  document.addEventListener("keydown", (e) => {
    if (e.key === "?" && !typing(e)) $("#help-dialog").showModal();
  });
  keepParticipant();
  // Wait for the service (it may be starting) and load the catalogue once: a request
  // that fails on the way (the service restarting, a connection dropped) is tried again,
  // so the page never waits for good on a first load that went wrong.
  let catalog;
  for (;;) {
    try {
      health = await get("/health");
      showData();
      const [stimuli, behaviours, sensors] = await Promise.all([get("/stimuli"), get("/behaviours"), get("/sensors")]);
      catalog = { stimuli, behaviours, sensors };
      break;
    } catch (error) {
      if (error.status === 401 && participantToken()) {
        // A participant's link the service does not know: say so, not a page that waits.
        setOnline(true);
        $("#view-study").hidden = false;
        participant.fail(error);
        document.body.dataset.ready = "true";
        return;
      }
      await new Promise((r) => setTimeout(r, RETRY_MS));
    }
  }
  setOnline(true);
  editor.init(catalog);
  console_.init(catalog);
  studies.init();
  ready = true;
  window.addEventListener("hashchange", route);
  try {
    await route();
  } catch (error) {
    // Shown, not swallowed: the page stays usable (the tabs, the next poll) and says why.
    toast(error.message || String(error), "error");
  }
  setTimeout(heartbeat, HEARTBEAT_MS);
  document.body.dataset.ready = "true";
}

boot();
