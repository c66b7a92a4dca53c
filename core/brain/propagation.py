"""Knowledge propagation (KP, Fig. 4-6): low-level S-R pairs teach a high-level sensor.

While a high-level stimulus S1 (a camera obstacle stimulus) is perceived, the low-level S-R
behaviours of the same objective that fire (sonar obstacle stimuli S0_a, S0_b... releasing
B1, B2...) are recorded in the RSTM of S1's logical sensor. On a reward, `reasoning`
(the paper's reasoningKPM) makes B from the vector sum of B1..Bn, and `update` (its
updateKPMMemory) applies the Eq. (1) rule to S1 -> B in RLTM with d_k = 1: the RSTM knows
which behaviour deserved the reward, so a delayed reward acts as an immediate one. Over the
threshold, S1 -> B joins the behaviour network as a ``kp`` association.

What KP learns only grows from the lap's reward unless `KpConfig.failure_penalty` is set:
then a failed episode punishes RLTM by the mirrored rule (`punish`), so a copy that leads
to failures is weakened and, below the threshold, leaves the network.
"""

from __future__ import annotations

import math
from collections import defaultdict, deque
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from typing import Literal

from core.brain.catalog import Behaviour, Catalog
from core.brain.memory import reinforce
from core.brain.network import BehaviourNetwork
from core.brain.selection import Decision, How
from core.events import AssociationDemoted, AssociationPromoted


@dataclass(frozen=True, slots=True)
class KpConfig:
    """Parameters of knowledge propagation.

    Attributes:
        enabled: whether the KP module runs.
        window_ticks: a low-level response up to this many ticks after the high-level
            stimulus was last perceived is associated with it (the camera sees the obstacle
            before the sonars do, Fig. 5's t1 before t2..t4).
        eta: the RLTM learning rate of the Eq. (1) rule.
        insert_threshold: an RLTM pair this reliable joins the behaviour network.
        synthesize: False snaps B to the nearest primitive behaviour; True keeps B as a new,
            synthesised behaviour when no primitive is within `snap_tolerance_deg`.
        snap_tolerance_deg: how close a primitive must be to stand for B when synthesising.
        rstm_capacity: bound of each RSTM.
        log_capacity: bound of each pair's inspection log (`KnowledgePropagation.log`).
        failure_penalty: the size of the punishment a failed episode gives RLTM, in
            [0, 1]; 0 (the default) never punishes, so RLTM learns only from rewards.
    """

    enabled: bool = False
    window_ticks: int = 20
    eta: float = 0.1
    insert_threshold: float = 0.5
    synthesize: bool = False
    snap_tolerance_deg: float = 1.0
    rstm_capacity: int = 256
    log_capacity: int = 256
    failure_penalty: float = 0.0

    def __post_init__(self) -> None:
        if not 0.0 <= self.failure_penalty <= 1.0:
            raise ValueError("failure_penalty must be in [0, 1]")


@dataclass(frozen=True, slots=True)
class RstmRecord:
    """A low-level response recorded while a high-level stimulus was perceived."""

    tick: int
    high: int
    low: int
    behaviour: int


Resolution = Literal["snapped", "synthesized", "reused"]
"""How reasoningKPM turned the vector sum into a behaviour: snapped to the nearest
primitive, synthesised a new one, or reused one it had synthesised before."""


@dataclass(frozen=True, slots=True)
class KpProvenance:
    """How one reasoningKPM made B for S1: the RSTM sources, their vector sum, the snap.

    Attributes:
        stimulus: S1, the high-level stimulus.
        sources: the RSTM records reasoned over (S0_i -> B_i, with the tick each ran).
        sum_x: the vector sum's component along the corridor (unit vectors, one a source).
        sum_y: its component across (+ = left).
        angle_rad: the direction of the sum (`resultant_direction`).
        speed_mps: the sources' mean speed.
        nearest: the forward or turn primitive whose heading is nearest the sum.
        nearest_angle_rad: that primitive's heading.
        behaviour: B, the behaviour S1 was taught (`nearest` unless synthesised).
        resolution: snapped, synthesized or reused.
        after_tick: the last tick the KP module saw before the reward (it arrived after).
    """

    stimulus: int
    sources: tuple[RstmRecord, ...]
    sum_x: float
    sum_y: float
    angle_rad: float
    speed_mps: float
    nearest: int
    nearest_angle_rad: float
    behaviour: int
    resolution: Resolution
    after_tick: int


@dataclass(frozen=True, slots=True)
class RltmPoint:
    """One Eq. (1) step of an RLTM pair: the reward after `after_tick` moved it."""

    after_tick: int
    reward: float
    before: float
    after: float


