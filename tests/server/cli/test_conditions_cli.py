"""Conditions and networks as data on the command line: `--condition FILE`, `--network`."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest
from clihelpers import exits_2

from server.cli import main

MINE = """
[[condition]]
name = "kp-copy"
description = "kp, as a researcher's file"
based_on = "kp"

[[condition]]
name = "sonar-eager"
description = "kp's ablation exploring three times as much"
based_on = "sonar"
epsilon = 0.3
"""


def write(tmp_path: Path, name: str, text: str) -> Path:
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return path


def simulate(capsys: pytest.CaptureFixture[str], *argv: str) -> dict[str, Any]:
    capsys.readouterr()
    base = ["simulate", "--episodes", "4", "--seed", "5", "--quiet", "--json"]
    assert main([*base, *argv]) == 0
    out: dict[str, Any] = json.loads(capsys.readouterr().out)
    return out


def test_a_condition_from_a_file_runs_as_the_built_in_one_it_copies(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    mine = write(tmp_path, "mine.toml", MINE)
    copy = simulate(capsys, "--condition", f"{mine}:kp-copy")
    kp = simulate(capsys, "--condition", "kp")
    assert copy.pop("condition") == "kp-copy" and kp.pop("condition") == "kp"
    assert copy == kp


def test_a_file_of_several_conditions_needs_one_named(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    mine = write(tmp_path, "mine.toml", MINE)
    err = exits_2(["simulate", "--condition", str(mine)], capsys)
    assert "holds conditions kp-copy, sonar-eager" in err and f"{mine}:NAME" in err
    err = exits_2(["simulate", "--condition", f"{mine}:nope"], capsys)
    assert "has no condition 'nope' (it has kp-copy, sonar-eager)" in err


def test_a_network_file_is_run_as_the_built_in_network_it_holds(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    net = write(
        tmp_path, "net.toml", 'name = "my-expert"\ndescription = "mine"\ninclude = ["expert"]\n'
    )
    mine = simulate(capsys, "--condition", "innate", "--network", str(net))
    built_in = simulate(capsys, "--condition", "innate", "--network", "expert")
    expert = simulate(capsys, "--condition", "expert")
    assert mine.pop("network") == "my-expert" and built_in.pop("network") == "expert"
    for d in (mine, built_in, expert):
        d.pop("condition")
    assert mine == built_in == expert


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--condition", "kp", "--network", "nowhere"], "--network 'nowhere': no such network"),
        (["--condition", "kp", "--network", "missing.toml"], "missing.toml"),
        (["--condition", "missing.toml"], "missing.toml: No such file"),
    ],
)
def test_bad_networks_and_files_exit_2_with_a_line(
    args: list[str], message: str, capsys: pytest.CaptureFixture[str]
) -> None:
    assert message in exits_2(["simulate", "--episodes", "1", *args], capsys)


def test_a_network_and_a_start_together_are_refused(capsys: pytest.CaptureFixture[str]) -> None:
    argv = ["experiment", "--conditions", "kp", "--network", "expert", "--start", "design"]
    assert "give one" in exits_2([*argv, "--seeds", "1", "--episodes", "1"], capsys)


def test_a_condition_naming_a_missing_network_names_the_file_entry_and_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bad = write(tmp_path, "bad.toml", '[[condition]]\nname = "x"\n\nnetwork = "nets/mine"\n')
    err = exits_2(["simulate", "--condition", str(bad)], capsys)
    assert f"{bad}: condition 'x' (line 4): network: 'nets/mine' is no network" in err


def test_a_network_file_with_a_built_in_name_or_a_bad_pair_is_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    taken = write(tmp_path, "kp.toml", 'name = "kp"\n')
    err = exits_2(["simulate", "--condition", "kp", "--network", str(taken)], capsys)
    assert "has the name of a built-in network" in err
    bad = write(
        tmp_path,
        "bad.toml",
        'name = "b"\nassociations = [{ stimulus = "Lava", behaviour = "stop" }]\n',
    )
    err = exits_2(["simulate", "--condition", "kp", "--network", str(bad)], capsys)
    assert f"{bad}: network 'b' association #0: unknown stimulus 'Lava'" in err


@pytest.mark.slow
def test_an_experiment_and_a_sweep_run_a_file_condition_in_worker_processes(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    mine = write(tmp_path, "mine.toml", MINE)
    out = tmp_path / "exp"
    argv = ["experiment", "--conditions", f"sonar,{mine}", "--declare", "sonar-eager-sonar"]
    argv += ["--seeds", "2", "--episodes", "2", "--jobs", "2", "--no-probe", "--quiet"]
    assert main([*argv, "--out", str(out)]) == 0
    doc = json.loads((out / "summary.json").read_text())
    assert doc["params"]["conditions"] == ["sonar", "kp-copy", "sonar-eager"]
    eager = doc["conditions"]["sonar-eager"]
    assert eager["seeds"] == 2 and eager["definition"]["epsilon"] == 0.3
    assert "definition" not in doc["conditions"]["sonar"]
    copy, kp_like = doc["conditions"]["kp-copy"], doc["conditions"]["sonar"]
    assert copy["description"] == "kp, as a researcher's file" and kp_like["seeds"] == 2

    swept = tmp_path / "sweep"
    argv = ["sweep", "--conditions", f"{mine}:sonar-eager", "--param", "eta=0.1,0.2"]
    argv += ["--seeds", "2", "--episodes", "2", "--jobs", "2", "--quiet", "--out", str(swept)]
    assert main(argv) == 0
    sweep = json.loads((swept / "summary.json").read_text())
    assert sweep["params"]["conditions"] == ["sonar-eager"]


def test_the_guides_condition_file_runs_as_written_and_its_error_is_the_one_shown(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    guide = (Path(__file__).parents[3] / "docs" / "conditions.md").read_text()
    toml = guide.split("```toml\n")[1].split("```")[0]
    commands = guide.split("```\nsrlab simulate")[1].split("```")[0]
    simulate = "srlab simulate" + commands.splitlines()[0]
    shown = next(line for line in guide.splitlines() if line.startswith("srlab: error:"))
    monkeypatch.chdir(tmp_path)
    (tmp_path / "conditions").mkdir()
    (tmp_path / "conditions" / "eager.toml").write_text(toml)
    assert main([*simulate.split()[1:], "--quiet", "--json"]) == 0
    run = json.loads(capsys.readouterr().out)
    assert run["condition"] == "kp-eager" and run["episodes"] == 50
    (tmp_path / "conditions" / "eager.toml").write_text(toml.replace("0.3", "3.0"))
    assert exits_2(simulate.split()[1:], capsys).strip() == shown
