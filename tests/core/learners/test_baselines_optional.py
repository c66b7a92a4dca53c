"""core.learners.baselines without its extra: it imports, says how to install it."""

from __future__ import annotations

import subprocess
import sys

import pytest

from core.learners.baselines import (
    INSTALL_HINT,
    USED_BY,
    BaselineConfig,
    BaselinesUnavailableError,
    run_baseline,
)
from core.params import ParameterError
from core.run.setup import Setup


def test_core_baselines_imports_without_torch_or_stable_baselines3() -> None:
    code = (
        "import sys\n"
        "sys.modules.update(torch=None, stable_baselines3=None)\n"
        "import core.learners.baselines\n"
        "assert 'torch' not in [m for m in sys.modules if sys.modules[m] is not None]\n"
    )
    subprocess.run([sys.executable, "-c", code], check=True)


@pytest.mark.parametrize("missing", ["stable_baselines3", "torch"])
def test_running_without_the_extra_names_the_command_that_installs_it(
    monkeypatch: pytest.MonkeyPatch, missing: str
) -> None:
    monkeypatch.setitem(sys.modules, missing, None)  # what an absent package looks like
    with pytest.raises(BaselinesUnavailableError, match=INSTALL_HINT):
        run_baseline("dqn", 0, 1, Setup())


def test_parameters_set_by_name_as_the_right_kind() -> None:
    cfg = BaselineConfig.with_params("dqn", {"epsilon": 0.2, "target_update_interval": 100.0})
    assert cfg.epsilon == 0.2
    assert cfg.target_update_interval == 100 and isinstance(cfg.target_update_interval, int)
    assert BaselineConfig.with_params("ppo", None) == BaselineConfig()


def test_every_field_is_used_by_some_algorithm() -> None:
    names = set(BaselineConfig.__dataclass_fields__)
    assert set().union(*USED_BY.values()) == names


@pytest.mark.parametrize(
    ("algo", "params", "message"),
    [
        ("ppo", {"epsilon": 0.1}, "ppo does not use epsilon"),
        ("dqn", {"ent_coef": 0.1}, "dqn does not use ent_coef"),
        ("dqn", {"nonsense": 1.0}, "dqn does not use nonsense"),
        ("dqn", {"batch_size": 2.5}, "whole number"),
        ("dqn", {"batch_size": 0.0}, "batch_size must be >= 1"),
        ("dqn", {"epsilon": 1.5}, r"epsilon must be in \[0, 1\]"),
        ("ppo", {"learning_rate": 0.0}, r"learning_rate must be in \(0, 1\]"),
    ],
)
def test_parameters_out_of_place_or_bounds_are_refused(
    algo: str, params: dict[str, float], message: str
) -> None:
    with pytest.raises(ParameterError, match=message):
        BaselineConfig.with_params(algo, params)  # type: ignore[arg-type]


def test_an_unknown_algorithm_is_refused() -> None:
    with pytest.raises(ValueError, match="unknown algorithm 'a2c'"):
        run_baseline("a2c", 0, 1, Setup())  # type: ignore[arg-type]


def test_a_deep_condition_without_the_extra_is_refused_before_anything_runs(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    from core.errors import ExtraMissingError
    from core.lab.experiment import parse_conditions
    from server.cli import main

    monkeypatch.setitem(sys.modules, "stable_baselines3", None)
    with pytest.raises(ExtraMissingError, match=r"dqn, ppo need the srlab\[baselines\] extra"):
        parse_conditions("kp,dqn,ppo")
    assert parse_conditions("kp,sonar") == ["kp", "sonar"]
    with pytest.raises(SystemExit) as e:
        main(["experiment", "--conditions", "kp,dqn", "--seeds", "1", "--episodes", "1"])
    assert e.value.code == 2
    err = capsys.readouterr().err
    assert "dqn needs the srlab[baselines] extra" in err and INSTALL_HINT in err
    assert "Traceback" not in err
