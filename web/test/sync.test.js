// The editor's sync queue (web/js/editor/sync.js) against a scripted service: the order
// of writes, version conflicts (412), the outbox while the service is away, undo and redo.
// Run with `node --test web/test/`.

import assert from "node:assert/strict";
import { describe, it } from "node:test";

import { SyncQueue, describeCell, lockRefusal, same } from "../js/editor/sync.js";

const dp = (strength, locked = false) => ({ strength, source: "dp", locked });
const key = (s, b) => `${s}|${b}`;

/**
 * A network on a pretend server, and the page's view of it. `answers` scripts what the
 * next sends answer ("stale", "offline", "error"; by default "ok"); `elsewhere(cells)`
 * changes the server as another writer would.
 */
function harness({ answers = [], confirm = true, builtin = false } = {}) {
  const server = { version: 1, cells: new Map() };
  const page = { net: { name: "mine", version: 1, builtin }, cells: new Map() };
  const log = { sent: [], notes: [], changed: [], asked: [], selected: [], reloads: 0 };
  const read = () => {
    page.net = { ...page.net, version: server.version };
    page.cells = new Map(server.cells);
  };
  const ports = {
    network: () => page.net,
    stored: (s, b) => page.cells.get(key(s, b)) ?? null,
    async send(op) {
      log.sent.push(op);
      const answer = answers.shift() ?? "ok";
      if (answer !== "ok") return answer;
      if (op.after === null) server.cells.delete(key(op.s, op.b));
      else server.cells.set(key(op.s, op.b), op.after);
      server.version += 1;
      read();
      return "ok";
    },
    async reload() {
      log.reloads += 1;
      read();
    },
    async ask(op, now) {
      log.asked.push({ op, now });
      return confirm;
    },
    select: (s, b) => log.selected.push(key(s, b)),
    notify: (message, kind) => log.notes.push({ message, kind }),
    changed: (what) => log.changed.push(what),
  };
  const elsewhere = (change) => {
    change(server.cells);
    server.version += 1;
  };
  return { sync: new SyncQueue(ports), server, page, log, elsewhere, read };
}

const edit = (page, s, b, before, after) => ({ s, b, before, after, force: false, note: "", based: page.net.version });

describe("the queue", () => {
  it("runs jobs one at a time in the order queued, past a job that fails", async () => {
    const { sync } = harness();
    const seen = [];
    const slow = () => new Promise((r) => setTimeout(() => r(seen.push("slow")), 20));
    sync.enqueue(slow);
    sync.enqueue(() => {
      seen.push("fails");
      throw new Error("boom");
    });
    await sync.enqueue(() => seen.push("last"));
    assert.deepEqual(seen, ["slow", "fails", "last"]);
  });

  it("counts a committed change as unsaved until it is written", async () => {
    const { sync, page } = harness();
    const done = sync.commit(edit(page, "Red", "stop", null, dp(0.5)));
    assert.deepEqual(sync.unsaved("Red", "stop").kind, "draft");
    assert.deepEqual(sync.settled("Red", "stop"), dp(0.5));
    await done;
    assert.equal(sync.unsaved("Red", "stop"), null);
    assert.deepEqual(sync.settled("Red", "stop"), dp(0.5), "now from the server");
  });
});

describe("writing", () => {
  it("stores an edit, notes its version as ours and makes it undoable", async () => {
    const { sync, page, server, log } = harness();
    assert.equal(await sync.write(edit(page, "Red", "stop", null, dp(0.9)), "edit"), true);
    assert.deepEqual(server.cells.get("Red|stop"), dp(0.9));
    assert.equal(page.net.version, 2);
    assert.ok(sync.mine.has(2));
    assert.deepEqual(sync.undo, [{ s: "Red", b: "stop", before: null, after: dp(0.9) }]);
    assert.deepEqual(log.changed, ["undo"]);
    assert.deepEqual(log.notes, []);
  });

  it("retries after a 412 once the network is read again, on top of another cell's change", async () => {
    const { sync, page, log, elsewhere } = harness({ answers: ["stale"] });
    const op = edit(page, "Red", "stop", null, dp(0.9));
    elsewhere((cells) => cells.set("Green|goforward1", dp(1))); // v2, another cell
    assert.equal(await sync.write(op, "edit"), true);
    assert.equal(log.reloads, 1);
    assert.equal(log.sent.length, 2);
    assert.equal(page.net.version, 3);
    assert.match(log.notes[0].message, /on top of the change made elsewhere \(v2\)/);
  });

  it("gives up after four 412s in a row", async () => {
    const { sync, page, log } = harness({ answers: ["stale", "stale", "stale", "stale", "ok"] });
    assert.equal(await sync.write(edit(page, "Red", "stop", null, dp(0.9)), "edit"), false);
    assert.equal(log.sent.length, 4);
    assert.deepEqual(sync.undo, []);
  });

  it("asks before reapplying an edit whose cell changed elsewhere", async () => {
    const { sync, page, server, log, elsewhere, read } = harness();
    const op = edit(page, "Red", "stop", null, dp(0.9));
    elsewhere((cells) => cells.set("Red|stop", dp(0.2)));
    read();
    assert.equal(await sync.write(op, "edit"), true);
    assert.deepEqual(log.asked, [{ op, now: dp(0.2) }]);
    assert.deepEqual(log.sent.at(-1), { ...op, before: dp(0.2), force: true, based: 2 });
    assert.deepEqual(server.cells.get("Red|stop"), dp(0.9));
  });

  it("keeps the other writer's change when the person says no", async () => {
    const { sync, page, server, log, elsewhere, read } = harness({ confirm: false });
    const op = edit(page, "Red", "stop", null, dp(0.9));
    elsewhere((cells) => cells.set("Red|stop", dp(0.2)));
    read();
    assert.equal(await sync.write(op, "edit"), false);
    assert.deepEqual(log.sent, []);
    assert.deepEqual(server.cells.get("Red|stop"), dp(0.2));
    assert.deepEqual(log.notes.at(-1), { message: "Your change to Red → stop was not saved: the editor shows version 2.", kind: "error" });
  });

  it("refuses an undo whose cell changed elsewhere, without asking", async () => {
    const { sync, page, log, elsewhere, read } = harness();
    await sync.write(edit(page, "Red", "stop", null, dp(0.9)), "edit");
    elsewhere((cells) => cells.set("Red|stop", dp(0.3, true)));
    read();
    await sync.replay("undo");
    assert.deepEqual(log.asked, []);
    assert.equal(log.sent.length, 1);
    assert.equal(sync.undo.length, 0, "a refused undo is dropped");
    assert.equal(sync.redo.length, 0);
    assert.equal(log.notes.at(-1).message, "Red → stop was changed elsewhere (now 0.30 dp locked): undoing would overwrite that change, so it was not undone.");
  });

  it("undoes and redoes as new versions, moving the change between the stacks", async () => {
    const { sync, page, server, log } = harness();
    await sync.write(edit(page, "Red", "stop", null, dp(0.9)), "edit");
    await sync.replay("undo");
    assert.equal(server.cells.has("Red|stop"), false);
    assert.equal(server.version, 3);
    assert.equal(log.sent.at(-1).note, "undo");
    assert.deepEqual([sync.undo.length, sync.redo.length], [0, 1]);
    await sync.replay("redo");
    assert.deepEqual(server.cells.get("Red|stop"), dp(0.9));
    assert.deepEqual([sync.undo.length, sync.redo.length], [1, 0]);
    assert.deepEqual(log.selected, ["Red|stop", "Red|stop"]);
  });
});