@dataclass(frozen=True, slots=True)
class Propagated:
    """What one reward taught a high-level stimulus.

    `provenance` says how B was made; it is left out of equality, which compares what was
    learned (it follows from the same RSTM deterministically anyway).
    """

    stimulus: int
    behaviour: int
    sources: tuple[int, ...]
    before: float
    after: float
    synthesized: bool
    provenance: KpProvenance | None = field(default=None, compare=False)


class KpLog:
    """What the KP module did to one RLTM pair S1 -> B, for inspection (bounded).

    Attributes:
        provenances: the latest reasonings that gave S1 -> B, oldest first.
        history: the pair's RLTM reliability after each reward, oldest first.
        runs: (first tick, last tick) spans of consecutive ticks where S1 -> B ran as a
            ``kp`` association (released or continued).
        reasoned: how many rewards reasoned S1 -> B in all.
        ran_ticks: how many ticks it ran in all.
    """

    __slots__ = ("history", "provenances", "ran_ticks", "reasoned", "runs")

    def __init__(self, capacity: int) -> None:
        self.provenances: deque[KpProvenance] = deque(maxlen=min(capacity, 16))
        self.history: deque[RltmPoint] = deque(maxlen=capacity)
        self.runs: deque[tuple[int, int]] = deque(maxlen=capacity)
        self.reasoned = 0
        self.ran_ticks = 0


def steer_angle(b: Behaviour, dt_s: float) -> float:
    """The heading, relative to the corridor, a primitive drives towards (0 for align)."""
    if b.mode == "align":
        return 0.0
    return math.radians(b.turn_dps) * b.ticks * dt_s


def resultant_direction(behaviours: Iterable[Behaviour], dt_s: float) -> float:
    """The direction of the vector sum of the behaviours' headings, radians (+ = left).

    Each behaviour is a unit vector pointing where it drives (`steer_angle`: the heading
    its motor steers to, off the corridor's direction), so the sum is compared like with
    like against each primitive's own heading: one source gives itself back, n copies of
    one turn give that turn, and mirrored sources give mirrored results. (Summing the
    displacements instead, and matching them against headings, halved every turn: the
    chord of a 30 degree arc points at 15 degrees.) Opposite turns cancel to straight on.
    """
    sx = sy = 0.0
    for b in behaviours:
        a = steer_angle(b, dt_s)
        sx += math.cos(a)
        sy += math.sin(a)
    if abs(sx) < 1e-12 and abs(sy) < 1e-12:
        return 0.0
    return math.atan2(sy, sx)


def nearest_primitive(
    catalog: Catalog, angle_rad: float, dt_s: float, speed_mps: float = 0.45
) -> Behaviour:
    """The forward or turn primitive whose heading is nearest `angle_rad`.

    Ties (the five forward speeds all head straight on) go to the speed nearest
    `speed_mps`, then to the smaller turn.
    """
    best: Behaviour | None = None
    best_key = (math.inf, math.inf, math.inf)
    for b in catalog.behaviours:
        if b.family not in ("forward", "turn") or b.synthesized:
            continue
        a = steer_angle(b, dt_s)
        key = (round(abs(a - angle_rad), 9), round(abs(b.speed_mps - speed_mps), 9), abs(a))
        if key < best_key:
            best, best_key = b, key
    assert best is not None, "the catalogue has no forward or turn primitive"
    return best


SAME_HEADING_RAD = 1e-9
"""Headings closer than this are one heading (a vector sum's rounding, not a new turn)."""


def synthesized_behaviour(angle_rad: float, speed_mps: float, dt_s: float) -> Behaviour:
    """A new steer primitive towards `angle_rad` at 150 deg/s or less (id set on insertion)."""
    deg = math.degrees(angle_rad)
    ticks = max(1, math.ceil(abs(deg) / 15.0 - 1e-9))
    name = f"kp_{'left' if deg >= 0 else 'right'}{abs(round(deg))}"
    return Behaviour(
        id=-1,
        name=name,
        family="synthesized",
        speed_mps=speed_mps,
        turn_dps=deg / (ticks * dt_s),
        ticks=ticks,
        mode="steer",
        synthesized=True,
    )


