"""Conditions as data: the built-in file, a researcher's files, and their errors."""

from __future__ import annotations

import hashlib
from dataclasses import replace
from pathlib import Path

import pytest

from core.brain.catalog import load_catalog
from core.errors import ConditionFileError
from core.run.conditions import (
    CONDITIONS,
    condition_definition,
    load_conditions,
    parse_condition_file,
    trainer_names,
)
from core.run.setup import Setup

BUILT_IN_DIGEST = "310556885a7e74be0636238152a6ce58"
"""md5 of the built-in conditions' reprs, one a line, as they were defined in Python before
they became data: the results were made with exactly these."""


SIGNAL_CONDITIONS = ("kp-signal", "beacon", "beacon-reflexes")
"""The stop-line beacon's conditions (`docs/results/signal-kp/`), defined after the digest."""


def test_the_built_in_conditions_are_the_ones_the_results_were_made_with() -> None:
    text = "".join(f"{c!r}\n" for c in CONDITIONS.values() if c.name not in SIGNAL_CONDITIONS)
    assert hashlib.md5(text.encode()).hexdigest() == BUILT_IN_DIGEST
    assert list(CONDITIONS)[:3] == ["innate", "delayed", "dp"]


def test_the_built_in_conditions_pass_the_checks_a_researchers_file_gets() -> None:
    text = (Path(__file__).parents[3] / "core" / "data" / "conditions.toml").read_text()
    knowledge = load_catalog().knowledge
    checked = parse_condition_file(text, "conditions.toml", {}, lambda n: n in knowledge)
    assert checked == tuple(CONDITIONS.values())
    assert "rp" in trainer_names()


def write(tmp_path: Path, text: str, name: str = "mine.toml") -> Path:
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return path


def test_a_condition_based_on_a_built_in_one_changes_only_what_it_says(tmp_path: Path) -> None:
    path = write(
        tmp_path,
        '[[condition]]\nname = "kp-eager"\ndescription = "kp exploring more"\n'
        'based_on = "kp"\nepsilon = 0.3\n\n'
        '[[condition]]\nname = "kp-eager-rp"\nbased_on = "kp-eager"\ntrainer = "rp"\n'
        "teacher = { mistake = 0.1 }\n",
    )
    eager, with_rp = load_conditions(path)
    assert eager == replace(CONDITIONS["kp"], name="kp-eager", description="kp exploring more",
                            epsilon=0.3)  # fmt: skip
    assert with_rp.epsilon == 0.3 and with_rp.trainer == "rp" and with_rp.teacher.mistake == 0.1
    assert condition_definition(with_rp)["teacher"] == {"mistake": 0.1}


def test_a_condition_from_scratch_takes_the_defaults(tmp_path: Path) -> None:
    (c,) = load_conditions(write(tmp_path, '[[condition]]\nname = "plain"\nnetwork = "innate"\n'))
    assert c.network == "innate" and c.learning is False and c.epsilon == 0.0 and c.kp is False
    assert c.learnable_sensors == ("signal", "camera_obstacle")


@pytest.mark.parametrize(
    ("body", "line", "reason"),
    [
        ('name = "a"\nnetwork = "kp"\nepsilonn = 0.2\n', 4, "unknown key 'epsilonn'"),
        ('name = "a"\nnetwork = "kp"\nepsilon = "lots"\n', 4, "epsilon must be a number"),
        ('name = "a"\nnetwork = "kp"\nlearning = 1\n', 4, "learning must be true or false"),
        ('name = "a"\nnetwork = "kp"\nepsilon = 1.5\n', 4, "epsilon must be in [0, 1]"),
        ('name = "a"\nnetwork = "my-net"\n', 3, "network: 'my-net' is no network"),
        ('name = "a"\nbased_on = "kpp"\n', 3, "based_on 'kpp' names no condition"),
        ('name = "a"\n', 1, "a condition needs a network"),
        ('name = "kp"\nnetwork = "kp"\n', 2, "the name 'kp' is taken by a built-in condition"),
        ('name = "a"\nbased_on = "kp"\ntrainer = "coach"\n', 4, "unknown reinforcement program"),
        ('name = "a"\nbased_on = "kp"\nagent = "sarsa"\n', 4, "agent must be one of"),
        ('name = "a"\nbased_on = "kp"\nlearnable_sensors = ["lidar"]\n', 4, "unknown sensor"),
        ('name = "a"\nbased_on = "rp"\nteacher = { patience = 1 }\n', 4, "unknown imperfections"),
        ('name = "a"\nbased_on = "rp"\nteacher = { mistake = 2 }\n', 4, "mistake must be in"),
        ('name = "a"\nbased_on = "kp"\nextra_networks = ["sig"]\n', 4, "'sig' is no network"),
    ],
)
def test_a_bad_condition_is_refused_naming_the_file_the_entry_its_line_and_why(
    tmp_path: Path, body: str, line: int, reason: str
) -> None:
    path = write(tmp_path, "# mine\n[[condition]]\n" + body)
    with pytest.raises(ConditionFileError) as e:
        load_conditions(path)
    message = str(e.value)
    assert message.startswith(f"{path}: condition ")
    assert f"(line {line + 1})" in message
    assert reason in message


@pytest.mark.parametrize(
    ("text", "reason"),
    [
        ("[[condition]\nname = 'a'\n", "Expected"),
        ("title = 'x'\n", "unknown table or key 'title'"),
        ("", r"no \[\[condition\]\] table"),
    ],
)
def test_a_file_that_is_no_condition_file_is_refused_naming_it(
    tmp_path: Path, text: str, reason: str
) -> None:
    path = write(tmp_path, text)
    with pytest.raises(ConditionFileError, match=reason) as e:
        load_conditions(path)
    assert str(e.value).startswith(str(path))


def test_a_missing_file_is_refused_naming_it(tmp_path: Path) -> None:
    with pytest.raises(ConditionFileError, match="No such file"):
        load_conditions(tmp_path / "nowhere.toml")


def test_a_setup_carries_its_conditions_and_looks_them_up_before_the_built_ins(
    tmp_path: Path,
) -> None:
    (mine,) = load_conditions(
        write(tmp_path, '[[condition]]\nname = "mine"\nbased_on = "sonar"\nepsilon = 0.2\n')
    )
    setup = Setup(conditions=(mine,))
    assert setup.lookup("mine") is mine and setup.lookup("kp") is CONDITIONS["kp"]
    with pytest.raises(Exception, match="unknown condition 'yours'"):
        setup.lookup("yours")
    with pytest.raises(Exception, match="unknown condition 'mine'"):
        Setup().lookup("mine")


def test_a_setup_network_replaces_every_conditions_own() -> None:
    setup = Setup(network="expert")
    assert setup.condition(CONDITIONS["kp"]).network == "expert"
    with pytest.raises(Exception, match="is no network"):
        Setup(network="nowhere")
    with pytest.raises(Exception, match="give one"):
        Setup(network="expert", start="design")
