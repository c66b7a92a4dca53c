// The editor's writes, in order and version-checked, with no DOM: what the page asks the
// service to store, and what happens when the service is away or another writer was first.
//
// Every change is one operation `op` = {s, b, before, after, force, note, based}: cell
// `s` -> `b` goes from `before` to `after` (an association {strength, source, locked}, or
// null for none) on top of version `based` of the network. Jobs run one at a time, in the
// order they were queued, so keystrokes are never dropped or reordered. A change is
// written only while the cell is still `before` on the server: a change of another cell
// elsewhere is kept and ours goes on top of it; if the cell itself changed, an edit asks
// first and an undo or redo is refused, so neither deletes another writer's change. While
// the service is away, changes wait in the outbox and are sent, in order, when it is back.
//
// The page supplies the rest through `ports`:
//   network()       the open network ({name, version, builtin}), or null
//   stored(s, b)    the cell as the page last read it from the server, or null
//   send(op)        write `op.after` to the cell: "ok", "stale" (the network moved on),
//                   "offline" or "error"; on "ok" the page's network and cells follow
//   reload()        read the network again (after "stale")
//   ask(op, now)    an edit's cell changed elsewhere (it is `now`): reapply it on top?
//   select(s, b)    an undo or redo is about to change this cell
//   notify(message, kind)   tell the person ("error" or "" for information)
//   changed(what)   redraw: "kept" (an op went to the outbox), "edit" (a queued edit is
//                   done), "flush" (the outbox was sent), "undo" (the stacks changed)

const ATTEMPTS = 4;

/** Whether two cells ({strength, source, locked} or null) are the same. */
export const same = (a, b) =>
  (a === null && b === null) ||
  (a !== null && b !== null && a.strength === b.strength && a.source === b.source && a.locked === b.locked);

/** A cell in words: "0.40 dp locked", "none". */
export const describeCell = (a) =>
  a === null ? "none" : `${Number(a.strength).toFixed(2)} ${a.source}${a.locked ? " locked" : ""}`;

/**
 * Why `before` -> `after` may not be made ("" if it may): a locked association only changes
 * its lock.
 */
export function lockRefusal(s, b, before, after) {
  const unlockOnly = before && after && before.locked && !after.locked &&
    before.strength === after.strength && before.source === after.source;
  if (before && before.locked && !unlockOnly) {
    return `${s} → ${b} is locked: unlock it first (L, or untick "locked" and Save).`;
  }
  return "";
}

export class SyncQueue {
  constructor(ports) {
    this.ports = ports;
    this.queue = Promise.resolve();
    this.outbox = []; // changes made while the service was away
    this.sending = []; // changes queued or being saved, oldest first
    this.mine = new Set(); // versions this page wrote
    this.undo = []; // this page's stored changes, newest last
    this.redo = [];
    this.pending = false; // a write is on the wire
  }

  /** Run `job` after every job queued before it, whether that one failed or not. */
  enqueue(job) {
    this.queue = this.queue.then(job, job);
    return this.queue;
  }

  /** Forget the undo and redo stacks (another network is open). */
  forget() {
    this.undo = [];
    this.redo = [];
  }

  /** Whether the page should not look for changes elsewhere now. */
  busy() {
    return this.pending || this.outbox.length > 0;
  }

  /**
   * A change of cell `s` -> `b` not stored yet, the newest: {op, kind} with kind "draft"
   * (queued or being saved) or "waiting" (in the outbox), or null.
   */
  unsaved(s, b) {
    for (const [list, kind] of [[this.sending, "draft"], [this.outbox, "waiting"]]) {
      for (let i = list.length - 1; i >= 0; i--) {
        if (list[i].s === s && list[i].b === b) return { op: list[i], kind };
      }
    }
    return null;
  }

  /** The cell as the server will have it once the changes kept in this page are sent. */
  settled(s, b) {
    const waiting = this.unsaved(s, b);
    return waiting ? waiting.op.after : this.ports.stored(s, b);
  }

  /** Queue `op` (a committed draft) as one version; it counts as unsaved until written. */
  commit(op) {
    this.sending.push(op);
    return this.enqueue(async () => {
      try {
        await this.write(op, "edit");
      } finally {
        this.sending.splice(this.sending.indexOf(op), 1);
      }
      this.ports.changed("edit");
    });
  }

