"""The memory module: short-term memory of S-R pairs and long-term reliabilities, Eq. (1)."""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass

from core.events import Credit as Credit  # re-exported: Credit lives with the events

Pair = tuple[int, int]
"""(stimulus id, behaviour id)."""


def reinforce(v: float, reward: float, eta: float, d_k: int) -> float:
    """One Eq. (1) update of a reliability `v` by a reward `reward` in [-1, 1].

    A positive reward moves `v` towards 1 as the paper's Eq. (1),
    ``V <- V + eta * (1 - V) / d_k``, scaled by the reward's size (a reward of 1 is exactly
    Eq. (1)). A negative reward (a trainer's "bad") is the mirrored rule that moves `v`
    towards 0 by the same proportion: ``V <- V - |r| * eta * V / d_k``. Either way `v` stays
    in [0, 1], and records nearer the reward (smaller `d_k`) move more.

    Args:
        v: the reliability before, in [0, 1].
        reward: the reward, in [-1, 1].
        eta: the learning rate, in [0, 1].
        d_k: ticks between the record and the reward, >= 1.

    Returns:
        The reliability after.
    """
    if d_k < 1:
        raise ValueError("d_k must be >= 1")
    if reward >= 0.0:
        return v + reward * eta * (1.0 - v) / d_k
    return v + reward * eta * v / d_k


@dataclass(frozen=True, slots=True)
class ReactionWindow:
    """How late a person's reward comes after the tick it is for, in ticks.

    A person presses a key 0.2 to 4 s after what they react to (TAMER's credit window);
    at a run's rate that is `lo_ticks` to `hi_ticks` ticks before the tick they saw.

    Attributes:
        lo_ticks: the fewest ticks between a credited record and the tick seen, >= 0.
        hi_ticks: the most, >= `lo_ticks`.
    """

    lo_ticks: int
    hi_ticks: int

    def __post_init__(self) -> None:
        if not 0 <= self.lo_ticks <= self.hi_ticks:
            raise ValueError("a reaction window needs 0 <= lo_ticks <= hi_ticks")

    @classmethod
    def of_seconds(cls, lo_s: float, hi_s: float, hz: float) -> ReactionWindow:
        """The window of `lo_s`..`hi_s` seconds at `hz` ticks a second.

        The seen tick is on screen for a period, ``1 / hz``, and the press comes at some
        time in it; a tick the person may have seen at least `lo_s` before the press is one
        at least ``ceil(lo_s * hz) - 1`` ticks before the seen tick (never less than 0),
        and one at most `hi_s` before it at most ``floor(hi_s * hz)`` ticks before. So
        ``lo_ticks = max(0, ceil(lo_s * hz) - 1)`` and ``hi_ticks = floor(hi_s * hz)``
        (products within 1e-9 of a whole number count as it: 0.3 s at 10 Hz is 3 ticks);
        a window narrower than a tick keeps its one tick, ``lo_ticks``. At 10 Hz TAMER's
        0.2-4 s is 1 to 40 ticks; at 0.5 Hz, 0 to 2.
        """
        if not 0.0 <= lo_s <= hi_s or hz <= 0.0:
            raise ValueError("a reaction window needs 0 <= lo_s <= hi_s and hz > 0")
        lo = max(0, math.ceil(round(lo_s * hz, 9)) - 1)
        return cls(lo, max(lo, math.floor(round(hi_s * hz, 9))))

    @property
    def length(self) -> int:
        """Ticks in the window."""
        return self.hi_ticks - self.lo_ticks + 1

    def span(self, tick_seen: int) -> tuple[int, int]:
        """The first and last tick a reward for `tick_seen` credits."""
        return tick_seen - self.hi_ticks, tick_seen - self.lo_ticks


DEFAULT_REACTION_S = (0.2, 4.0)
"""TAMER's reaction window in seconds: the default of a run's."""
MAX_REACTION_S = 60.0
"""The longest reaction window a run may have, in seconds."""


