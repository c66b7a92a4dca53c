// Small DOM helpers shared by the editor and the console.

import { onReachability } from "./api.js";

/** Build an element: el("div", {class: "x", onclick: fn}, child, "text", ...). */
export function el(tag, attrs = {}, ...children) {
  const node = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs)) {
    if (v === undefined || v === null || v === false) continue;
    if (k.startsWith("on")) node.addEventListener(k.slice(2), v);
    else if (k === "class") node.className = v;
    else if (k === "text") node.textContent = v;
    else if (k === "dataset") Object.assign(node.dataset, v);
    else node.setAttribute(k, v === true ? "" : String(v));
  }
  for (const child of children.flat()) {
    if (child === undefined || child === null || child === false) continue;
    node.append(child instanceof Node ? child : document.createTextNode(String(child)));
  }
  return node;
}

const SVG_NS = "http://www.w3.org/2000/svg";

/** Build an SVG element: svg("line", {x1: 0, ...}) or svg("text", {...}, "label"). */
export function svg(tag, attrs = {}, text) {
  const node = document.createElementNS(SVG_NS, tag);
  for (const [k, v] of Object.entries(attrs)) node.setAttribute(k, String(v));
  if (text !== undefined) node.textContent = text;
  return node;
}

export const $ = (selector, root = document) => root.querySelector(selector);
export const $$ = (selector, root = document) => [...root.querySelectorAll(selector)];

const TOAST_MS = { error: 15000, other: 4000 };

/**
 * A message in the corner: kind is "error", "ok" or "" (info). The same message again
 * does not pile up: the one shown counts it ("×3") and its time starts over. With
 * `offline`, it is about the service not answering and goes when the service is back.
 */
export function toast(message, kind = "", { offline = false } = {}) {
  const box = $("#toasts");
  const same = [...box.children].find((t) => t.dataset.kind === kind && t.dataset.message === message);
  if (same) {
    same.dataset.count = String(Number(same.dataset.count || 1) + 1);
    $(".count", same).textContent = `×${same.dataset.count}`;
    clearTimeout(Number(same.dataset.timer));
    same.dataset.timer = String(setTimeout(() => same.remove(), TOAST_MS[kind === "error" ? "error" : "other"]));
    box.append(same); // the newest last
    return same;
  }
  const close = el("button", { type: "button", "aria-label": "Dismiss", text: "✕" });
  const node = el("div", {
    class: `toast ${kind}${offline ? " offline" : ""}`,
    role: kind === "error" ? "alert" : "status",
    dataset: { kind, message },
  }, el("span", { class: "msg", text: message }), el("span", { class: "count" }), close);
  close.addEventListener("click", () => node.remove());
  box.append(node);
  while (box.children.length > 4) box.firstElementChild.remove();
  node.dataset.timer = String(setTimeout(() => node.remove(), TOAST_MS[kind === "error" ? "error" : "other"]));
  return node;
}

/** Take down the messages about the service not answering (it answers again). */
export function clearOfflineToasts() {
  for (const node of $$("#toasts .toast.offline")) node.remove();
}

onReachability((online) => {
  if (online) clearOfflineToasts();
});

/** Run `fn`; show its ApiError as a toast and return undefined instead of throwing. */
export async function attempt(fn, what) {
  try {
    return await fn();
  } catch (error) {
    toast(what ? `${what}: ${error.message}` : error.message, "error", { offline: error.status === 0 });
    return undefined;
  }
}

export function fmt(value, digits = 2) {
  return value === null || value === undefined ? "—" : Number(value).toFixed(digits);
}

/** A color from white to deep green for x in [0, 1], and a readable ink for it. */
export function heat(x) {
  const t = Math.max(0, Math.min(1, x));
  const r = Math.round(255 + (14 - 255) * t);
  const g = Math.round(255 + (122 - 255) * t);
  const b = Math.round(255 + (58 - 255) * t);
  return { bg: `rgb(${r},${g},${b})`, ink: t > 0.55 ? "#fff" : "#1b1f27" };
}

/** Call `fn` at most once per `ms`, the last call winning. */
export function throttle(fn, ms) {
  let timer = null;
  let last = 0;
  return (...args) => {
    const wait = last + ms - Date.now();
    clearTimeout(timer);
    if (wait <= 0) {
      last = Date.now();
      fn(...args);
    } else {
      timer = setTimeout(() => {
        last = Date.now();
        fn(...args);
      }, wait);
    }
  };
}

/** Whether a key event comes from a text field (shortcuts leave those alone). */
export function typing(event) {
  const t = event.target;
  return t instanceof HTMLElement && (t.isContentEditable || ["INPUT", "TEXTAREA", "SELECT"].includes(t.tagName));
}
