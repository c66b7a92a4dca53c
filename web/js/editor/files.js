// Making, importing, exporting and deleting networks (the list's forms and buttons).

import { del, get, post, seg } from "../api.js";
import { attempt, el, toast } from "../ui.js";
import { state } from "./state.js";

export async function onCreate(event) {
  event.preventDefault();
  const form = event.target;
  const body = { name: form.name.value.trim(), base: form.base.value || null, description: form.description.value };
  const created = await attempt(() => post("/networks", body), `Creating ${body.name}`);
  if (!created) return; // the form keeps what was typed
  // reset(), not emptied fields: an emptied required field the user typed in is
  // :user-invalid, and the Name field showed red after a Create that worked.
  const base = form.base.value;
  form.reset();
  form.base.value = base;
  toast(`Created ${created.name}.`, "ok");
  location.hash = `#/editor/${seg(created.name)}`;
}

/** Import the form's document; resolves to the imported network's name, or null. */
export async function onImport(event) {
  event.preventDefault();
  const form = event.target;
  let text = form.text.value.trim();
  const file = form.file.files[0];
  if (!text && file) {
    text = await file.text();
    form.text.value = text; // kept on an error
  }
  if (!text) {
    toast("Choose a JSON file or paste a document first.", "error");
    return null;
  }
  let doc;
  try {
    doc = JSON.parse(text);
  } catch (error) {
    toast(`That is not JSON: ${error.message}`, "error");
    return null;
  }
  const query = { name: form.name.value.trim() || undefined, replace: form.replace.checked || undefined };
  const net = await attempt(() => post("/networks/import", doc, query), "Importing");
  if (!net) return null;
  form.reset();
  toast(`Imported ${net.name} (version ${net.version}).`, "ok");
  location.hash = `#/editor/${seg(net.name)}`;
  return net.name;
}

export async function onExport() {
  if (!state.net) return;
  const doc = await attempt(() => get(`/networks/${seg(state.net.name)}/export`), "Exporting");
  if (!doc) return;
  const blob = new Blob([JSON.stringify(doc, null, 2)], { type: "application/json" });
  const link = el("a", { href: URL.createObjectURL(blob), download: `${state.net.name}.json` });
  document.body.append(link);
  link.click();
  link.remove();
  setTimeout(() => URL.revokeObjectURL(link.href), 1000);
}

/** Delete the open network after asking; resolves to whether it was deleted. */
export async function onDelete() {
  if (!state.net || state.net.builtin) return false;
  const name = state.net.name;
  if (!confirm(`Delete network ${name} and its history? Runs started from it keep their copy.`)) return false;
  const done = await attempt(() => del(`/networks/${seg(name)}`, { expected_version: state.net.version }), `Deleting ${name}`);
  if (done === undefined) return false;
  state.net = null;
  toast(`Deleted ${name}.`, "ok");
  location.hash = "#/editor";
  return true;
}
