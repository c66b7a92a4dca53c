"""Experiments: conditions x seeds x episodes, run in parallel, summarised over seeds."""

from __future__ import annotations

import math
import traceback
from collections.abc import Callable, Generator, Iterable, Iterator, Sequence
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np

from core.brain.catalog import Catalog
from core.conditions import CONDITIONS, get_condition
from core.errors import UnknownNameError
from core.events import Cause, Outcome
from core.params import Params, configure, qlambda_config
from core.qlambda import run_qlambda
from core.runner import EpisodeSummary, run
from core.setup import Setup
from core.stats import paired_difference

CRITERION_WINDOW = 10
CRITERION_RATE = 0.8
CAMERA_SENSOR = "camera_obstacle"
DEFAULT_SETUP = Setup()


@dataclass(frozen=True, slots=True)
class Task:
    """One (condition, seed) run, with the learning parameters it sets (none: defaults).

    It runs in `setup`: a world, a sensor definition and a signal mode (the defaults
    unless given).
    """

    condition: str
    seed: int
    episodes: int
    params: Params = ()
    setup: Setup = DEFAULT_SETUP


@dataclass(frozen=True, slots=True)
class TaskResult:
    """A task's episodes and its final camera-stimulus reliabilities, or its error.

    `ltm` and `rltm` map "stimulus/behaviour" to the reliability, for the camera obstacle
    stimuli (the paper's Table III); `rltm` is empty unless KP ran. `programmed` holds the
    strengths of the camera pairs the condition's network was designed with (DP's S-R
    editor), which the paper's Table III shows as reliability 1.
    """

    task: Task
    episodes: tuple[EpisodeSummary, ...] = ()
    ticks: int = 0
    ltm: dict[str, float] = field(default_factory=dict)
    rltm: dict[str, float] = field(default_factory=dict)
    programmed: dict[str, float] = field(default_factory=dict)
    error: str | None = None
    ticks_by_origin: dict[str, int] = field(default_factory=dict)
    """Ticks by what made their behaviour run (see `core.runner.RunSummary`)."""
    camera_met: dict[str, tuple[int, int, int, int]] = field(default_factory=dict)
    """Per camera obstacle stimulus met: (ticks it was active, encounters, episodes it was
    met in, successes among those episodes)."""

    @property
    def ok(self) -> bool:
        """Whether the task ran to the end."""
        return self.error is None


def parse_conditions(text: str) -> list[str]:
    """A comma-separated list of known condition names, in order, without repeats."""
    names = [n.strip() for n in text.split(",") if n.strip()]
    if not names:
        raise UnknownNameError("no condition given")
    for n in names:
        get_condition(n)
    return list(dict.fromkeys(names))


def _camera_memory(
    catalog: Catalog, memory: Iterable[tuple[tuple[int, int], float]], behaviours: Sequence[str]
) -> dict[str, float]:
    camera = {s.id: s.name for s in catalog.stimuli if s.sensor == CAMERA_SENSOR}
    return {
        f"{camera[s]}/{behaviours[b]}": v
        for (s, b), v in memory
        if s in camera and v > 0.0 and b < len(behaviours)
    }


