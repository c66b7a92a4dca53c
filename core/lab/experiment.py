"""Experiments: conditions x seeds x episodes, run in parallel, summarised over seeds."""

from __future__ import annotations

import traceback
from collections.abc import Callable, Generator, Iterable, Iterator, Mapping, Sequence
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol

import numpy as np
import numpy.typing as npt

from core.brain.catalog import Behaviour, Catalog, Stimulus
from core.brain.network import BehaviourNetwork
from core.errors import ExtraMissingError, UnknownNameError
from core.events import Outcome
from core.lab.analysis import (
    CRITERION_RATE,
    CRITERION_WINDOW,
    episodes_to_criterion,
    mean_ci,
    paired_against,
    summarise,
    t_quantile_975,
)
from core.lab.tasks import DEFAULT_SETUP as DEFAULT_SETUP
from core.lab.tasks import Checkpoint as Checkpoint
from core.lab.tasks import Task as Task
from core.lab.tasks import TaskResult as TaskResult
from core.learners.qlambda import WatkinsQLambda, run_qlambda
from core.params import (
    Params,
    ParamValue,
    applicable,
    baseline_params,
    configure,
    normalise,
    qlambda_config,
    tuned_params,
)
from core.run.conditions import DEEP_AGENTS, Condition
from core.run.runner import EpisodeSummary, run
from core.run.setup import Setup

if TYPE_CHECKING:
    from stable_baselines3.common.base_class import BaseAlgorithm

    from core.learners.envs import AmigoTrackEnv

CAMERA_SENSOR = "camera_obstacle"


def parse_conditions(text: str, setup: Setup | None = None) -> list[str]:
    """A comma-separated list of known condition names, in order, without repeats.

    Known: the built-in conditions and `setup`'s own. A deep baseline (dqn, ppo) without
    the srlab[baselines] extra installed is an error here, before anything runs.
    """
    names = [n.strip() for n in text.split(",") if n.strip()]
    if not names:
        raise UnknownNameError("no condition given")
    lookup = (setup or Setup()).lookup
    deep = [n for n in names if lookup(n).agent in DEEP_AGENTS]
    if deep:
        from core.learners import baselines

        if not baselines.available():
            raise ExtraMissingError(
                f"{', '.join(deep)} need{'s' if len(deep) == 1 else ''} the srlab[baselines] "
                f"extra (stable-baselines3 on a CPU-only torch): run `{baselines.INSTALL_HINT}`"
            )
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
        condition = setup.condition(setup.lookup(task.condition))
        if condition.agent == "qlambda":
            return _run_qlambda_task(task, catalog, condition)
        if condition.agent in DEEP_AGENTS:
            return _run_deep_task(task, catalog, condition)
        return _run_brain_task(task, catalog, condition)
    except Exception as e:  # a failed task is reported with its seed, never lost silently
        return TaskResult(task, error=f"{type(e).__name__}: {e}\n{traceback.format_exc()}")


