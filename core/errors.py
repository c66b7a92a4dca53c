"""Errors the core raises; the server maps them to its answers in one place."""


class CoreError(Exception):
    """Base of every error srlab's core raises on purpose."""


class CatalogError(CoreError):
    """A data file (stimuli, behaviours, logical sensors, networks) is malformed."""


class ConditionFileError(CatalogError):
    """A condition file that cannot be read: names the file, the entry, its line, the reason."""


class UnknownNameError(CatalogError):
    """A stimulus, behaviour, sensor, network or condition name that does not exist."""


class SimulationStateError(CoreError):
    """The simulation was used out of order, e.g. ticked before `reset`."""


class LockedAssociationError(CoreError):
    """An attempt to change an association that is locked."""


class UnknownRunError(CoreError):
    """A run id that does not exist."""


class StorageError(CoreError):
    """Storage failed (disk full, database locked, connection lost): the run stops."""


class RunStateError(CoreError):
    """A command that does not fit the run's state (a reward to a run that is not running)."""


class SeenTickError(CoreError):
    """A reward's seen tick (or its episode) the run has not reached or no longer holds.

    Args:
        field: the request's field at fault (``tick_seen`` or ``episode``).
        message: what is wrong with it.
    """

    def __init__(self, field: str, message: str) -> None:
        super().__init__(field, message)
        self.field = field
        self.message = message

    def __str__(self) -> str:
        return f"{self.field}: {self.message}"


class ExtraMissingError(CoreError):
    """A condition needs an optional extra that is not installed (e.g. srlab[baselines])."""