describe("while the service is away", () => {
  it("keeps changes in the outbox, in order, and sends them when it is back", async () => {
    const { sync, page, server, log } = harness({ answers: ["offline"] });
    assert.equal(await sync.write(edit(page, "Red", "stop", null, dp(0.5)), "edit"), "kept");
    // Later changes queue behind it without trying the service.
    assert.equal(await sync.write(edit(page, "Red", "stop", dp(0.5), dp(0.7)), "edit"), "kept");
    assert.equal(log.sent.length, 1);
    assert.equal(sync.busy(), true);
    assert.deepEqual(sync.unsaved("Red", "stop").kind, "waiting");
    assert.deepEqual(sync.settled("Red", "stop"), dp(0.7));
    assert.equal(log.notes.length, 1, "one note for the first change kept");
    await sync.flush();
    assert.deepEqual(sync.outbox, []);
    assert.deepEqual(server.cells.get("Red|stop"), dp(0.7));
    assert.equal(server.version, 3);
    assert.deepEqual(log.changed, ["kept", "kept", "undo", "undo", "flush"]);
    assert.equal(sync.undo.length, 2);
  });

  it("stops a flush at the first change the service still cannot take", async () => {
    const { sync, page } = harness({ answers: ["offline", "offline"] });
    await sync.write(edit(page, "Red", "stop", null, dp(0.5)), "edit");
    await sync.flush();
    assert.equal(sync.outbox.length, 1);
    await sync.flush();
    assert.equal(sync.outbox.length, 0);
  });
});

describe("changing a cell", () => {
  it("writes nothing when the cell would not change", async () => {
    const { sync, log } = harness();
    assert.equal(await sync.change("Red", "stop", null), false);
    assert.deepEqual(log.sent, []);
  });

  it("refuses a built-in network", async () => {
    const { sync, log } = harness({ builtin: true });
    assert.equal(await sync.change("Red", "stop", dp(1)), false);
    assert.deepEqual(log.sent, []);
    assert.match(log.notes[0].message, /built in and read-only/);
  });

  it("refuses to change a locked association other than unlocking it", async () => {
    const { sync, log, server, read } = harness();
    server.cells.set("Red|stop", dp(0.4, true));
    read();
    assert.equal(await sync.change("Red", "stop", dp(0.8, true)), false);
    assert.match(log.notes[0].message, /is locked: unlock it first/);
    assert.equal(await sync.change("Red", "stop", dp(0.4, false), { note: "unlock" }), true);
    assert.equal(log.sent[0].force, true);
    assert.equal(log.sent[0].note, "unlock");
  });
});

describe("the helpers", () => {
  it("compare and describe cells", () => {
    assert.equal(same(null, null), true);
    assert.equal(same(dp(0.5), null), false);
    assert.equal(same(dp(0.5), dp(0.5)), true);
    assert.equal(same(dp(0.5), dp(0.5, true)), false);
    assert.equal(describeCell(null), "none");
    assert.equal(describeCell(dp(0.25, true)), "0.25 dp locked");
    assert.equal(lockRefusal("Red", "stop", dp(0.4), null), "");
    assert.equal(lockRefusal("Red", "stop", dp(0.4, true), dp(0.4)), "");
    assert.match(lockRefusal("Red", "stop", dp(0.4, true), null), /locked/);
  });
});