def run_task(task: Task, catalog: Catalog | None = None) -> TaskResult:
    """Run one task; any error is returned, not raised, so the others' results survive.

    A pure function of the task: the same task gives the same result in any process, on
    any machine running the same code.
    """
    try:
        setup = task.setup
        catalog = catalog or setup.catalog()
        condition = setup.condition(get_condition(task.condition))
        if condition.agent == "qlambda":
            from core.envs import AmigoTrackEnv

            config = qlambda_config(condition, task.params)
            env = AmigoTrackEnv(
                prior=config.prior,
                learnable=condition.learnable_sensors,
                world_config=setup.world_config(),
                catalog=catalog,
                extra_networks=condition.extra_networks,
            )
            episodes, _, ticks = run_qlambda(task.seed, task.episodes, config, env=env)
            return TaskResult(task, tuple(episodes), ticks)
        from core.simulation import Simulation

        condition, brain_config = configure(condition, task.params)
        sim = Simulation(
            condition,
            task.seed,
            catalog=catalog,
            world_config=setup.world_config(),
            brain_config=brain_config,
        )
        camera = [st.id for st in catalog.stimuli if st.sensor == CAMERA_SENSOR]
        met_in = dict.fromkeys(camera, 0)
        won_in = dict.fromkeys(camera, 0)

        def tally(e: EpisodeSummary) -> None:
            won = e.outcome is Outcome.SUCCESS
            for s in camera:
                if s in sim.met_this_episode:
                    met_in[s] += 1
                    won_in[s] += won

        summary = run(condition, task.seed, task.episodes, simulation=sim, on_episode=tally)
        names = [b.name for b in sim.brain.catalog.behaviours]
        rltm = sim.brain.kp.rltm.items() if sim.brain.kp is not None else ()
        designed = (
            ((a.stimulus, a.behaviour), a.strength)
            for a in sim.brain.network
            if a.source not in ("learned", "kp")
        )
        return TaskResult(
            task,
            summary.episodes,
            summary.ticks,
            _camera_memory(catalog, sim.brain.ltm.items(), names),
            _camera_memory(catalog, rltm, names),
            _camera_memory(catalog, designed, names),
            ticks_by_origin=summary.ticks_by_origin,
            camera_met={
                catalog.stimuli[s].name: (
                    sim.stimulus_ticks[s],
                    sim.encounters[s],
                    met_in[s],
                    won_in[s],
                )
                for s in camera
                if sim.encounters[s]
            },
        )
    except Exception as e:  # a failed task is reported with its seed, never lost silently
        return TaskResult(task, error=f"{type(e).__name__}: {e}\n{traceback.format_exc()}")


TaskFunction = Callable[[Task], TaskResult]


class Backend(Protocol):
    """Where tasks run: local processes (`LocalBackend`) or a cluster (server's Ray backend).

    Results may come in any order; `run_tasks` puts them back in the tasks' order.
    """

    def run(self, tasks: Sequence[Task], fn: TaskFunction = run_task) -> Iterator[TaskResult]:
        """Run `fn` on every task, yielding each result as it is done."""
        ...


@dataclass(frozen=True, slots=True)
class LocalBackend:
    """`jobs` processes on this machine (1: in this process, in order)."""

    jobs: int = 1

    def __post_init__(self) -> None:
        if self.jobs < 1:
            raise ValueError("jobs must be >= 1")

    def run(self, tasks: Sequence[Task], fn: TaskFunction = run_task) -> Iterator[TaskResult]:
        """Run `fn` on every task, yielding each result as it is done."""
        if self.jobs == 1:
            for t in tasks:
                yield fn(t)
            return
        lost = yield from _in_pool(tasks, fn, self.jobs)
        while lost:
            # A worker died (killed, out of memory, a crash in native code) and took down
            # the pool's pending tasks with it. Run them again; once a round finishes none,
            # run each alone, so that a task that kills its worker is told apart from the
            # ones that were beside it, and comes back as a failed result with its seed.
            again = yield from _in_pool(lost, fn, self.jobs)
            if len(again) == len(lost):
                for task in again:
                    if (yield from _in_pool([task], fn, 1)):
                        yield TaskResult(task, error=WORKER_DIED)
                return
            lost = again


WORKER_DIED = (
    "its worker process died (killed, out of memory, or a crash in native code); "
    "run this task alone, with --jobs 1, to see why"
)


def _in_pool(
    tasks: Sequence[Task], fn: TaskFunction, workers: int
) -> Generator[TaskResult, None, list[Task]]:
    """Yield each task's result from a pool of `workers` processes.

    Returns the tasks lost to a broken pool, in the tasks' order.
    """
    lost: set[Task] = set()
    with ProcessPoolExecutor(max_workers=workers) as pool:
        futures = {pool.submit(fn, t): t for t in tasks}
        pending: set[Future[TaskResult]] = set(futures)
        while pending:
            done, pending = wait(pending, return_when=FIRST_COMPLETED)
            for f in done:
                try:
                    result = f.result()
                except BrokenProcessPool:
                    lost.add(futures[f])
                    continue
                except Exception as e:  # e.g. a result that cannot be pickled back
                    result = TaskResult(futures[f], error=f"{type(e).__name__}: {e}")
                yield result
    return [t for t in tasks if t in lost]


