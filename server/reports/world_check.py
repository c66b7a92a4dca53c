"""`srlab world-check --out`'s files: world-check.json and world-check.md."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from server.reports.base import clean_json, interval_line


def write_world_check(out: Path, report: dict[str, Any]) -> list[Path]:
    """Write the checks' JSON (no NaN) and their tables into `out`; returns the paths."""
    out.mkdir(parents=True, exist_ok=True)
    report = clean_json(report)
    paths = [out / "world-check.json", out / "world-check.md"]
    paths[0].write_text(json.dumps(report, indent=2) + "\n")
    paths[1].write_text(world_check_markdown(report))
    return paths


def world_check_markdown(report: dict[str, Any]) -> str:
    """`srlab world-check --out`'s tables: each property's success with its interval."""
    lines = [
        "# srlab world-check",
        "",
        f"`{report.get('command', 'srlab world-check')}`",
        "",
        f"{report['seeds']} seeds (from {report['seed_base']}) x {report['episodes']} episodes "
        "per property, no learning anywhere; success is the mean over seeds with its 95% "
        "interval.",
        "",
        interval_line(),
    ]
    described: set[str] = set()
    for check in report["checks"]:
        lines += [
            "",
            f"## World `{check['world']}`, camera stimuli `{check['sensors']}`: "
            + ("every property holds" if check["holds"] else "not every property holds"),
            "",
        ]
        if check["world"] not in described:
            described.add(check["world"])
            lines += [check["reasons"].replace("\n", " "), ""]
        lines += [
            "| | property | condition | success [95% CI] | bounds | holds |",
            "|---|---|---|---|---|---|",
        ]
        for p in check["properties"]:
            s = p["success"]
            ci = "" if s["low"] != s["low"] else f" [{100 * s['low']:.0f}, {100 * s['high']:.0f}]"
            lines.append(
                f"| ({p['key']}) | {p['label']} | {p['condition']}"
                f"{' + signal' if p['signal'] == 'given' else ''} | {100 * s['mean']:.0f}%{ci} | "
                f"{100 * p['bounds'][0]:.0f}-{100 * p['bounds'][1]:.0f}% | "
                f"{'yes' if p['holds'] else '**no**'} |"
            )
    return "\n".join(lines) + "\n"
