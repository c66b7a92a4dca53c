// A form's refusals beside the fields they name: the browser's own checks, and the API's
// 422s (each names its field in `loc`), with whatever names no field under the form.

import { $, el } from "./ui.js";

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

/** Take every mark off the form, and empty its error line `box`. */
export function clearFormErrors(form, box) {
  for (const input of form.elements) clearFieldError(input);
  box.hidden = true;
  box.textContent = "";
}

/** Mark fields as the browser refuses them, and unmark a field once it is changed. */
export function watchFields(form) {
  // A field the browser refuses says why beside it, even where its bubble would not show.
  form.addEventListener("invalid", (e) => fieldError(e.target, e.target.validationMessage), true);
  form.addEventListener("input", (e) => clearFieldError(e.target));
}

/**
 * The API's refusal on `form`: a 422 names each field (the last name in its `loc` that is
 * a field of the form); the rest goes in `box`, after `lead`. `keep(d)` may drop an entry
 * (e.g. the branch of a union the form did not send).
 */
export function showApiErrors(form, box, error, { lead = "Not created", keep = () => true } = {}) {
  const detail = error.body && error.body.detail;
  const rest = [];
  let first = null;
  if (Array.isArray(detail)) {
    for (const d of detail.filter(keep)) {
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
  box.textContent = rest.length ? `${lead}: ${rest.join("; ")}` : `${lead}: see the marked field.`;
  box.hidden = false;
  if (first) first.focus();
}
