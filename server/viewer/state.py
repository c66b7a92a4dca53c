"""What passes between the service's event loop and the 3D view's threads.

The controller (on the service's event loop) owns the view's state and replaces it as a
whole, immutable `ViewState`; live ticks go through a bounded deque. The renderer thread
reads both and draws. Panel controls, which viser calls back on its own thread, become
`ViewerCommand`s handed to the event loop. Nothing here touches the core.
"""

from __future__ import annotations

import threading
import time
from collections import deque
from dataclasses import dataclass

from server.viewer.replay import Replay, ReplayClock
from server.viewer.scene import Mode, TickView


@dataclass(frozen=True, slots=True)
class RunChoice:
    """A run the panel's dropdown offers."""

    id: int
    label: str
    live: bool


@dataclass(frozen=True, slots=True)
class LiveInfo:
    """The selected run as the controller last saw it."""

    run_id: int
    condition: str
    """"" in a study participant's view: they are not told it."""
    seed: int
    status: str
    realtime: bool
    hz: float
    ticking: bool
    """An engine of this process runs it (running or paused)."""
    world: str = ""
    """Its world preset ("" for the default: a run stored before runs kept it)."""


@dataclass(frozen=True, slots=True)
class ViewState:
    """Everything the renderer shows besides live ticks; replaced whole on each change."""

    clients: int = 0
    runs: tuple[RunChoice, ...] = ()
    run_id: int | None = None
    mode: Mode = "live"
    live: LiveInfo | None = None
    episodes: tuple[tuple[int, str], ...] = ()
    """The selected run's stored episodes: number and a label."""
    replay: Replay | None = None
    clock: ReplayClock | None = None
    writable: bool = True
    """Panel rewards and rate changes are allowed (the service listens on loopback only)."""
    only: int | None = None
    """The one run this view may show, read-only (a participant's): no run list, no
    rewards or rate from its panel."""
    notice: str = ""
    version: int = 0
    """Bumped when the selected run or replay changes: the renderer starts afresh."""

    @property
    def blind(self) -> bool:
        """A study participant's view: nothing in it tells them their condition."""
        return self.only is not None


@dataclass(frozen=True, slots=True)
class SelectRun:
    """Show another run."""

    run_id: int


@dataclass(frozen=True, slots=True)
class SetMode:
    """Switch between the live run and replay."""

    mode: Mode


@dataclass(frozen=True, slots=True)
class SelectEpisode:
    """Load a stored episode of the selected run for replay."""

    episode: int


@dataclass(frozen=True, slots=True)
class TogglePlay:
    """Play or pause the replay."""


@dataclass(frozen=True, slots=True)
class Seek:
    """Jump to a tick index of the replay."""

    index: int


@dataclass(frozen=True, slots=True)
class SetSpeed:
    """Change the replay's speed."""

    speed: float


@dataclass(frozen=True, slots=True)
class ChangeRate:
    """Change the selected realtime run's tick rate (the engine's own `set_rate`)."""

    hz: float


@dataclass(frozen=True, slots=True)
class GiveReward:
    """A trainer's reward to the selected run (the engine's own `reward`, as over HTTP).

    `client` is the viewer (viser's client id) it came from: each has its own rate limit.
    """

    value: float
    client: int | None = None


@dataclass(frozen=True, slots=True)
class ClientsChanged:
    """A browser connected or left."""

    clients: int


@dataclass(frozen=True, slots=True)
class RefreshRuns:
    """Read the run list again."""


@dataclass(frozen=True, slots=True)
class ShowNotice:
    """Tell the viewer something on its panel (why a value it sent was refused)."""

    text: str


ViewerCommand = (
    SelectRun
    | SetMode
    | SelectEpisode
    | TogglePlay
    | Seek
    | SetSpeed
    | ChangeRate
    | GiveReward
    | ClientsChanged
    | RefreshRuns
    | ShowNotice
)


class Inbox:
    """The controller's state and live ticks, for the renderer thread.

    `publish` and `push` are called on the event loop; `wake` tells the renderer there is
    something new. Replacing `state` and appending to the deque are atomic, so no lock.
    """

    def __init__(self, max_ticks: int = 512) -> None:
        self.state = ViewState()
        self.ticks: deque[TickView] = deque(maxlen=max_ticks)
        self.pushed_at = 0.0
        """When the newest live tick was pushed (time.monotonic)."""
        self.wake = threading.Event()

    def publish(self, state: ViewState) -> None:
        """Replace the view's state."""
        self.state = state
        self.wake.set()

    def push(self, view: TickView) -> None:
        """A live tick to draw (the oldest is dropped when the renderer is behind)."""
        self.ticks.append(view)
        self.pushed_at = time.monotonic()
        self.wake.set()

    def drain(self) -> list[TickView]:
        """Every tick pushed since the last drain, oldest first."""
        out = []
        while True:
            try:
                out.append(self.ticks.popleft())
            except IndexError:
                return out


__all__ = [
    "ChangeRate",
    "ClientsChanged",
    "GiveReward",
    "Inbox",
    "LiveInfo",
    "RefreshRuns",
    "RunChoice",
    "Seek",
    "SelectEpisode",
    "SelectRun",
    "SetMode",
    "SetSpeed",
    "ShowNotice",
    "TogglePlay",
    "ViewState",
    "ViewerCommand",
]
