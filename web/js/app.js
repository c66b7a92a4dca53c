// The page: routing between the editor and the console, the connection to the service,
// and recovery when the service restarts.

import { get, onReachability, setToken, token } from "./api.js";
import * as console_ from "./console/console.js";
import * as editor from "./editor/editor.js";
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
  $("#offline").hidden = up;
  if (up && wasOffline && ready) recover();
}

/** Ask the service how it is now and then, so a restart shows even on an idle page. */
async function heartbeat() {
  try {
    health = await get("/health");
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
    } catch {
      return;
    }
    await editor.reload();
    await console_.reload(health);
  } finally {
    document.body.removeAttribute("aria-busy");
  }
}

function parseHash() {
  const [, view, arg] = location.hash.match(/^#\/(editor|console)(?:\/(.+))?$/) || [];
  return { view: view || "editor", arg: arg ? decodeURIComponent(arg) : null };
}

async function route() {
  const { view, arg } = parseHash();
  for (const tab of $$(".tabs a")) tab.setAttribute("aria-selected", tab.dataset.view === view ? "true" : "false");
  $("#view-editor").hidden = view !== "editor";
  $("#view-console").hidden = view !== "console";
  document.title = `srlab · ${view === "editor" ? "S-R editor" : "trainer console"}`;
  if (view === "editor") {
    console_.hide();
    await editor.show(arg);
  } else {
    editor.hide();
    await console_.show(arg, health);
  }
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
  // Wait for the service (it may be starting), then load the catalogue once.
  for (;;) {
    try {
      health = await get("/health");
      break;
    } catch {
      await new Promise((r) => setTimeout(r, RETRY_MS));
    }
  }
  setOnline(true);
  const [stimuli, behaviours, sensors] = await Promise.all([get("/stimuli"), get("/behaviours"), get("/sensors")]);
  const catalog = { stimuli, behaviours, sensors };
  editor.init(catalog);
  console_.init(catalog);
  ready = true;
  window.addEventListener("hashchange", route);
  await route();
  setTimeout(heartbeat, HEARTBEAT_MS);
  document.body.dataset.ready = "true";
}

boot();