def _run_brain_task(task: Task, catalog: Catalog, condition: Condition) -> TaskResult:
    from core.lab.evaluation import evaluate, without_sonar
    from core.run.simulation import Simulation

    setup = task.setup
    condition, brain_config = configure(condition, task.params)
    world = setup.world_config()
    sim = Simulation(
        condition, task.seed, catalog=catalog, world_config=world, brain_config=brain_config
    )
    camera = [st.id for st in catalog.stimuli if st.sensor == CAMERA_SENSOR]
    met_in = dict.fromkeys(camera, 0)
    won_in = dict.fromkeys(camera, 0)
    answers: list[tuple[str | None, ...]] = []
    checkpoints: list[Checkpoint] = []

    def held_out(network: BehaviourNetwork) -> tuple[EpisodeSummary, ...]:
        return evaluate(
            condition, sim.brain.catalog, network, task.seed, task.eval_episodes,
            world_config=world, brain_config=sim.brain.config,
        )  # fmt: skip

    def frozen_now(episodes: int) -> Checkpoint:
        network = sim.brain.network
        transfer = held_out(without_sonar(sim.brain.catalog, network))
        return Checkpoint(episodes, held_out(network), transfer)

    def after_episode(e: EpisodeSummary) -> None:
        won = e.outcome is Outcome.SUCCESS
        for s in camera:
            if s in sim.met_this_episode:
                met_in[s] += 1
                won_in[s] += won
        names = sim.brain.catalog.behaviours
        answers.append(tuple(_name(names, sim.brain.answer(s)) for s in camera))
        if len(answers) in task.eval_after:
            checkpoints.append(frozen_now(len(answers)))

    summary = run(condition, task.seed, task.episodes, simulation=sim, on_episode=after_episode)
    brain = sim.brain
    names = [b.name for b in brain.catalog.behaviours]
    rltm = brain.kp.rltm.items() if brain.kp is not None else ()
    designed = (
        ((a.stimulus, a.behaviour), a.strength)
        for a in brain.network
        if a.source not in ("learned", "kp")
    )
    evaluation: tuple[EpisodeSummary, ...] = ()
    transfer: tuple[EpisodeSummary, ...] = ()
    if task.eval_episodes:
        last = frozen_now(task.episodes)
        evaluation, transfer = last.evaluation, last.transfer
    return TaskResult(
        task,
        summary.episodes,
        summary.ticks,
        _camera_memory(catalog, brain.ltm.items(), names),
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
        answers=tuple(answers),
        evaluation=evaluation,
        transfer=transfer,
        checkpoints=tuple(checkpoints),
    )


def _run_qlambda_task(task: Task, catalog: Catalog, condition: Condition) -> TaskResult:
    from core.lab.evaluation import eval_seed
    from core.learners.envs import AmigoTrackEnv
    from core.learners.qlambda import answer, evaluate_qlambda

    setup = task.setup
    config = qlambda_config(condition, task.params)

    def env_for(prior: str) -> AmigoTrackEnv:
        return AmigoTrackEnv(
            prior=prior,
            learnable=condition.learnable_sensors,
            world_config=setup.world_config(),
            catalog=catalog,
            extra_networks=condition.extra_networks,
            defer=config.defer,
        )

    camera = [st for st in catalog.stimuli if st.sensor == CAMERA_SENSOR]
    answers: list[tuple[str | None, ...]] = []
    agent_ref: list[WatkinsQLambda] = []
    checkpoints: list[Checkpoint] = []
    done = [0]

    def frozen_now(agent: WatkinsQLambda, episodes: int) -> Checkpoint:
        seed, n = eval_seed(task.seed), task.eval_episodes
        evaluation = tuple(evaluate_qlambda(agent, env_for(config.prior), seed, n))
        without = env_for(_without_sonar_set(config.prior))
        return Checkpoint(episodes, evaluation, tuple(evaluate_qlambda(agent, without, seed, n)))

    def after_episode(_: EpisodeSummary) -> None:
        done[0] += 1
        if agent_ref:
            agent = agent_ref[0]
            answers.append(
                tuple(
                    _name(catalog.behaviours, answer(agent, _alone(catalog, st, env)))
                    for st in camera
                )
            )
            if done[0] in task.eval_after:
                checkpoints.append(frozen_now(agent, done[0]))

    env = env_for(config.prior)
    episodes, agent, ticks = run_qlambda(
        task.seed, task.episodes, config, env=env, on_agent=agent_ref.append,
        on_episode=after_episode,
    )  # fmt: skip
    last = frozen_now(agent, task.episodes) if task.eval_episodes else Checkpoint(0, (), ())
    sim = env.simulation
    return TaskResult(
        task, tuple(episodes), ticks, answers=tuple(answers), evaluation=last.evaluation,
        transfer=last.transfer, checkpoints=tuple(checkpoints),
        ticks_by_origin=dict(sim.ticks_by_origin),
        camera_met={
            st.name: (sim.stimulus_ticks[st.id], sim.encounters[st.id], 0, 0)
            for st in camera
            if sim.encounters[st.id]
        },
    )  # fmt: skip