def run_tasks(
    tasks: Sequence[Task],
    backend: Backend,
    on_result: Callable[[TaskResult], None] | None = None,
    fn: TaskFunction = run_task,
) -> list[TaskResult]:
    """Run every task on `backend`; the results come back in the tasks' order.

    Each task is a pure function of itself, so the results are the same whatever the
    backend and its parallelism.
    """
    if len(set(tasks)) != len(tasks):
        raise ValueError("tasks must be distinct")
    order = {t: i for i, t in enumerate(tasks)}
    results: list[TaskResult] = []
    for r in backend.run(tasks, fn):
        results.append(r)
        if on_result is not None:
            on_result(r)
    results.sort(key=lambda r: order[r.task])
    if [r.task for r in results] != list(tasks):
        raise RuntimeError("the backend did not return one result per task")
    return results


def run_experiment(
    conditions: Sequence[str],
    seeds: Sequence[int],
    episodes: int,
    jobs: int = 1,
    on_result: Callable[[TaskResult], None] | None = None,
    backend: Backend | None = None,
    setup: Setup | None = None,
) -> list[TaskResult]:
    """Run every (condition, seed) task on `backend` (default: `jobs` local processes).

    Each task is a pure function of (condition, seed, episodes), so the results are the
    same whatever the backend and `jobs`; they are returned in (condition, seed) order.
    """
    if episodes < 1:
        raise ValueError("episodes must be >= 1")
    if not seeds:
        raise ValueError("at least one seed is needed")
    if jobs < 1:
        raise ValueError("jobs must be >= 1")
    for c in conditions:
        get_condition(c)
    setup = (setup or Setup()).resolved()
    tasks = [Task(c, s, episodes, setup=setup) for c in conditions for s in seeds]
    return run_tasks(tasks, backend or LocalBackend(jobs), on_result)


# --- analysis -------------------------------------------------------------------------

_T975 = (
    12.706, 4.303, 3.182, 2.776, 2.571, 2.447, 2.365, 2.306, 2.262, 2.228,
    2.201, 2.179, 2.160, 2.145, 2.131, 2.120, 2.110, 2.101, 2.093, 2.086,
    2.080, 2.074, 2.069, 2.064, 2.060, 2.056, 2.052, 2.048, 2.045, 2.042,
)  # fmt: skip


def t_quantile_975(df: int) -> float:
    """Student's t 97.5% quantile for `df` degrees of freedom (1.96 beyond 30)."""
    if df < 1:
        return math.nan
    return _T975[df - 1] if df <= len(_T975) else 1.96


def mean_ci(values: Sequence[float]) -> dict[str, float]:
    """Mean and the half-width of its 95% confidence interval (Student's t), over seeds."""
    n = len(values)
    if n == 0:
        return {"mean": math.nan, "ci95": math.nan, "n": 0}
    arr = np.asarray(values, dtype=np.float64)
    mean = float(arr.mean())
    if n == 1:
        return {"mean": mean, "ci95": math.nan, "n": 1}
    sd = float(arr.std(ddof=1))
    return {"mean": mean, "ci95": t_quantile_975(n - 1) * sd / math.sqrt(n), "n": n}


def episodes_to_criterion(
    successes: Sequence[bool], window: int = CRITERION_WINDOW, rate: float = CRITERION_RATE
) -> int | None:
    """The first episode count after which the rolling success over `window` is >= `rate`."""
    need = math.ceil(rate * window - 1e-9)
    count = 0
    for i, s in enumerate(successes):
        count += s
        if i >= window:
            count -= successes[i - window]
        if i + 1 >= window and count >= need:
            return i + 1
    return None


def paired_against(
    summary: dict[str, Any], reference: str, horizon: int | None = None
) -> dict[str, dict[str, float]]:
    """Each condition's success minus `reference`'s, paired by seed.

    Over the first `horizon` episodes (None: all): the mean difference, its 95% bootstrap
    interval and the sign-flip p, per condition.
    """
    ref = summary.get(reference, {})
    if not ref.get("seeds"):
        return {}
    ref_by_seed = dict(zip(ref["seed_ids"], ref["success_by_seed"], strict=True))
    out = {}
    for name, s in summary.items():
        if name == reference or not s.get("seeds"):
            continue
        mine = dict(zip(s["seed_ids"], s["success_by_seed"], strict=True))
        seeds = [x for x in mine if x in ref_by_seed]
        if len(seeds) < 2:
            continue
        a = [float(np.mean(mine[x][:horizon])) for x in seeds]
        b = [float(np.mean(ref_by_seed[x][:horizon])) for x in seeds]
        d = paired_difference(a, b)
        out[name] = {**d.diff.as_dict(), "p": d.p}
    return out


