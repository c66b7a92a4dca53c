"""The sensor module's logical sensors: data-declared rules compiled into one function."""

from __future__ import annotations

from collections.abc import Callable, Sequence

from core.brain.catalog import Catalog, RuleCondition

StimulusDetector = Callable[[Sequence[float]], list[int]]


def _condition_source(c: RuleCondition) -> str:
    # Every piece is validated data: an int index, an operator from a closed set, a float
    # or another int index. A stale channel is NaN (a robot's topic gone quiet,
    # server.robots.ros2): every comparison with it is false, `!=` too, so it releases nothing.
    if c.other >= 0:
        source = f"c[{int(c.channel)}] {c.op} c[{int(c.other)}]"
        if c.op == "!=":
            source += f" and c[{int(c.channel)}] == c[{int(c.channel)}]"
            source += f" and c[{int(c.other)}] == c[{int(c.other)}]"
        return source
    source = f"c[{int(c.channel)}] {c.op} {float(c.value)!r}"
    if c.op == "!=":
        source += f" and c[{int(c.channel)}] == c[{int(c.channel)}]"
    return source


def compile_detector(catalog: Catalog) -> StimulusDetector:
    """Compile every logical sensor's rules into one function: channels -> active stimulus ids.

    The rules come from data files, so a new logical sensor needs no code; compiling them to
    a single Python function keeps the per-tick cost to a few comparisons per stimulus.
    """
    lines = ["def detect(c):", "    active = []"]
    for s in catalog.stimuli:
        alternatives = " or ".join(
            "(" + " and ".join(_condition_source(c) for c in alt) + ")" for alt in s.rule
        )
        lines.append(f"    if {alternatives}:")
        lines.append(f"        active.append({int(s.id)})")
    lines.append("    return active")
    namespace: dict[str, object] = {}
    exec(compile("\n".join(lines), "<srlab logical sensors>", "exec"), namespace)
    detect: StimulusDetector = namespace["detect"]  # type: ignore[assignment]
    return detect
