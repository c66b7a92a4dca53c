"""Noisy perception beside exact (`core.lab.noise`): the cells, and the study's arithmetic."""

from __future__ import annotations

import pytest

from core.errors import UnknownNameError
from core.lab.cells import run_study
from core.lab.experiment import LocalBackend, experiment_tasks, run_task
from core.lab.noise import NoiseStudy, label, summarise_noise
from core.run.setup import Setup
from core.sim.worlds import PERCEPTION_PRESETS, parse_perception

GIVEN = Setup(signal="given")
NOISY = PERCEPTION_PRESETS["noisy"]


def test_the_exact_cells_are_the_experiments_tasks_and_the_noisy_ones_its_tasks_with_noise() -> (
    None
):
    study = NoiseStudy(("kp", "rp"), NOISY, GIVEN)
    assert [c.label for c in study.cells()] == [
        label("kp", "exact"), label("rp", "exact"), label("kp", "noisy"), label("rp", "noisy"),
    ]  # fmt: skip
    tasks = [c.task(s, 5, 2) for c in study.cells() for s in (0, 1)]
    # With exact perception a cell is the headline's task: the same numbers, digit for digit.
    assert tasks[:4] == experiment_tasks(("kp", "rp"), (0, 1), 5, GIVEN, 2, tuned=True)
    noisy = experiment_tasks(
        ("kp", "rp"), (0, 1), 5, Setup(signal="given", world_settings=NOISY), 2, tuned=True
    )
    assert tasks[4:] == noisy


def test_the_noise_keeps_the_setups_other_settings_and_sets_perception_alone() -> None:
    echo = (("track.obstacle.echo_range_m", 0.5),)
    study = NoiseStudy(
        ("kp",), parse_perception("camera_miss_rate=0.5"), Setup(world_settings=echo)
    )
    assert study.perception_setup("exact").world_settings == echo
    assert study.perception_setup("noisy").world_settings == (
        ("perception.camera_miss_rate", 0.5),
        *echo,
    )


def test_a_noisy_cell_reproduces_its_seed_and_differs_from_the_exact_one() -> None:
    study = NoiseStudy(("kp",), NOISY, GIVEN)
    exact, noisy = (c.task(4, 6, 0) for c in study.cells())
    first, again, truth = run_task(noisy), run_task(noisy), run_task(exact)
    assert first.ok and truth.ok
    assert first.episodes == again.episodes and first.ltm == again.ltm
    assert first.episodes != truth.episodes


def test_the_change_of_a_lead_is_the_lead_with_noise_minus_the_lead_without() -> None:
    study = NoiseStudy(("kp", "sonar"), NOISY, GIVEN)
    results = run_study(study.cells(), [0, 1, 2], 3, 2, LocalBackend(1))
    summary = summarise_noise(study, results)
    lead, change = summary["lead"], summary["change"]["sonar"]
    for measure in ("1-10", "all", "held-out"):
        with_noise, without = (lead[p]["sonar"][measure]["mean"] for p in ("noisy", "exact"))
        assert change[measure]["mean"] == pytest.approx(with_noise - without)
        assert change[measure]["seeds"] == 3
    effect = summary["grid"]["kp"]["noise_effect"]["all"]["mean"]
    kp = summary["grid"]["kp"]
    assert effect == pytest.approx(
        kp["noisy"]["success_rate"]["mean"] - kp["exact"]["success_rate"]["mean"]
    )


def test_the_declared_comparisons_are_kp_minus_each_with_noise_holm_adjusted() -> None:
    study = NoiseStudy(("kp", "sonar", "rp"), NOISY, GIVEN)
    results = run_study(study.cells(), [0, 1, 2], 3, 2, LocalBackend(1))
    summary = summarise_noise(study, results)
    declared = summary["declared"]
    assert [d["label"] for d in declared] == [
        f"kp - {c}, noisy perception, {t}"
        for c in ("sonar", "rp")
        for t in ("training", "held out")
    ]
    noisy = summary["lead"]["noisy"]
    assert [d["mean"] for d in declared] == [
        noisy[c][k]["mean"] for c in ("sonar", "rp") for k in ("all", "held-out")
    ]
    ps = sorted(d["p"] for d in declared)
    assert min(d["p_holm"] for d in declared) == pytest.approx(min(1.0, 4 * ps[0]))
    assert all(d["p"] <= d["p_holm"] <= 1.0 for d in declared)


@pytest.mark.parametrize(
    ("kwargs", "error", "says"),
    [
        ({"reference": "dp"}, UnknownNameError, "the reference 'dp' is not among"),
        ({"conditions": ("kp", "telepathy")}, UnknownNameError, "telepathy"),
        ({"noise": ()}, ValueError, "perceives exactly"),
        ({"noise": (("track.obstacle.size_m", 0.3),)}, ValueError, "perception settings only"),
        (
            {"setup": Setup(world_settings=NOISY)},
            ValueError,
            "the study sets perception itself",
        ),
    ],
)
def test_a_study_that_cannot_compare_is_refused_saying_why(
    kwargs: dict[str, object], error: type[Exception], says: str
) -> None:
    args: dict[str, object] = {"conditions": ("kp", "rp"), "noise": NOISY, "setup": GIVEN}
    with pytest.raises(error, match=says):
        NoiseStudy(**{**args, **kwargs})  # type: ignore[arg-type]
