// The HTTP API, with errors turned into sentences a person can act on.

const TOKEN_KEY = "srlab.token";
// A study participant's token, from their link: this tab's only (sessionStorage), so the
// organiser's own tabs in the same browser keep the organiser's token.
const PARTICIPANT_KEY = "srlab.participant";

/** An API call that failed: `status` 0 means the service did not answer. */
export class ApiError extends Error {
  constructor(status, message, body = null) {
    super(message);
    this.status = status;
    this.body = body;
  }
}

export function token() {
  return localStorage.getItem(TOKEN_KEY) || "";
}

export function setToken(value) {
  if (value) localStorage.setItem(TOKEN_KEY, value);
  else localStorage.removeItem(TOKEN_KEY);
}

/** The participant's token this tab holds ("" when it is not a participant's page). */
export function participantToken() {
  return sessionStorage.getItem(PARTICIPANT_KEY) || "";
}

export function setParticipantToken(value) {
  if (value) sessionStorage.setItem(PARTICIPANT_KEY, value);
  else sessionStorage.removeItem(PARTICIPANT_KEY);
}

/**
 * The bearer a request carries: a participant's token on every request (their reads are
 * held to their own run by it); else the organiser's saved token, on reads too (a service
 * with `SRLAB_READS=token` answers reads only to a token).
 */
function bearer() {
  return participantToken() || token();
}

/** The headers that carry this tab's token (none when it holds none). */
export function authHeaders() {
  const given = bearer();
  return given ? { Authorization: `Bearer ${given}` } : {};
}

const listeners = new Set();

/** Call `fn(online)` whenever a request finds the service up or down. */
export function onReachability(fn) {
  listeners.add(fn);
}

function reachable(online) {
  for (const fn of listeners) fn(online);
}

/** FastAPI's error body as one line: 422s name the field. */
export function describe(status, body) {
  const detail = body && body.detail;
  if (Array.isArray(detail)) {
    return detail
      .map((e) => {
        const where = (e.loc || []).filter((p) => p !== "body" && p !== "query" && p !== "path");
        return where.length ? `${where.join(".")}: ${e.msg}` : e.msg;
      })
      .join("; ");
  }
  if (typeof detail === "string" && detail) return detail;
  if (status === 401) return "This service needs its access token: set it with ⚙ token.";
  return `The service answered ${status}.`;
}

/**
 * `method` `path` (under /api) with an optional JSON `body` and `query` parameters.
 * Resolves to the parsed JSON (null for 204); rejects with an ApiError.
 */
export async function api(method, path, { body, query, raw = false } = {}) {
  const url = new URL(`/api${path}`, location.origin);
  for (const [k, v] of Object.entries(query || {})) {
    if (v !== undefined && v !== null && v !== "") url.searchParams.set(k, String(v));
  }
  const headers = authHeaders();
  if (body !== undefined) headers["Content-Type"] = "application/json";
  let response;
  try {
    response = await fetch(url, {
      method,
      headers,
      body: body === undefined ? undefined : JSON.stringify(body),
    });
  } catch {
    reachable(false);
    throw new ApiError(0, "The service is not answering; check that `srlab serve` is running.");
  }
  reachable(true);
  if (raw && response.ok) return response;
  if (response.status === 204) return null;
  let parsed = null;
  try {
    parsed = await response.json();
  } catch {
    parsed = null;
  }
  if (!response.ok) throw new ApiError(response.status, describe(response.status, parsed), parsed);
  return parsed;
}

export const get = (path, query) => api("GET", path, { query });
export const post = (path, body, query) => api("POST", path, { body, query });
export const put = (path, body, query) => api("PUT", path, { body, query });
export const del = (path, query) => api("DELETE", path, { query });

/** A path segment, escaped. */
export const seg = (s) => encodeURIComponent(s);

/** Every item of a paged list (`{data, count}`), a page of `limit` at a time. */
export async function getAll(path, limit = 1000) {
  const data = [];
  for (;;) {
    const page = await get(path, { limit, offset: data.length });
    data.push(...page.data);
    if (!page.data.length || data.length >= page.count) return { data, count: page.count };
  }
}