  /**
   * Change cell `s` -> `b` to `next` (null removes it) as one version, after what is
   * queued. Resolves to true when it was stored.
   */
  change(s, b, next, { note = "" } = {}) {
    return this.enqueue(async () => {
      const net = this.ports.network();
      if (!net) return false;
      if (net.builtin) {
        this.ports.notify(`${net.name} is built in and read-only: copy it to edit it.`, "error");
        return false;
      }
      const before = this.settled(s, b);
      if (same(before, next)) return false;
      const refusal = lockRefusal(s, b, before, next);
      if (refusal) {
        this.ports.notify(refusal, "error");
        return false;
      }
      const op = { s, b, before, after: next, force: Boolean(before && before.locked), note, based: net.version };
      return (await this.write(op, "edit")) === true;
    });
  }

  /**
   * Store one change `op` made as `kind` ("edit", "undo", "redo" or "flush").
   * Answers true (stored), "kept" (the service is away: kept in this page), "offline"
   * (a flush found it still away), "refused" or false.
   */
  async write(op, kind) {
    if (!this.ports.network()) return false;
    if (this.outbox.length && kind !== "flush") return this.keep(op);
    for (let attempt = 0; attempt < ATTEMPTS; attempt++) {
      const now = this.ports.stored(op.s, op.b);
      if (!same(now, op.before)) return this.clash(op, kind, now);
      this.pending = true;
      let result;
      try {
        result = await this.ports.send(op);
      } finally {
        this.pending = false;
      }
      if (result === "ok") {
        this.stored(op, kind);
        return true;
      }
      if (result === "offline") return kind === "flush" ? "offline" : this.keep(op);
      if (result !== "stale") return false;
      await this.ports.reload(); // then look at the cell again
    }
    return false;
  }

  /** `op` was stored: note its version as ours, and say what it went on top of. */
  stored(op, kind) {
    const version = this.ports.network().version;
    const elsewhere = [];
    for (let v = op.based + 1; v < version; v++) if (!this.mine.has(v)) elsewhere.push(v);
    this.mine.add(version);
    if (elsewhere.length && kind === "edit") {
      this.ports.notify(`Saved ${op.s} → ${op.b} on top of the change${elsewhere.length > 1 ? "s" : ""} made elsewhere (v${elsewhere.join(", v")}); that cell had not changed.`, "");
    }
    if (kind === "edit" || kind === "flush") {
      this.undo.push({ s: op.s, b: op.b, before: op.before, after: op.after });
      this.redo = [];
      this.ports.changed("undo");
    }
  }

  keep(op) {
    if (!this.outbox.length) {
      this.ports.notify(`The service is away: your change to ${op.s} → ${op.b} is kept in this page and sent when it is back.`, "");
    }
    this.outbox.push(op);
    this.ports.changed("kept");
    return "kept";
  }

  /** Send the changes kept while the service was away, in order, each version-checked. */
  flush() {
    return this.enqueue(async () => {
      while (this.outbox.length && this.ports.network()) {
        const result = await this.write(this.outbox[0], "flush");
        if (result === "offline") return;
        this.outbox.shift();
      }
      if (this.ports.network()) this.ports.changed("flush");
    });
  }

  /** The cell changed elsewhere after `op` was made on it (`now` is how it is stored). */
  async clash(op, kind, now) {
    if (kind === "undo" || kind === "redo") {
      const [doing, done] = kind === "undo" ? ["undoing", "undone"] : ["redoing", "redone"];
      this.ports.notify(`${op.s} → ${op.b} was changed elsewhere (now ${describeCell(now)}): ${doing} would overwrite that change, so it was not ${done}.`, "error");
      return "refused";
    }
    const current = this.ports.network().version;
    if (!(await this.ports.ask(op, now))) {
      this.ports.notify(`Your change to ${op.s} → ${op.b} was not saved: the editor shows version ${current}.`, "error");
      return false;
    }
    if (same(now, op.after)) return true;
    return this.write({ ...op, before: now, force: true, based: current }, kind);
  }

  /**
   * Undo (`kind` "undo") or redo the last change of this page, only while its cell is as
   * the change left it. Written as a new version, so the history shows what happened.
   */
  replay(kind) {
    const [from, to] = kind === "undo" ? [this.undo, this.redo] : [this.redo, this.undo];
    return this.enqueue(async () => {
      const net = this.ports.network();
      const op = from.pop();
      if (!op || !net) return;
      this.ports.select(op.s, op.b);
      const [before, after] = kind === "undo" ? [op.after, op.before] : [op.before, op.after];
      const result = await this.write({ s: op.s, b: op.b, before, after, force: true, note: kind, based: net.version }, kind);
      if (result === true || result === "kept") to.push(op);
      else if (result !== "refused") from.push(op);
      this.ports.changed("undo");
    });
  }
}
