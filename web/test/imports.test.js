// Every named import between the web client's modules names an export of the module it
// comes from: a browser refuses the whole page otherwise, and ESLint does not look.

import assert from "node:assert/strict";
import { readFileSync, readdirSync } from "node:fs";
import { dirname, join, relative, resolve } from "node:path";
import { it } from "node:test";
import { fileURLToPath } from "node:url";

const WEB = resolve(dirname(fileURLToPath(import.meta.url)), "..");

function modules(dir) {
  return readdirSync(dir, { withFileTypes: true }).flatMap((entry) =>
    entry.isDirectory() ? modules(join(dir, entry.name)) : entry.name.endsWith(".js") ? [join(dir, entry.name)] : []);
}

/** The names a module exports: declarations and `export { a, b as c }` lists. */
function exported(source) {
  const names = new Set();
  for (const m of source.matchAll(/^export\s+(?:async\s+)?(?:function\*?|const|let|class)\s+([\w$]+)/gm)) names.add(m[1]);
  for (const m of source.matchAll(/^export\s*\{([^}]*)\}/gm)) {
    for (const part of m[1].split(",")) {
      const name = part.trim().split(/\s+as\s+/).pop();
      if (name) names.add(name);
    }
  }
  return names;
}

/**
 * `[names, path]` of each relative import of a module: `import { a, b as c } from` names
 * a and b; `import * as ns from` names what the module reads as `ns.name`.
 */
function imports(text) {
  const source = text.replace(/\/\*[\s\S]*?\*\//g, "").replace(/\/\/.*$/gm, ""); // comments say "cells.js" too
  const named = [...source.matchAll(/^import\s*\{([^}]*)\}\s*from\s*"(\.[^"]+)"/gm)].map((m) => [
    m[1].split(",").map((part) => part.trim().split(/\s+as\s+/)[0]).filter(Boolean),
    m[2],
  ]);
  const spaces = [...source.matchAll(/^import\s*\*\s*as\s+([\w$]+)\s+from\s*"(\.[^"]+)"/gm)].map((m) => [
    [...new Set([...source.matchAll(new RegExp(`(?<![\\w$./])${m[1].replace("$", "\\$")}\\.([\\w$]+)`, "g"))].map((u) => u[1]))],
    m[2],
  ]);
  return [...named, ...spaces];
}

it("imports only names the imported module exports", () => {
  const files = modules(join(WEB, "js"));
  assert.ok(files.length > 10, "the client's modules were found");
  const missing = [];
  for (const file of files) {
    for (const [names, path] of imports(readFileSync(file, "utf8"))) {
      const target = resolve(dirname(file), path);
      const has = exported(readFileSync(target, "utf8"));
      for (const name of names) if (!has.has(name)) missing.push(`${relative(WEB, file)}: ${name} from ${path}`);
    }
  }
  assert.deepEqual(missing, []);
});