def _run_deep_task(task: Task, catalog: Catalog, condition: Condition) -> TaskResult:
    """A deep baseline (DQN or PPO, `core.learners.baselines`), trained and evaluated as any."""
    from core.lab.evaluation import eval_seed
    from core.learners import baselines

    algo: baselines.Algo = "dqn" if condition.agent == "dqn" else "ppo"
    config = baselines.BaselineConfig.with_params(algo, baseline_params(condition, task.params))
    setup = task.setup

    def env_for(prior: str) -> AmigoTrackEnv:
        return baselines.baseline_env(setup, prior, defer=condition.hybrid)

    env = env_for(condition.network)
    camera = [st for st in catalog.stimuli if st.sensor == CAMERA_SENSOR]
    alone = [_alone(catalog, st, env) for st in camera]
    answers: list[tuple[str | None, ...]] = []
    model_ref: list[BaseAlgorithm] = []

    checkpoints: list[Checkpoint] = []

    def frozen_now(model: BaseAlgorithm, episodes: int) -> Checkpoint:
        seeds, n = (eval_seed(task.seed),), task.eval_episodes
        evaluation = baselines.evaluate(model, lambda: env_for(condition.network), seeds, n)
        without = _without_sonar_set(condition.network)
        transfer = baselines.evaluate(model, lambda: env_for(without), seeds, n)
        return Checkpoint(episodes, tuple(evaluation), tuple(transfer))

    def after_episode(_: EpisodeSummary) -> None:
        model = model_ref[0]
        answers.append(
            tuple(
                _name(catalog.behaviours, baselines.answer(model, obs, env.defer_action))
                for obs in alone
            )
        )
        if len(answers) in task.eval_after:
            checkpoints.append(frozen_now(model, len(answers)))

    episodes, model, ticks = baselines.learn(
        algo, task.seed, task.episodes, config, env=env, on_episode=after_episode,
        on_model=model_ref.append,
    )  # fmt: skip
    last = frozen_now(model, task.episodes) if task.eval_episodes else Checkpoint(0, (), ())
    sim = env.simulation
    return TaskResult(
        task, tuple(episodes), ticks, answers=tuple(answers[: task.episodes]),
        evaluation=last.evaluation, transfer=last.transfer, checkpoints=tuple(checkpoints),
        ticks_by_origin=dict(sim.ticks_by_origin),
        camera_met={
            st.name: (sim.stimulus_ticks[st.id], sim.encounters[st.id], 0, 0)
            for st in camera
            if sim.encounters[st.id]
        },
    )  # fmt: skip


def _without_sonar_set(prior: str) -> str:
    """The knowledge set a camera-only transfer test gives an outside learner's robot."""
    return "position" if prior == "kp" else prior


LANE_STIMULI = {"L": "Left", "M": "Middle", "R": "Right"}
"""The position stimulus of each lane letter of a camera stimulus's name (Obstacle_M_R)."""


def _alone(catalog: Catalog, stimulus: Stimulus, env: AmigoTrackEnv) -> npt.NDArray[np.int8]:
    """The observation of a camera stimulus seen alone, with its lane's position stimulus."""
    active = [stimulus.id]
    parts = stimulus.name.split("_")
    lane = LANE_STIMULI.get(parts[1]) if len(parts) == 3 else None
    if lane is not None:
        active.append(catalog.stimulus(lane).id)
    return env.observation(active)


def _name(behaviours: Sequence[Behaviour], b: int) -> str | None:
    return behaviours[b].name if 0 <= b < len(behaviours) else None


TaskFunction = Callable[[Task], TaskResult]


