"""Search for an expert: the best single response per camera obstacle stimulus, by simulation.

Coordinate descent over the nine camera stimuli: for each in turn, try every candidate
behaviour as its response (on top of the kp condition's design and the signal's responses,
no learning) and keep the one with the most successes over the tuning seeds; repeat until
a sweep changes nothing. It is how `core/data/networks/expert-paper.toml` was found, and it
tells how well any one-response-per-stimulus design can do with a sensor definition:

    .venv/bin/python scripts/expert_search.py --sensors paper
    .venv/bin/python scripts/expert_search.py --sensors path --start expert

The tuning seeds (1000 and up by default) are ones the experiments never use. It prints
each step and, at the end, the associations in the data files' TOML form.
"""

from __future__ import annotations

import argparse
import sys
from concurrent.futures import ProcessPoolExecutor
from functools import partial

from core.brain.catalog import AssociationSpec
from core.brain.network import BehaviourNetwork
from core.run.conditions import get_condition
from core.run.runner import run
from core.run.setup import Setup, network_specs
from core.run.simulation import Simulation

CANDIDATES = (
    "goforward3",
    "leftturn15",
    "leftturn30",
    "leftturn45",
    "leftturn60",
    "rightturn15",
    "rightturn30",
    "rightturn45",
    "rightturn60",
)
CAMERA = "camera_obstacle"


def score(
    assignment: tuple[tuple[str, str], ...],
    world: str,
    sensors: str,
    seeds: tuple[int, ...],
    episodes: int,
) -> float:
    """Success rate of the kp design plus the signal's responses plus `assignment`."""
    setup = Setup(world, sensors, "given")
    catalog = setup.catalog()
    condition = setup.condition(get_condition("reflexes"))
    specs = (
        *network_specs(catalog, condition),
        *(AssociationSpec(s, b, 1.0, "expert") for s, b in assignment),
    )
    successes = total = 0
    for seed in seeds:
        sim = Simulation(
            condition,
            seed,
            catalog=catalog,
            world_config=setup.world_config(),
            network=BehaviourNetwork.from_specs(catalog, specs),
        )
        summary = run(condition, seed, episodes, simulation=sim)
        successes += summary.successes
        total += len(summary.episodes)
    return successes / total


def main(argv: list[str] | None = None) -> int:
    """Run the search the arguments describe."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--world", default="", help="world preset (default: the default)")
    parser.add_argument("--sensors", default="", help="sensor definition (default: the default)")
    parser.add_argument("--seeds", type=int, default=10, help="tuning seeds (default 10)")
    parser.add_argument("--seed-base", type=int, default=1000, help="first seed (default 1000)")
    parser.add_argument("--episodes", type=int, default=30, help="episodes a seed (default 30)")
    parser.add_argument(
        "--start",
        default="",
        help="start from this knowledge set's camera responses (default: goforward3 for all)",
    )
    parser.add_argument("--jobs", type=int, default=2, help="processes (default 2)")
    args = parser.parse_args(argv)
    setup = Setup(args.world, args.sensors).resolved()
    catalog = setup.catalog()
    stimuli = [s.name for s in catalog.stimuli if s.sensor == CAMERA]
    current = dict.fromkeys(stimuli, "goforward3")
    if args.start:
        for a in catalog.knowledge_set(catalog.network_name(args.start)).associations:
            if a.stimulus in current:
                current[a.stimulus] = a.behaviour
    seeds = tuple(range(args.seed_base, args.seed_base + args.seeds))
    evaluate = partial(
        score, world=setup.world_name, sensors=setup.sensors_name, seeds=seeds,
        episodes=args.episodes,
    )  # fmt: skip
    best = evaluate(tuple(current.items()))
    out = sys.stdout
    out.write(f"world {setup.world_name}, sensors {setup.sensors_name}: start {best:.1%}\n")
    with ProcessPoolExecutor(args.jobs) as pool:
        changed = True
        sweep = 0
        while changed:
            changed = False
            sweep += 1
            for s in stimuli:
                trials = [dict(current, **{s: b}) for b in CANDIDATES]
                scores = list(pool.map(evaluate, [tuple(t.items()) for t in trials]))
                i = max(range(len(CANDIDATES)), key=lambda k: scores[k])
                if scores[i] > best + 1e-9:
                    current, best, changed = trials[i], scores[i], True
                row = " ".join(f"{b}={x:.0%}" for b, x in zip(CANDIDATES, scores, strict=True))
                out.write(f"sweep {sweep} {s}: {current[s]} ({best:.1%}); {row}\n")
                out.flush()
    out.write(f"best {best:.1%}:\n")
    for s in stimuli:
        out.write(f'    {{ stimulus = "{s}", behaviour = "{current[s]}" }},\n')
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
