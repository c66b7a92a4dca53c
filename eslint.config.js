// ESLint for the web client (`make lint` runs it): the recommended rules, on ES modules
// served as they are to the browser, and on their node tests.
import js from "@eslint/js";
import globals from "globals";

export default [
  // Only the client and this file: the rest of the tree (.venv, node_modules, ...) is not ours.
  { ignores: ["**/*", "!web/", "!web/**/", "!web/**/*.js", "!eslint.config.js"] },
  js.configs.recommended,
  {
    files: ["web/js/**/*.js"],
    languageOptions: { ecmaVersion: 2024, sourceType: "module", globals: globals.browser },
  },
  {
    files: ["web/test/**/*.js", "eslint.config.js"],
    languageOptions: { ecmaVersion: 2024, sourceType: "module", globals: globals.node },
  },
  {
    rules: {
      "no-unused-vars": ["error", { args: "after-used", caughtErrors: "none" }],
      eqeqeq: ["error", "always"],
      "prefer-const": "error",
      "no-var": "error",
    },
  },
];
