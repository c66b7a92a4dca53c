"""The behaviour network: the S-R associations releasers fire on."""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from dataclasses import dataclass, replace

from core.brain.catalog import AssociationSpec, Catalog, Source
from core.errors import LockedAssociationError


@dataclass(frozen=True, slots=True)
class Association:
    """One releaser: stimulus -> behaviour with a strength, a source and a lock."""

    stimulus: int
    behaviour: int
    strength: float
    source: Source
    locked: bool = False


class BehaviourNetwork:
    """S-R associations by stimulus, as the releasers read them each tick.

    Learning writes `learned` and `kp` associations; it never overwrites a locked one nor
    one that was designed (innate, dp, expert), which is how a DP programmer's edits and the
    innate knowledge stay put.
    """

    def __init__(self, n_stimuli: int, associations: Iterable[Association] = ()) -> None:
        self._by_stimulus: list[dict[int, Association]] = [{} for _ in range(n_stimuli)]
        self.version = 0
        for a in associations:
            self._by_stimulus[a.stimulus][a.behaviour] = a

    @classmethod
    def from_specs(cls, catalog: Catalog, specs: Iterable[AssociationSpec]) -> BehaviourNetwork:
        """A network from a knowledge set's associations."""
        return cls(
            len(catalog.stimuli),
            (
                Association(
                    catalog.stimulus(a.stimulus).id,
                    catalog.behaviour(a.behaviour).id,
                    a.strength,
                    a.source,
                    a.locked,
                )
                for a in specs
            ),
        )

    def releasers(self, stimulus: int) -> Iterable[Association]:
        """The associations a stimulus releases."""
        return self._by_stimulus[stimulus].values()

    def get(self, stimulus: int, behaviour: int) -> Association | None:
        """The association stimulus -> behaviour, if there is one."""
        return self._by_stimulus[stimulus].get(behaviour)

    def strongest(self, stimulus: int) -> float:
        """The strongest association of a stimulus (0 if it has none)."""
        d = self._by_stimulus[stimulus]
        return max((a.strength for a in d.values()), default=0.0)

    def __iter__(self) -> Iterator[Association]:
        for d in self._by_stimulus:
            yield from d.values()

    def __len__(self) -> int:
        return sum(len(d) for d in self._by_stimulus)

    def put(self, association: Association, *, force: bool = False) -> None:
        """Add or replace an association; a locked one is only replaced with `force`."""
        old = self._by_stimulus[association.stimulus].get(association.behaviour)
        if old is not None and old.locked and not force:
            raise LockedAssociationError(
                f"association {association.stimulus}->{association.behaviour} is locked"
            )
        self._by_stimulus[association.stimulus][association.behaviour] = association
        self.version += 1

    def remove(self, stimulus: int, behaviour: int, *, force: bool = False) -> bool:
        """Remove an association; returns whether there was one."""
        old = self._by_stimulus[stimulus].get(behaviour)
        if old is None:
            return False
        if old.locked and not force:
            raise LockedAssociationError(f"association {stimulus}->{behaviour} is locked")
        del self._by_stimulus[stimulus][behaviour]
        self.version += 1
        return True

    def learn(self, stimulus: int, behaviour: int, strength: float, source: Source) -> bool:
        """Set a learned association's strength, unless another owns the pair.

        A design, a lock or the other learner owns it: LTM learning and KP never relabel
        each other's pairs. Returns whether the network changed.
        """
        old = self._by_stimulus[stimulus].get(behaviour)
        if old is not None and (old.locked or old.source != source):
            return False
        if old is not None and old.strength == strength and old.source == source:
            return False
        new = (
            Association(stimulus, behaviour, strength, source)
            if old is None
            else replace(old, strength=strength, source=source)
        )
        self._by_stimulus[stimulus][behaviour] = new
        self.version += 1
        return True

    def copy(self) -> BehaviourNetwork:
        """An independent copy."""
        return BehaviourNetwork(len(self._by_stimulus), iter(self))
