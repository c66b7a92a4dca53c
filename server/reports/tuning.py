"""`srlab tune --out`'s files: tuning.json and tuning.md, every learner's grid best first."""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from pathlib import Path

from core.lab.tune import GRIDS, TunedPoint
from core.run.setup import Setup
from server.reports.base import head, row, setup_params


def write_tuning(
    out: Path,
    rows: Mapping[str, Sequence[TunedPoint]],
    *,
    command: str,
    seeds: Sequence[int],
    episodes: int,
    elapsed_s: float,
    setup: Setup,
) -> list[Path]:
    """Write every learner's points with their success into `out`; returns the paths."""
    out.mkdir(parents=True, exist_ok=True)
    paths = [out / "tuning.json", out / "tuning.md"]
    doc = {
        "command": command, "seeds": list(seeds), "episodes": episodes, "elapsed_s": elapsed_s,
        **setup_params(setup),
        "learners": {
            c: [{"point": p.point, "success": p.success, "per_seed": p.per_seed} for p in points]
            for c, points in rows.items()
        },
    }  # fmt: skip
    paths[0].write_text(json.dumps(doc, indent=1) + "\n")
    lines = [
        "# srlab tune", "", f"`{command}`", "",
        f"Every learner's grid on tuning seeds {seeds[0]}-{seeds[-1]} x {episodes} episodes "
        f"(world {setup.world_name}, sensors {setup.sensors_name}, signal {setup.signal}), "
        f"{elapsed_s:.0f} s. Mean success over the tuning seeds, best first.",
    ]  # fmt: skip
    for c, points in rows.items():
        names = [n for n, _ in GRIDS[c]]
        lines += ["", f"## {c}", "", *head([*names, "success"])]
        lines += [row([*(f"{p.point[n]:g}" for n in names), f"{p.success:.1%}"]) for p in points]
    paths[1].write_text("\n".join(lines) + "\n")
    return paths