def _ticks_by_origin(results: Sequence[TaskResult]) -> dict[str, int]:
    """Ticks summed over seeds by what made their behaviour run, most first."""
    total: dict[str, int] = {}
    for r in results:
        for origin, n in r.ticks_by_origin.items():
            total[origin] = total.get(origin, 0) + n
    return dict(sorted(total.items(), key=lambda kv: (-kv[1], kv[0])))


def _camera_met(results: Sequence[TaskResult]) -> dict[str, dict[str, float]]:
    """What each camera stimulus met: its ticks and encounters per seed, and more.

    Also the seeds that met it, the episodes it was met in (all seeds together) and the
    success rate of those episodes.
    """
    names = sorted({n for r in results for n in r.camera_met})
    out = {}
    for n in names:
        met = [r.camera_met.get(n, (0, 0, 0, 0)) for r in results]
        episodes = sum(m[2] for m in met)
        out[n] = {
            "ticks_per_seed": float(np.mean([m[0] for m in met])),
            "encounters_per_seed": float(np.mean([m[1] for m in met])),
            "seeds": sum(1 for m in met if m[1] > 0),
            "episodes": episodes,
            "success_when_met": sum(m[3] for m in met) / episodes if episodes else math.nan,
        }
    return out


def summarise(results: Sequence[TaskResult], conditions: Sequence[str]) -> dict[str, Any]:
    """Per condition, over seeds: the figures of the experiment's summary."""
    out: dict[str, Any] = {}
    for c in conditions:
        rs = [r for r in results if r.task.condition == c and r.ok]
        if not rs:
            out[c] = {"seeds": 0}
            continue
        n_ep = min(len(r.episodes) for r in rs)
        success = np.array([[e.outcome is Outcome.SUCCESS for e in r.episodes[:n_ep]] for r in rs])
        last = min(CRITERION_WINDOW, n_ep)
        crit = [episodes_to_criterion(list(row)) for row in success]
        reached = sorted(x for x in crit if x is not None)

        def per_episode(cause: Cause, rs: list[TaskResult] = rs) -> list[float]:
            return [sum(e.cause is cause for e in r.episodes) / len(r.episodes) for r in rs]

        collisions = [
            a + b
            for a, b in zip(
                per_episode(Cause.WALL_COLLISION),
                per_episode(Cause.OBSTACLE_COLLISION),
                strict=True,
            )
        ]
        memory = "rltm" if get_condition(c).kp else "ltm"

        def reliability(r: TaskResult, key: str, memory: str = memory) -> float:
            learned: dict[str, float] = getattr(r, memory)
            return max(learned.get(key, 0.0), r.programmed.get(key, 0.0))

        keys = sorted({k for r in rs for k in (*getattr(r, memory), *r.programmed)})
        reliab = {k: mean_ci([reliability(r, k) for r in rs]) for k in keys}
        out[c] = {
            "description": CONDITIONS[c].description,
            "seeds": len(rs),
            "episodes": n_ep,
            "success_rate": mean_ci(success.mean(axis=1).tolist()),
            "success_last10": mean_ci(success[:, -last:].mean(axis=1).tolist()),
            "success_curve": success.mean(axis=0).tolist(),
            "success_by_seed": success.astype(int).tolist(),
            "seed_ids": [r.task.seed for r in rs],
            "success_curve_ci95": [
                mean_ci(success[:, i].astype(float).tolist())["ci95"] for i in range(n_ep)
            ],
            "episodes_to_criterion": {
                "median": float(np.median(reached)) if reached else None,
                "reached": len(reached),
                "never": len(crit) - len(reached),
                "per_seed": crit,
            },
            "collisions_per_episode": mean_ci(collisions),
            "obstacle_collisions_per_episode": mean_ci(per_episode(Cause.OBSTACLE_COLLISION)),
            "wall_collisions_per_episode": mean_ci(per_episode(Cause.WALL_COLLISION)),
            "violations_per_episode": mean_ci(per_episode(Cause.SIGNAL_VIOLATION)),
            "timeouts_per_episode": mean_ci(per_episode(Cause.TIMEOUT)),
            "camera_memory": memory if get_condition(c).agent == "brain" else None,
            "learns_camera": get_condition(c).agent == "brain" and get_condition(c).learning,
            "camera_reliability": reliab,
            "ticks": sum(r.ticks for r in rs),
            "ticks_by_origin": _ticks_by_origin(rs),
            "camera_stimuli_met": _camera_met(rs),
        }
    return out