class Backend(Protocol):
    """Where tasks run: local processes (`LocalBackend`) or a cluster (`server.backends`).

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


_AGENT_COST = {"brain": 1.0, "qlambda": 1.4}
"""Relative cost of an episode per agent: measured ticks/s of one core (the Gymnasium
learners step about 1.4x slower than the brain); the deep agents, not listed, cost most."""
_DEEP_COST = 10.0


def expected_cost(task: Task) -> float:
    """A task's expected run time, in brain episodes: for ordering work, never for results."""
    agent = task.setup.lookup(task.condition).agent
    per_episode = _AGENT_COST.get(agent, _DEEP_COST if agent in DEEP_AGENTS else 1.0)
    return per_episode * (task.episodes + 2 * task.eval_episodes * (1 + len(task.eval_after)))


def _in_pool(
    tasks: Sequence[Task], fn: TaskFunction, workers: int
) -> Generator[TaskResult, None, list[Task]]:
    """Yield each task's result from a pool of `workers` processes.

    Returns the tasks lost to a broken pool, in the tasks' order.
    """
    lost: set[Task] = set()
    with ProcessPoolExecutor(max_workers=workers) as pool:
        # Longest first, so that no long task starts last while the other workers idle.
        futures = {pool.submit(fn, t): t for t in sorted(tasks, key=expected_cost, reverse=True)}
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
    eval_episodes: int = 0,
    tuned: bool = False,
    params: Mapping[str, ParamValue] | None = None,
) -> list[TaskResult]:
    """Run every (condition, seed) task on `backend` (default: `jobs` local processes).

    With `eval_episodes`, each task ends with a frozen, held-out evaluation of that many
    episodes and the camera-only transfer test (`core.lab.evaluation`). With `tuned`, each
    condition runs with its tuned parameters (`core/data/tuned.toml`, `srlab tune`);
    `params` are set, over those, on every condition that uses them (a teacher's
    imperfections on rp's, say).

    Each task is a pure function of (condition, seed, episodes), so the results are the
    same whatever the backend and `jobs`; they are returned in (condition, seed) order.
    """
    if episodes < 1:
        raise ValueError("episodes must be >= 1")
    if not seeds:
        raise ValueError("at least one seed is needed")
    if jobs < 1:
        raise ValueError("jobs must be >= 1")
    setup = (setup or Setup()).resolved()
    for c in conditions:
        setup.condition(setup.lookup(c))  # an unknown name, or a start it cannot take
    if eval_episodes < 0:
        raise ValueError("eval_episodes must be >= 0")
    tasks = experiment_tasks(conditions, seeds, episodes, setup, eval_episodes, tuned, params)
    return run_tasks(tasks, backend or LocalBackend(jobs), on_result)


def experiment_tasks(
    conditions: Sequence[str],
    seeds: Sequence[int],
    episodes: int,
    setup: Setup,
    eval_episodes: int = 0,
    tuned: bool = False,
    params: Mapping[str, ParamValue] | None = None,
) -> list[Task]:
    """The (condition, seed) tasks of an experiment, in that order (see `run_experiment`)."""
    setup = setup.resolved()

    def params_of(c: str) -> Params:
        base = dict(tuned_params(c)) if tuned else {}
        return normalise({**base, **dict(applicable(setup.lookup(c), params or {}))})

    return [
        Task(c, s, episodes, params_of(c), setup=setup, eval_episodes=eval_episodes)
        for c in conditions
        for s in seeds
    ]


__all__ = [
    "CAMERA_SENSOR",
    "CRITERION_RATE",
    "CRITERION_WINDOW",
    "WORKER_DIED",
    "Backend",
    "LocalBackend",
    "Task",
    "TaskFunction",
    "TaskResult",
    "episodes_to_criterion",
    "expected_cost",
    "experiment_tasks",
    "mean_ci",
    "paired_against",
    "parse_conditions",
    "run_experiment",
    "run_task",
    "run_tasks",
    "summarise",
    "t_quantile_975",
]
