"""`srlab study create|add|status|forget` on a SQLite file: what is stored, and bad input."""

from __future__ import annotations

import csv
import sqlite3
from pathlib import Path

import pytest
from apphelpers import migrated_copy
from clihelpers import exits_2

from core.studies import token_digest
from server.cli import main
from server.cli.common import counted


@pytest.fixture
def db(tmp_path: Path) -> tuple[str, Path]:
    path = tmp_path / "srlab.db"
    return migrated_copy(path), path


@pytest.fixture
def consent(tmp_path: Path) -> Path:
    path = tmp_path / "consent.txt"
    path.write_text("You will train a simulated robot.\n")
    return path


def create_argv(url: str, consent: Path, *extra: str) -> list[str]:
    return [
        "study", "create", "pilot", "--conditions", "kp,trainer", "--episodes", "3",
        "--consent-file", str(consent), "--consent-version", "v2", "--completion-code", "C0DE42",
        "--url", url, *extra,
    ]  # fmt: skip


def test_a_budget_of_one_episode_is_said_in_the_singular(
    db: tuple[str, Path], consent: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    argv = create_argv(db[0], consent)
    argv[argv.index("--episodes") + 1] = "1"

    assert main(argv) == 0
    assert main(["study", "status", "pilot", "--url", db[0]]) == 0

    out = " ".join(capsys.readouterr().out.split())  # as one line, however rich wrapped it
    assert out.count("1 episode each") == 2 and "1 episodes" not in out
    assert [counted(n, "run") for n in (0, 1, 2, 1000)] == [
        "0 runs",
        "1 run",
        "2 runs",
        "1,000 runs",
    ]


def rows(path: Path, sql: str) -> list[tuple[object, ...]]:
    with sqlite3.connect(path) as con:
        return list(con.execute(sql))


def test_create_stores_the_study_as_given(
    db: tuple[str, Path], consent: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    questions = tmp_path / "questions.txt"
    questions.write_text("How hard was it?\n\nWould you again?\n")

    assert main(create_argv(db[0], consent, "--questionnaire", str(questions))) == 0

    assert "study pilot created" in capsys.readouterr().out
    [row] = rows(
        db[1],
        "SELECT name, conditions, assignment, budget_episodes, budget_s, consent_text, "
        "consent_version, questionnaire, completion_code, redirect_url FROM studies",
    )
    assert row == (
        "pilot", '["kp", "trainer"]', "balanced", 3, None, "You will train a simulated robot.",
        "v2", '["How hard was it?", "Would you again?"]', "C0DE42", None,
    )  # fmt: skip


@pytest.mark.parametrize(
    ("change", "named"),
    [
        (["--conditions", "kp,telepathy"], "--conditions"),
        (["--conditions", "kp,kp"], "--conditions"),
        (["--episodes", "0"], "--episodes"),
        (["--seconds", "0.5", "--episodes", None], "--seconds"),
        (["--redirect", "ftp://x", "--completion-code", None], "--redirect"),
        (["--consent-file", "missing.txt"], "--consent-file"),
        (["--assignment", "random"], "--assignment"),
        (["NAME", "no spaces"], "NAME"),
    ],
)
def test_create_with_bad_input_names_it_and_stores_nothing(
    db: tuple[str, Path],
    consent: Path,
    capsys: pytest.CaptureFixture[str],
    change: list[str | None],
    named: str,
) -> None:
    argv = create_argv(db[0], consent)
    for flag, value in zip(change[::2], change[1::2], strict=True):
        assert flag is not None
        if flag == "NAME":
            argv[2] = str(value)
        elif value is None:  # drop the flag and its value
            i = argv.index(flag)
            del argv[i : i + 2]
        elif flag in argv:
            argv[argv.index(flag) + 1] = value
        else:
            argv += [flag, value]

    err = exits_2(argv, capsys)

    assert named in err
    assert rows(db[1], "SELECT count(*) FROM studies") == [(0,)]


def test_create_refuses_a_taken_name(
    db: tuple[str, Path], consent: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(create_argv(db[0], consent)) == 0
    err = exits_2(create_argv(db[0], consent), capsys)
    assert "'pilot' exists already" in err


def test_add_prints_each_link_once_and_stores_only_the_digests(
    db: tuple[str, Path], consent: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    main(create_argv(db[0], consent))
    ids = tmp_path / "ids.txt"
    ids.write_text("prolific-1\n\nprolific-2\n")
    capsys.readouterr()

    assert main(["study", "add", "pilot", "--ids", str(ids), "--url", db[0],
                 "--service", "https://lab.example"]) == 0  # fmt: skip

    out = capsys.readouterr().out
    lines = [line.split() for line in out.splitlines() if line.startswith("prolific-")]
    assert [line[0] for line in lines] == ["prolific-1", "prolific-2"]
    tokens = [line[3] for line in lines]
    assert [line[1] for line in lines] == [f"https://lab.example/#/study/{t}" for t in tokens]
    assert {h for (h,) in rows(db[1], "SELECT token_hash FROM participants")} == {
        token_digest(t) for t in tokens
    }
    assert sorted(rows(db[1], "SELECT external_id FROM participant_identities")) == [
        ("prolific-1",),
        ("prolific-2",),
    ]


def test_add_writes_the_links_to_a_new_csv_only(
    db: tuple[str, Path], consent: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    main(create_argv(db[0], consent))
    out = tmp_path / "links.csv"
    argv = ["study", "add", "pilot", "--count", "2", "--out", str(out), "--url", db[0]]

    assert main(argv) == 0

    assert "srp_" not in capsys.readouterr().out  # the tokens are in the file only
    with out.open(newline="") as f:
        written = list(csv.DictReader(f))
    assert [list(r) for r in written] == [["pseudonym", "external_id", "token", "link"]] * 2
    assert all(r["external_id"] == "" and r["link"].endswith(r["token"]) for r in written)
    assert {h for (h,) in rows(db[1], "SELECT token_hash FROM participants")} == {
        token_digest(r["token"]) for r in written
    }
    before = out.read_bytes()
    err = exits_2(argv, capsys)  # never overwritten: those tokens exist nowhere else
    assert f"--out {out} exists" in err
    assert out.read_bytes() == before
    assert rows(db[1], "SELECT count(*) FROM participants") == [(2,)]


def test_add_with_a_taken_id_adds_no_one_and_leaves_no_file(
    db: tuple[str, Path], consent: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    main(create_argv(db[0], consent))
    ids = tmp_path / "ids.txt"
    ids.write_text("prolific-1\n")
    assert main(["study", "add", "pilot", "--ids", str(ids), "--url", db[0]]) == 0
    ids.write_text("prolific-2\nprolific-1\n")
    out = tmp_path / "links.csv"

    err = exits_2(
        ["study", "add", "pilot", "--ids", str(ids), "--out", str(out), "--url", db[0]], capsys
    )

    assert "'prolific-1'" in err
    assert not out.exists()
    assert rows(db[1], "SELECT count(*) FROM participants") == [(1,)]


@pytest.mark.parametrize(
    "argv",
    [
        ["study", "add", "nope", "--count", "1"],
        ["study", "status", "nope"],
        ["study", "forget", "nope", "--yes"],
    ],
)
def test_an_unknown_study_is_named(
    db: tuple[str, Path], capsys: pytest.CaptureFixture[str], argv: list[str]
) -> None:
    err = exits_2([*argv, "--url", db[0]], capsys)
    assert "no study named 'nope'" in err


def test_add_refuses_a_count_out_of_range(
    db: tuple[str, Path], consent: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    main(create_argv(db[0], consent))
    err = exits_2(["study", "add", "pilot", "--count", "1001", "--url", db[0]], capsys)
    assert "--count" in err
    assert rows(db[1], "SELECT count(*) FROM participants") == [(0,)]


def test_status_counts_participants_per_status_and_condition(
    db: tuple[str, Path], consent: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    main(create_argv(db[0], consent))
    main(["study", "add", "pilot", "--count", "3", "--url", db[0]])
    with sqlite3.connect(db[1]) as con:  # one consented, as the service records it
        con.execute("UPDATE participants SET status = 'consented', condition = 'trainer' "
                    "WHERE id = (SELECT min(id) FROM participants)")  # fmt: skip
    capsys.readouterr()

    assert main(["study", "status", "pilot", "--url", db[0]]) == 0

    out = capsys.readouterr().out
    assert "study pilot: conditions kp, trainer (balanced), 3 episodes each" in out
    table = {line.split()[0]: line.split()[1:] for line in out.splitlines()[1:] if line.strip()}
    assert table["status"] == ["kp", "trainer", "all"]
    assert table["invited"] == ["-", "-", "2"]
    assert table["consented"] == ["-", "1", "1"]
    assert table["all"] == ["0", "1", "3"]


def test_status_marks_done_a_participant_whose_stored_run_spent_the_budget(
    db: tuple[str, Path], consent: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from server.cli.db import open_store
    from server.services.runspec import run_spec

    main(create_argv(db[0], consent))  # 3 episodes each
    main(["study", "add", "pilot", "--count", "2", "--url", db[0]])
    store, engine = open_store(db[0])
    spec = run_spec(condition="trainer", seed=1, episodes=3, mode="realtime", hz=10.0)
    runs = [store.create_run(spec, ()) for _ in range(2)]
    engine.dispose()
    with sqlite3.connect(db[1]) as con:  # both training, as the service records it; one spent
        for pid, (run, episodes) in zip((1, 2), zip(runs, (3, 2), strict=True), strict=True):
            con.execute(
                "UPDATE participants SET status = 'training', condition = 'trainer', run_id = ? "
                "WHERE id = ?",
                (run, pid),
            )
            con.execute("UPDATE runs SET episodes_done = ? WHERE id = ?", (episodes, run))
    capsys.readouterr()

    assert main(["study", "status", "pilot", "--url", db[0]]) == 0

    out = capsys.readouterr().out
    table = {line.split()[0]: line.split()[1:] for line in out.splitlines()[1:] if line.strip()}
    assert table["training"] == ["-", "1", "1"] and table["done"] == ["-", "1", "1"]
    assert rows(db[1], "SELECT id, status FROM participants ORDER BY id") == [
        (1, "done"),
        (2, "training"),
    ]


def test_forget_asks_for_yes_then_deletes_the_mapping_only(
    db: tuple[str, Path], consent: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    main(create_argv(db[0], consent))
    ids = tmp_path / "ids.txt"
    ids.write_text("prolific-1\nprolific-2\n")
    main(["study", "add", "pilot", "--ids", str(ids), "--url", db[0]])

    err = exits_2(["study", "forget", "pilot", "--url", db[0]], capsys)
    assert "--yes" in err
    assert rows(db[1], "SELECT count(*) FROM participant_identities") == [(2,)]

    assert main(["study", "forget", "pilot", "--yes", "--url", db[0]]) == 0

    assert "deleted 2 recruiters' ids" in capsys.readouterr().out
    assert rows(db[1], "SELECT count(*) FROM participant_identities") == [(0,)]
    assert rows(db[1], "SELECT count(*) FROM participants") == [(2,)]