class KnowledgePropagation:
    """RSTM per high-level logical sensor, RLTM, and the reasoning between them."""

    def __init__(
        self,
        catalog: Catalog,
        network: BehaviourNetwork,
        config: KpConfig,
        dt_s: float,
        add_behaviour: Callable[[Behaviour], Behaviour],
    ) -> None:
        self.catalog = catalog
        self.network = network
        self.config = config
        self._dt = dt_s
        self._add_behaviour = add_behaviour
        self._high = tuple(s.level == "high" for s in catalog.stimuli)
        self._objective = tuple(s.objective for s in catalog.stimuli)
        self._sensor = tuple(s.sensor for s in catalog.stimuli)
        self._low_objectives = {s.objective for s in catalog.stimuli if s.level == "low"}
        self._last_high: dict[str, tuple[int, int]] = {}
        self.rstm: dict[str, deque[RstmRecord]] = defaultdict(
            lambda: deque(maxlen=config.rstm_capacity)
        )
        self.rltm: dict[tuple[int, int], float] = {}
        self.log: dict[tuple[int, int], KpLog] = {}
        """Per RLTM pair: its provenance, reliability history and runs (read-only use)."""
        self.now = -1
        """The latest tick `percept` saw."""
        self._running: tuple[int, int] | None = None
        self._ran: dict[tuple[int, int], None] = {}
        """The KP-made pairs that ran since the episode started or the last reward, in order."""

    @property
    def dt_s(self) -> float:
        """The tick length the behaviours' headings are computed with."""
        return self._dt

    def perceived(self) -> dict[str, tuple[int, int]]:
        """Per objective, the high-level stimulus last perceived and the tick (a copy)."""
        return dict(self._last_high)

    def reset_episode(self) -> None:
        """Forget what was perceived and recorded (a new episode, a new approach)."""
        self._last_high.clear()
        self._running = None
        self._ran.clear()
        for r in self.rstm.values():
            r.clear()

    def percept(self, tick: int, active: Sequence[int], decision: Decision) -> None:
        """Fig. 6: if a KP percept exists, save it with the current behaviour in RSTM."""
        self.now = tick
        self._note_run(tick, decision)
        high = self._high
        objective = self._objective
        for s in active:
            if high[s] and objective[s] in self._low_objectives:
                self._last_high[objective[s]] = (s, tick)
        low = decision.stimulus
        if low < 0 or high[low] or decision.how is not How.RELEASED:
            return
        seen = self._last_high.get(objective[low])
        if seen is None or tick - seen[1] > self.config.window_ticks:
            return
        s1 = seen[0]
        self.rstm[self._sensor[s1]].append(RstmRecord(tick, s1, low, decision.behaviour))

    def _note_run(self, tick: int, decision: Decision) -> None:
        """Keep the tick spans where a KP-made association ran (its decision's origin)."""
        if decision.origin != "kp" or decision.stimulus < 0:
            self._running = None
            return
        pair = (decision.stimulus, decision.behaviour)
        log = self.log.get(pair)
        if log is None:  # a kp association this module did not make (a loaded design)
            self._running = None
            return
        log.ran_ticks += 1
        self._ran[pair] = None
        runs = log.runs
        # One span per stretch of consecutive ticks: a two-tick turn released again and
        # again while the camera keeps seeing the obstacle reads as one run, not many.
        if self._running == pair and runs and runs[-1][1] == tick - 1:
            runs[-1] = (runs[-1][0], tick)
        else:
            runs.append((tick, tick))
        self._running = pair

    def reasoning(self, behaviours: Sequence[int]) -> tuple[Behaviour, bool]:
        """reasoningKPM: B from the vector sum of B1..Bn; returns (B, whether it is new)."""
        made = self._reason(behaviours)
        return made[0], made[1] == "synthesized"

    def _reason(
        self, behaviours: Sequence[int]
    ) -> tuple[Behaviour, Resolution, tuple[float, float], float, float, Behaviour]:
        """The workings of reasoningKPM: B, how, the vector sum, angle, speed, nearest."""
        catalog = self.catalog
        dt = self._dt
        parts = [catalog.behaviours[b] for b in behaviours]
        stops = [b for b in parts if b.family == "stop"]
        if stops and 2 * len(stops) >= len(parts):
            # A stop has no heading to add to the sum (the paper's reasoningKPM sums
            # headings, and its sources always moved): when the low-level responses were
            # stops at least as often as moves, B is the stop; otherwise the sum runs over
            # the moves. Without a stop among the sources nothing changes.
            stop = stops[0]
            return (stop, "snapped", (0.0, 0.0), 0.0, 0.0, stop)
        parts = [b for b in parts if b.family != "stop"]
        sx = sum(math.cos(steer_angle(b, dt)) for b in parts)
        sy = sum(math.sin(steer_angle(b, dt)) for b in parts)
        angle = resultant_direction(parts, dt)
        speed = sum(b.speed_mps for b in parts) / len(parts)
        nearest = nearest_primitive(catalog, angle, dt, speed)
        workings = ((sx, sy), angle, speed, nearest)
        if not self.config.synthesize:
            return (nearest, "snapped", *workings)
        tolerance = math.radians(self.config.snap_tolerance_deg)
        if abs(steer_angle(nearest, dt) - angle) <= tolerance:
            return (nearest, "snapped", *workings)
        new = synthesized_behaviour(angle, speed, dt)
        for b in catalog.behaviours:
            # The same heading is the same behaviour, whatever its rounded name: a source
            # at 2.5 deg is `kp_left2`, and its vector sum, 2.5000000000000004 deg, would
            # be named `kp_left3`.
            same = b.synthesized and abs(steer_angle(b, dt) - angle) <= SAME_HEADING_RAD
            if same or b.name == new.name:
                return (b, "reused", *workings)
        added = self._add_behaviour(new)
        self.catalog = self._catalog_after(added)
        return (added, "synthesized", *workings)

    def _catalog_after(self, added: Behaviour) -> Catalog:
        if len(self.catalog.behaviours) > added.id:
            return self.catalog
        return self.catalog.with_behaviour(added)

    def reward(
        self, value: float
    ) -> tuple[list[Propagated], list[AssociationPromoted | AssociationDemoted]]:
        """updateKPMMemory: reason over every RSTM and apply Eq. (1) to RLTM (d_k = 1)."""
        learned: list[Propagated] = []
        promoted: list[AssociationPromoted | AssociationDemoted] = []
        self._ran.clear()
        for records in self.rstm.values():
            by_high: dict[int, list[RstmRecord]] = defaultdict(list)
            for r in records:
                by_high[r.high].append(r)
            records.clear()
            for s1, recs in sorted(by_high.items()):
                b, how, (sx, sy), angle, speed, nearest = self._reason([r.behaviour for r in recs])
                provenance = KpProvenance(
                    s1, tuple(recs), sx, sy, angle, speed, nearest.id,
                    steer_angle(nearest, self._dt), b.id, how, self.now,
                )  # fmt: skip
                learned.append(
                    self._update(s1, b.id, value, tuple(r.behaviour for r in recs), provenance,
                                 promoted)
                )  # fmt: skip
        return learned, promoted

    def punish(
        self, penalty: float
    ) -> tuple[list[Propagated], list[AssociationPromoted | AssociationDemoted]]:
        """A failed episode: apply a reward of ``-penalty`` to what KP taught and would teach.

        Two kinds of RLTM pair take the blame, each once: the pairs the RSTM reasons to now,
        as a reward would (what the low-level responses of this episode would teach), and
        the KP-made pairs that ran during the episode (what KP taught and the robot did).
        The second matters when a copy runs and the episode fails before any low-level
        response fires: the RSTM is then empty, and the copy is what failed.
        """
        if not 0.0 <= penalty <= 1.0:
            raise ValueError("penalty must be in [0, 1]")
        ran = list(self._ran)
        learned, promoted = self.reward(-penalty)
        done = {(p.stimulus, p.behaviour) for p in learned}
        for s1, b in ran:
            if (s1, b) not in done:
                learned.append(self._update(s1, b, -penalty, (), None, promoted))
        return learned, promoted

    def _update(
        self,
        s1: int,
        b: int,
        value: float,
        sources: tuple[int, ...],
        provenance: KpProvenance | None,
        promoted: list[AssociationPromoted | AssociationDemoted],
    ) -> Propagated:
        """Eq. (1) on RLTM's S1 -> B with d_k = 1, logged; promote or demote it."""
        cfg = self.config
        before = self.rltm.get((s1, b), 0.0)
        after = reinforce(before, value, cfg.eta, 1)
        self.rltm[(s1, b)] = after
        log = self.log.get((s1, b))
        if log is None:
            log = self.log[(s1, b)] = KpLog(cfg.log_capacity)
        if provenance is not None:
            log.provenances.append(provenance)
            log.reasoned += 1
        log.history.append(RltmPoint(self.now, value, before, after))
        old = self.network.get(s1, b)
        if after >= cfg.insert_threshold:
            if self.network.learn(s1, b, after, "kp") and old is None:
                promoted.append(AssociationPromoted(s1, b, after, "kp"))
        elif old is not None and old.source == "kp" and not old.locked:
            self.network.remove(s1, b)
            promoted.append(AssociationDemoted(s1, b, after))
        synthesized = provenance is not None and provenance.resolution == "synthesized"
        return Propagated(s1, b, sources, before, after, synthesized, provenance)
