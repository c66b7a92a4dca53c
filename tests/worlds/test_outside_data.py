"""An outside world's bad data files: one error naming the file, the entry and the reason."""

from __future__ import annotations

import shutil
import sys
from pathlib import Path

import pytest
from clihelpers import exits_2

from core.errors import ExtraMissingError
from core.outside.world import OutsideWorldError, load_outside, outside_folder, outside_names


@pytest.fixture
def world(tmp_path: Path) -> Path:
    folder = tmp_path / "mine"
    shutil.copytree(outside_folder() / "minigrid-dynamic", folder)
    return folder


def _edit(path: Path, old: str, new: str) -> None:
    text = path.read_text()
    assert old in text
    path.write_text(text.replace(old, new, 1))


def test_the_shipped_worlds_load_without_their_environments() -> None:
    assert set(outside_names()) >= {"minigrid-dynamic", "irsim-corridor"}
    for name in outside_names():
        w = load_outside(name)
        assert {"kp", "sonar"} <= set(w.conditions)
        assert w.conditions["kp"].kp and not w.conditions["sonar"].kp
        assert len(w.actions) == len(w.catalog.behaviours)
        high = {s.objective for s in w.catalog.stimuli if s.level == "high"}
        low = {s.objective for s in w.catalog.stimuli if s.level == "low"}
        assert high <= low  # KP has a low-level sensor to copy from


def test_a_copied_folder_is_a_world_by_its_path(world: Path) -> None:
    assert load_outside(world).name == "mine"


def test_an_unknown_channel_names_file_entry_and_reason(world: Path) -> None:
    _edit(world / "sensors.toml", '["front_wall", ">", 0.5]', '["front_lava", ">", 0.5]')
    with pytest.raises(OutsideWorldError) as e:
        load_outside(world)
    message = str(e.value)
    assert str(world / "sensors.toml") in message
    assert "sensor 'wall' stimulus #0 (WallAhead)" in message
    assert "unknown channel 'front_lava'" in message


def test_an_unknown_action_names_the_behaviour(world: Path) -> None:
    _edit(world / "behaviours.toml", 'action = "left"', 'action = "jump"')
    with pytest.raises(OutsideWorldError, match=r"behaviours.toml: behaviour 'left': unknown "
                       r"action 'jump' \(the world's: left, right, forward\)"):  # fmt: skip
        load_outside(world)


def test_a_mode_reading_srlab_odometry_is_refused(world: Path) -> None:
    _edit(world / "behaviours.toml", "ticks = 1\n", 'ticks = 1\nmode = "align"\n')
    with pytest.raises(OutsideWorldError, match="behaviour 'forward': mode must be 'constant'"):
        load_outside(world)


def test_a_network_naming_an_unknown_stimulus(world: Path) -> None:
    _edit(world / "networks" / "reflex.toml", '"BallAhead_LeftFree"', '"BallBehind"')
    with pytest.raises(OutsideWorldError) as e:
        load_outside(world)
    assert str(e.value) == (
        f"{world / 'networks' / 'reflex.toml'}: network 'reflex' association #0: unknown "
        "stimulus 'BallBehind'"
    )


def test_a_condition_naming_a_missing_network(world: Path) -> None:
    _edit(world / "conditions.toml", 'network = "copy"', 'network = "nowhere"')
    with pytest.raises(OutsideWorldError) as e:
        load_outside(world)
    assert str(world / "conditions.toml") in str(e.value)
    assert "condition 'copy' (line 18): network: 'nowhere' is no network" in str(e.value)


def test_learnable_sensors_are_the_worlds_own(world: Path) -> None:
    _edit(
        world / "conditions.toml",
        'learnable_sensors = ["view"]',
        'learnable_sensors = ["camera_obstacle"]',
    )
    with pytest.raises(OutsideWorldError, match="unknown sensor 'camera_obstacle'"):
        load_outside(world)


def test_the_cli_says_which_world_is_unknown(capsys: pytest.CaptureFixture[str]) -> None:
    err = exits_2(["outside", "check", "atlantis"], capsys)
    assert "unknown outside world 'atlantis'" in err
    assert "minigrid-dynamic" in err


@pytest.mark.parametrize(("name", "package"), [("minigrid-dynamic", "minigrid"),
                                               ("irsim-corridor", "irsim")])  # fmt: skip
def test_a_world_without_its_package_says_how_to_install_it(
    name: str, package: str, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setitem(sys.modules, package, None)  # as if the extra were not installed
    with pytest.raises(ExtraMissingError, match=rf"needs '{package}', of the srlab\[worlds\] "
                       r"extra: run `make install-worlds`"):  # fmt: skip
        load_outside(name).make()
    err = exits_2(["outside", "check", name, "--seeds", "1"], capsys)
    assert "make install-worlds" in err


def test_a_learning_condition_must_name_the_worlds_sensors(world: Path) -> None:
    (world / "conditions.toml").write_text(
        '[[condition]]\nname = "eager"\nnetwork = "reflex"\nlearning = true\n'
    )
    with pytest.raises(OutsideWorldError, match=r"condition 'eager': it learns, but its "
                       r"learnable_sensors \(signal, camera_obstacle\) name none"):  # fmt: skip
        load_outside(world)
