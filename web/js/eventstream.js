// A run's server-sent events read with fetch, so the request carries this tab's token
// (`Authorization: Bearer`, which EventSource cannot send; a token never goes in a URL).
// It answers as the console used EventSource: listeners per event name, `onerror` once
// when the stream ends, fails or is refused, and `close()`. Like the EventSource it
// replaces, it does not reconnect by itself: whoever follows the run decides (the stream
// carries no event ids, so there is no `Last-Event-ID` to resume from; a new stream starts
// with a `status` event, and what came between is read from the store).

import { authHeaders } from "./api.js";

export class EventStream {
  constructor(url) {
    this.url = url;
    this.onerror = null;
    this.closed = false;
    this.listeners = new Map();
    this.abort = new AbortController();
    this.read();
  }

  addEventListener(name, fn) {
    if (!this.listeners.has(name)) this.listeners.set(name, []);
    this.listeners.get(name).push(fn);
  }

  close() {
    this.closed = true;
    this.abort.abort();
  }

  async read() {
    try {
      const response = await fetch(this.url, {
        headers: { Accept: "text/event-stream", ...authHeaders() },
        cache: "no-store",
        signal: this.abort.signal,
      });
      if (!response.ok || !response.body) throw new Error(`the stream answered ${response.status}`);
      const reader = response.body.pipeThrough(new TextDecoderStream()).getReader();
      let buffered = "";
      for (;;) {
        const { value, done } = await reader.read();
        if (done) break;
        buffered += value;
        // Events end with a blank line (the service writes "\n"; "\r\n" is allowed too).
        const blocks = buffered.split(/\r?\n\r?\n/);
        buffered = blocks.pop();
        for (const block of blocks) this.dispatch(block);
      }
    } catch {
      // Refused, cut or closed: said once below, as EventSource's error.
    }
    if (!this.closed && this.onerror) this.onerror();
  }

  dispatch(block) {
    let name = "message";
    const data = [];
    for (const line of block.split(/\r?\n/)) {
      if (!line || line.startsWith(":")) continue; // a heartbeat or a comment
      const at = line.indexOf(":");
      const field = at < 0 ? line : line.slice(0, at);
      const value = at < 0 ? "" : line.slice(at + 1).replace(/^ /, "");
      if (field === "event") name = value;
      else if (field === "data") data.push(value);
    }
    if (!data.length || this.closed) return;
    const event = { type: name, data: data.join("\n") };
    for (const fn of this.listeners.get(name) || []) fn(event);
  }
}