class ShortTermMemory:
    """The S-R pair of every tick until a reward pops them (Fig. 2 and 3).

    Bounded: past `capacity` records the oldest are forgotten; with the defaults they are
    over 1,000 ticks old, where Eq. (1) would give them less than eta / 1000 anyway.
    """

    def __init__(self, capacity: int = 1000) -> None:
        if capacity < 1:
            raise ValueError("STM capacity must be >= 1")
        self._records: deque[tuple[int, int, int]] = deque(maxlen=capacity)
        self.push = self._records.append
        """Record (tick, stimulus, behaviour)."""

    def pop_all(self) -> list[tuple[int, int, int]]:
        """Pop every record, newest first (the paper's popFromSTM loop)."""
        out = list(reversed(self._records))
        self._records.clear()
        return out

    def pop_before(self, tick: int) -> list[tuple[int, int, int]]:
        """Pop the records made before `tick`, newest first; later ones stay."""
        records = self._records
        if not records or records[-1][0] < tick:
            return self.pop_all()
        keep = [r for r in records if r[0] >= tick]
        out = [r for r in reversed(records) if r[0] < tick]
        records.clear()
        records.extend(keep)
        return out

    def pop_through(self, tick: int) -> list[tuple[int, int, int]]:
        """Pop the records made at or before `tick`, newest first; later ones stay."""
        return self.pop_before(tick + 1)

    def clear(self) -> None:
        """Forget everything."""
        self._records.clear()

    def __len__(self) -> int:
        return len(self._records)

    def __iter__(self) -> Iterator[tuple[int, int, int]]:
        return iter(self._records)


class LongTermMemory:
    """Reliabilities of S-R pairs, updated by Eq. (1) when a reward pops STM."""

    def __init__(self, eta: float = 0.1, initial: Mapping[Pair, float] | None = None) -> None:
        if not 0.0 <= eta <= 1.0:
            raise ValueError("eta must be in [0, 1]")
        self.eta = eta
        self._v: dict[Pair, float] = dict(initial or {})

    def reliability(self, stimulus: int, behaviour: int) -> float:
        """V of a pair (0 if never recorded)."""
        return self._v.get((stimulus, behaviour), 0.0)

    def set(self, stimulus: int, behaviour: int, v: float) -> None:
        """Set a pair's reliability (restoring a checkpoint)."""
        if not 0.0 <= v <= 1.0:
            raise ValueError("a reliability is in [0, 1]")
        self._v[(stimulus, behaviour)] = v

    def items(self) -> Iterable[tuple[Pair, float]]:
        """Every (pair, V)."""
        return self._v.items()

    def as_dict(self) -> dict[Pair, float]:
        """A copy of every (pair, V)."""
        return dict(self._v)

    def __len__(self) -> int:
        return len(self._v)

    def apply(
        self, records: Iterable[tuple[int, int, int]], reward_tick: int, reward: float
    ) -> list[Credit]:
        """Credit popped STM records with a reward arriving at `reward_tick`.

        Pairs not yet in LTM are inserted first (at 0), as Fig. 3's insertData().
        ``d_k = reward_tick - record_tick``, at least 1.
        """
        if not -1.0 <= reward <= 1.0:
            raise ValueError("reward must be in [-1, 1]")
        eta = self.eta
        v = self._v
        credits = []
        for tick, s, b in records:
            d = max(1, reward_tick - tick)
            before = v.get((s, b), 0.0)
            after = reinforce(before, reward, eta, d)
            v[(s, b)] = after
            credits.append(Credit(tick, s, b, d, before, after))
        return credits


def credit_seen(
    stm: ShortTermMemory,
    ltm: LongTermMemory,
    reward: float,
    window: tuple[int, int],
) -> list[Credit]:
    """Credit a person's reward for the tick they saw, over the reaction window before it.

    The rule for a trainer's reward that says which tick the person was looking at when
    they pressed (`tick_seen`). With the window's first and last tick,
    ``first = tick_seen - hi_ticks`` and ``last = tick_seen - lo_ticks``
    (`ReactionWindow.span`; a paused run's ends at the seen tick itself):

    - the records of ticks ``first..last`` are credited by Eq. (1), each with
      ``d_k = last - tick + 1`` (the newest record in the window gets ``d_k = 1``);
    - records newer than ``last`` stay in `stm` for the next reward (the person has not
      reacted to them yet);
    - records older than ``first`` are popped without credit (too long before the press
      to be what it is for, as the paper's rule pops every record it credits).

    A reward without a seen tick keeps the paper's rule (`LongTermMemory.apply` over
    every record before the boundary, ``d_k`` counted from the boundary).

    Args:
        stm: the records to credit from (the run's STM, the ended episode's last records
            or a stored episode's); popped as above.
        ltm: the reliabilities updated.
        reward: the reward, in [-1, 1].
        window: the first and last tick credited.

    Returns:
        The credits, newest record first.
    """
    first, last = window
    popped = stm.pop_through(last)
    return ltm.apply([r for r in popped if r[0] >= first], last + 1, reward)
