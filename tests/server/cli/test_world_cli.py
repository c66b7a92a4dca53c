"""`srlab world`: list the presets, check a world file, draw one, print the schema."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from core.sim.worldfile import json_schema
from core.sim.worlds import load_world
from server.cli import main

ROOT = Path(__file__).resolve().parents[3]


def test_world_show_draws_a_preset_and_a_world_file(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    for world in ("figure-8", str(ROOT / "core" / "data" / "worlds" / "l-shape.toml"), "classic"):
        out = tmp_path / "pictures" / f"{Path(world).stem}.png"
        assert main(["world", "show", world, "--png", str(out)]) == 0
        assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
        assert capsys.readouterr().out == f"wrote {out}\n"


def test_a_bad_world_file_exits_2_with_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bad = tmp_path / "bad.toml"
    bad.write_text(
        "[track]\ncentre = [[0.6, 0.6], [6.6, 0.6], [6.6, 4.6], [0.6, 4.6]]\nwidth_m = 1.2\n"
        "signal = { segment = 2, fraction = 0.5 }\n[[track.obstacles]]\nrule = 'fixed'\n"
        "segment = 0\nalong_m = 3.0\nlateral_m = 0.9\n"
    )
    for action in (["show", str(bad), "--png", str(tmp_path / "x.png")], ["check", str(bad)]):
        with pytest.raises(SystemExit) as e:
            main(["world", *action])
        assert e.value.code == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1
        assert err.startswith(f"srlab: error: {bad}:9: track.obstacles[0].lateral_m: off the track")
    assert not (tmp_path / "x.png").exists()
    with pytest.raises(SystemExit) as e:
        main(["world", "check", "moon"])
    assert e.value.code == 2
    assert "no world preset or world file 'moon'" in capsys.readouterr().err


def test_world_list_check_and_schema(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["world", "list", "--json"]) == 0
    worlds = {w["name"]: w for w in json.loads(capsys.readouterr().out)["worlds"]}
    assert worlds["figure-8"]["track"] == "corridor"
    assert worlds["classic"]["track"] == "ring"
    assert main(["world", "check", "narrow-passage"]) == 0
    assert capsys.readouterr().out.startswith(
        "narrow-passage: world 'narrow-passage' loads: 6 segments, a lap of 21.20 m"
    )
    assert main(["world", "schema"]) == 0
    assert json.loads(capsys.readouterr().out) == json_schema()


def test_simulate_runs_on_a_world_file_given_by_its_path(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    world = tmp_path / "doorway.toml"
    world.write_text((ROOT / "core" / "data" / "worlds" / "narrow-passage.toml").read_text())
    monkeypatch.chdir(tmp_path)
    argv = ["simulate", "--condition", "expert", "--episodes", "1", "--json", "--quiet"]
    assert main([*argv, "--world", "doorway.toml"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["world"] == str(world) and out["episodes"] == 1
    world.write_text(world.read_text().replace("width_m = 1.2\n", "width_m = 1.2\nwall = 1\n"))
    load_world.cache_clear()
    with pytest.raises(SystemExit) as e:
        main([*argv, "--world", "doorway.toml"])
    assert e.value.code == 2
    assert f"argument --world: {world}:" in capsys.readouterr().err


def test_the_picture_shades_a_seeded_area_only_where_an_obstacle_is_seeded(tmp_path: Path) -> None:
    from core.sim.types import build_geometry
    from server.reports.world_picture import seeded_spans

    text = (ROOT / "core" / "data" / "worlds" / "u-shape.toml").read_text()
    assert seeded_spans(build_geometry(load_world("u-shape").config.track))
    fixed = text.replace('rule = "seeded"', 'rule = "fixed"\nsegment = 0\nalong_m = 4.0')
    (tmp_path / "fixed.toml").write_text(fixed)
    world = load_world(str(tmp_path / "fixed.toml"))
    assert seeded_spans(build_geometry(world.config.track)) == []
