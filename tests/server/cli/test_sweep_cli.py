"""`srlab sweep` on the local backend: the report files, and clear errors for bad input."""

from __future__ import annotations

import json
import socket
import sys
from pathlib import Path

import pytest
from clihelpers import assert_png, exits_2

from server.backends import BackendError
from server.backends.ray import RayBackend, check_reachable
from server.cli import main

SWEEP = [
    "sweep",
    "--param",
    "eta=0.1,0.5",
    "--param",
    "epsilon=0,1",
    "--conditions",
    "kp,qlambda",
    "--seeds",
    "2",
    "--episodes",
    "3",
    "--quiet",
]


@pytest.fixture(scope="module")
def report(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("sweep")
    assert main([*SWEEP, "--jobs", "1", "--out", str(out)]) == 0
    return out


def test_sweep_writes_every_report_file(report: Path) -> None:
    assert {p.name for p in report.iterdir()} == {
        "summary.json",
        "summary.md",
        "runs.jsonl",
        "learning_curves.png",
        "param_eta.png",
        "param_epsilon.png",
    }


def test_sweep_summary_json(report: Path) -> None:
    doc = json.loads((report / "summary.json").read_text())
    params = doc["params"]
    assert params["conditions"] == ["kp", "qlambda"]
    assert (params["points"], params["tasks"], params["seeds"], params["episodes"]) == (
        4,
        2 * 2 * 2 + 2 * 2,
        2,
        3,
    )
    assert params["backend"] == "local"
    assert doc["grid"] == {"eta": [0.1, 0.5], "epsilon": [0.0, 1.0]}
    assert [p["params"] for p in doc["points"]] == [
        {"eta": 0.1, "epsilon": 0.0},
        {"eta": 0.1, "epsilon": 1.0},
        {"eta": 0.5, "epsilon": 0.0},
        {"eta": 0.5, "epsilon": 1.0},
    ]
    for p in doc["points"]:
        assert set(p["conditions"]) == {"kp", "qlambda"}
        assert p["conditions"]["kp"]["seeds"] == 2
        assert "success_by_seed" not in p["conditions"]["kp"]
    assert doc["by_parameter"]["eta"]["ignored_by"] == ["qlambda"]
    assert set(doc["by_parameter"]["epsilon"]["conditions"]) == {"kp", "qlambda"}
    assert doc["failed"] == []


def test_sweep_runs_jsonl_has_each_task_once_with_its_parameters(report: Path) -> None:
    rows = [json.loads(line) for line in (report / "runs.jsonl").read_text().splitlines()]
    assert len(rows) == (2 * 2 * 2 + 2 * 2) * 3
    qlambda = {json.dumps(r["params"]) for r in rows if r["condition"] == "qlambda"}
    assert qlambda == {'{"epsilon": 0.0}', '{"epsilon": 1.0}'}
    kp = {(r["params"]["eta"], r["params"]["epsilon"]) for r in rows if r["condition"] == "kp"}
    assert kp == {(0.1, 0.0), (0.1, 1.0), (0.5, 0.0), (0.5, 1.0)}


def test_sweep_summary_md_has_a_table_per_parameter(report: Path) -> None:
    md = (report / "summary.md").read_text()
    assert md.startswith("# srlab sweep\n")
    assert md.index("### eta") < md.index("### epsilon") < md.index("## Every setting")
    assert "![eta](param_eta.png)" in md
    assert "| 0.5 | kp |" in md
    assert "| qlambda | - | 1 |" in md  # qlambda does not use eta
    assert "## Failed tasks" not in md


@pytest.mark.parametrize("name", ["learning_curves.png", "param_eta.png", "param_epsilon.png"])
def test_sweep_plots_are_pngs(report: Path, name: str) -> None:
    assert_png(report / name)


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--param", "eta=abc"], "srlab: error: eta: 'abc' is not a number"),
        (["--param", "etta=0.1"], "srlab: error: unknown parameter 'etta' (known: eta,"),
        (["--param", "eta"], "srlab: error: --param takes NAME=V1,V2,..., got 'eta'"),
        (["--param", "eta=0.1,3"], "srlab: error: eta must be in [0, 1], got 3"),
        (["--param", "eta=0.1", "--param", "eta=0.2"], "--param eta is given twice"),
        (
            ["--param", "alpha=0.1", "--conditions", "kp"],
            "--param alpha applies to none of the conditions kp (it applies to qlambda)",
        ),
        (["--param", "eta=0.1", "--conditions", "kp,bogus"], "unknown condition 'bogus'"),
        (["--param", "eta=0.1", "--seeds", "0"], "argument --seeds: must be at least 1"),
        (
            ["--param", "eta=0.1", "--address", "auto"],
            "srlab: error: --address and --ship-code need --backend ray",
        ),
        (["--param", "eta=0.1", "--backend", "dask"], "argument --backend: invalid choice"),
    ],
)
def test_sweep_bad_arguments_exit_2_and_write_nothing(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], argv: list[str], message: str
) -> None:
    out = tmp_path / "out"
    err = exits_2(["sweep", *argv, "--episodes", "1", "--out", str(out), "--quiet"], capsys)
    assert message in err
    assert not out.exists()


def test_sweep_needs_a_param(capsys: pytest.CaptureFixture[str]) -> None:
    err = exits_2(["sweep", "--conditions", "kp"], capsys)
    assert "the following arguments are required: --param" in err


def closed_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@pytest.mark.parametrize("command", ["sweep", "experiment"])
@pytest.mark.parametrize("scheme", ["", "ray://"])
def test_an_unreachable_ray_address_is_a_clear_error_at_once(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], command: str, scheme: str
) -> None:
    address = f"{scheme}127.0.0.1:{closed_port()}"
    argv = [command, "--backend", "ray", "--address", address, "--out", str(tmp_path / "o")]
    if command == "sweep":
        argv += ["--param", "eta=0.1"]
    err = exits_2([*argv, "--quiet"], capsys)
    assert f"srlab: error: cannot reach the Ray cluster at '{address}'" in err
    assert not (tmp_path / "o").exists()


def test_ray_address_from_the_environment_is_checked_too(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    address = f"127.0.0.1:{closed_port()}"
    monkeypatch.setenv("RAY_ADDRESS", address)
    backend = RayBackend(None, 2)
    assert backend.address == address
    with pytest.raises(BackendError, match="cannot reach the Ray cluster"):
        check_reachable(backend.address)


@pytest.mark.parametrize("address", ["nowhere", "host:port", "http://h:1", "ray://:10001"])
def test_a_malformed_ray_address_is_refused(address: str) -> None:
    with pytest.raises(BackendError, match="use auto, HOST:PORT or ray://HOST:PORT"):
        check_reachable(address)


def test_without_ray_installed_the_ray_backend_says_how_to_get_it(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setitem(sys.modules, "ray", None)  # `import ray` raises ImportError
    argv = ["sweep", "--param", "eta=0.1", "--backend", "ray", "--out", str(tmp_path / "o")]
    err = exits_2([*argv, "--quiet"], capsys)
    assert "srlab: error: the ray backend needs Ray: pip install 'srlab[ray]'" in err
    assert not (tmp_path / "o").exists()
