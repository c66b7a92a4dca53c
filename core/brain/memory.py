"""The memory module: short-term memory of S-R pairs and long-term reliabilities, Eq. (1)."""

from __future__ import annotations

from collections import deque
from collections.abc import Iterable, Iterator, Mapping

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
