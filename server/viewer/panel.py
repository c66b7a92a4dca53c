"""The 3D view's panel: its inputs, the commands they post, and what it shows of the state.

`Panel` is the part of `server.viewer.render.Renderer` that owns the panel's inputs.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable
from typing import Any

import viser

from server.viewer.inbound import guard_panel
from server.viewer.nodes import Cache
from server.viewer.replay import SPEEDS
from server.viewer.scene import TickView, decision_markdown
from server.viewer.state import (
    ChangeRate,
    GiveReward,
    Seek,
    SelectEpisode,
    SelectRun,
    SetMode,
    SetSpeed,
    ShowNotice,
    TogglePlay,
    ViewerCommand,
    ViewState,
)

log = logging.getLogger("srlab.viewer")

NO_RUNS = "(no runs yet)"
NO_EPISODES = "(no stored episodes)"


def run_label(run_id: int, condition: str, mode: str) -> str:
    """A dropdown entry; it starts with ``#<id>`` so the id can be read back."""
    return f"#{run_id} {condition} {mode}"


def _number(value: object) -> float:
    """A panel control's value as a finite float (ValueError otherwise, TypeError for bools)."""
    if isinstance(value, bool) or not isinstance(value, int | float | str):
        raise TypeError(f"not a number: {value!r}")
    x = float(value)
    if not math.isfinite(x):
        raise ValueError(f"not a finite number: {value!r}")
    return x


def run_of_label(label: str) -> int | None:
    """The run id of a dropdown entry, None for the placeholder."""
    head = label.split(" ", 1)[0]
    if head.startswith("#") and head[1:].isdigit():
        return int(head[1:])
    return None


def speed_label(speed: float) -> str:
    """A replay speed as the dropdown shows it."""
    return f"{speed:g}x"


def episode_of_label(label: str) -> int | None:
    """The episode number of an episode dropdown entry."""
    head = label.split(" ", 1)[0]
    return int(head) if head.isdigit() else None


def _assign(handle: Any, value: object) -> None:
    """Set a panel input's value.

    viser's setter takes more types than its getter gives, which mypy cannot express.
    """
    handle.value = value


def run_heading(state: ViewState) -> str:
    """The panel's first line: the run shown (its condition, unless a participant's view)."""
    live = state.live
    if state.run_id is None or live is None:
        return "**srlab**: no run selected. Create one in the editor or with `srlab run`."
    mode = f"realtime {live.hz:g} Hz" if live.realtime else "fast"
    world = f", world {live.world}" if live.world else ""
    text = (
        f"**Run {live.run_id}**: {f'{live.condition}, ' if live.condition else ''}"
        f"seed {live.seed}{world}, {mode}, "
        f"**{live.status}**"
    )
    if not live.ticking and state.mode == "live":
        text += ". Not running now: **Replay** shows its stored episodes."
    return text


class Panel:
    """The panel's inputs: built once, their callbacks posting commands; each frame shows the state.

    A part of `Renderer`, which sets what is declared here.
    """

    server: viser.ViserServer | viser.ClientHandle
    post: Callable[[ViewerCommand], None]
    _cache: Cache

    def _build_panel(self) -> None:
        gui = self.server.gui
        post = self.post
        # Before the inputs exist: a socket may send values as soon as it learns their ids.
        guard_panel(gui, lambda problem: post(ShowNotice(f"**Refused:** {problem}")))
        gui.configure_theme(show_share_button=False, control_width="medium")
        # Docked, the panel takes its own strip and the canvas the rest: floating over the
        # canvas, it covered the track's right side (and the robot there) at 1024 px.
        gui.main_panel.dock_right()
        gui.set_panel_label("srlab 3D view")
        self._header = gui.add_markdown("**srlab**: waiting for a run")
        self._runs = gui.add_dropdown("Run", (NO_RUNS,))
        self._mode = gui.add_button_group("View", ("Live", "Replay"))
        self._live_folder = gui.add_folder("Live run")
        with self._live_folder:
            self._rate = gui.add_slider("Tick rate (Hz)", 1.0, 100.0, 1.0, 10.0)
            self._plus = gui.add_button("+ reward", color="green", hint="reward +1 now")
            self._minus = gui.add_button("- reward", color="red", hint="reward -1 now")
        self._replay_folder = gui.add_folder("Replay", visible=False)
        with self._replay_folder:
            self._episode = gui.add_dropdown("Episode", (NO_EPISODES,))
            self._play = gui.add_button("Play")
            # Counted from 1, as the decision panel counts an episode's ticks.
            self._scrub = gui.add_slider("Tick", 1, 2, 1, 1)
            self._speed = gui.add_dropdown(
                "Speed", tuple(speed_label(s) for s in SPEEDS), initial_value=speed_label(1.0)
            )
        self._decision = gui.add_markdown("")
        self._notice = gui.add_markdown("")

        def command(make: Callable[[viser.GuiEvent[Any]], ViewerCommand | None]) -> Any:
            """A callback that posts `make(event)`: a value it cannot read is ignored.

            `guard_panel` refuses what viser's page would not send; whatever else cannot be
            read must not leave a failed task ("Task exception was never retrieved") in
            viser's loop either.
            """

            async def callback(event: viser.GuiEvent[Any]) -> None:
                try:
                    made = make(event)
                except (TypeError, ValueError, AttributeError, OverflowError) as e:
                    log.warning("the 3D view ignored a malformed panel value: %s", e)
                    return
                if made is not None:
                    post(made)

            return callback

        def from_client(event: viser.GuiEvent[Any]) -> bool:
            return event.client_id is not None

        # Callbacks run on viser's event loop: they only hand commands on. Assignments
        # made here by the renderer call them too, without a client: those are ignored.
        self._runs.on_update(
            command(
                lambda e: (
                    SelectRun(run)
                    if from_client(e) and (run := run_of_label(self._runs.value)) is not None
                    else None
                )
            )
        )
        self._mode.on_click(
            command(lambda e: SetMode("replay" if self._mode.value == "Replay" else "live"))
        )
        self._rate.on_update(
            command(lambda e: ChangeRate(_number(self._rate.value)) if from_client(e) else None)
        )
        self._plus.on_click(command(lambda e: GiveReward(1.0, e.client_id)))
        self._minus.on_click(command(lambda e: GiveReward(-1.0, e.client_id)))
        self._episode.on_update(
            command(
                lambda e: (
                    SelectEpisode(n)
                    if from_client(e) and (n := episode_of_label(self._episode.value)) is not None
                    else None
                )
            )
        )
        self._play.on_click(command(lambda e: TogglePlay()))
        self._scrub.on_update(
            command(lambda e: Seek(int(_number(self._scrub.value)) - 1) if from_client(e) else None)
        )
        self._speed.on_update(
            command(
                lambda e: (
                    SetSpeed(_number(str(self._speed.value).rstrip("x")))
                    if from_client(e)
                    else None
                )
            )
        )

    def _draw_panel(self, state: ViewState, view: TickView | None, now: float) -> None:
        changed = self._cache.changed
        options = tuple(r.label for r in state.runs) or (NO_RUNS,)
        if changed("runs.options", options):
            self._runs.options = options
        selected = next((r.label for r in state.runs if r.id == state.run_id), options[0])
        if changed("runs.value", selected):
            _assign(self._runs, selected)
        replaying = state.mode == "replay"
        any_run = state.only is None  # else one run, read-only: no run list, no controls
        if changed("mode", (replaying, any_run)):
            self._live_folder.visible = not replaying and any_run
            self._replay_folder.visible = replaying
        if changed("only", any_run):
            self._runs.visible = any_run
        live = state.live
        if live is not None and changed("rate", (live.run_id, live.hz)):
            _assign(self._rate, float(min(max(round(live.hz), 1), 100)))
        writable = live is not None and live.ticking and state.writable
        if changed("writable", (writable, live is not None and live.realtime)):
            self._plus.disabled = not writable
            self._minus.disabled = not writable
            self._rate.disabled = not (writable and live is not None and live.realtime)
        episodes = tuple(label for _, label in state.episodes) or (NO_EPISODES,)
        if changed("episodes", episodes):
            self._episode.options = episodes
        if state.replay is not None:
            label = next((lb for n, lb in state.episodes if n == state.replay.episode), None)
            if label is not None and changed("episode", label):
                _assign(self._episode, label)
        clock = state.clock
        if clock is not None:
            if changed("scrub.max", clock.ticks):
                self._scrub.max = max(clock.ticks, 2)
            index = clock.at(now)
            if changed("scrub", index):
                _assign(self._scrub, index + 1)  # the episode tick the panel shows
            if changed("play", clock.playing):
                self._play.label = "Pause" if clock.playing else "Play"
            if changed("speed", clock.speed):
                _assign(self._speed, speed_label(clock.speed))
        header = run_heading(state)
        if changed("header", header):
            self._header.content = header
        heading = state.replay.heading() if replaying and state.replay else "**Decision**"
        text = decision_markdown(
            view, "replay" if replaying else "live", heading, blind=state.blind
        )
        if changed("decision", text):
            self._decision.content = text
        if changed("notice", state.notice):
            self._notice.content = state.notice
