"""The views study (lab/studies/views.py) and its label-efficiency curves (lab/studies/label_curves.py):
labels to 90% of the oracle and the area under a curve worked out by hand, the bootstrap interval's
ends where only two seeds can be drawn, each run's short arm name, and the trials the study trains."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from dospcot.sweeps.report import TrialRun
from dospcot.sweeps.sweep import Trial
from dospcot.tasks import load_config
from dospcot_lab.studies import sweep_spec
from dospcot_lab.studies.label_curves import Curve, labels_text
from dospcot_lab.studies.views import STUDIES, arm_of, curves, tables, task_of

# Two seeds at budgets 10/20/40 against an oracle that always succeeds: the mean curve's shares are
# 0.3, 0.7 and 1.0.
CURVE = Curve(
    np.array([10.0, 20.0, 40.0]),
    np.array([[10.0, 20.0, 40.0], [10.0, 20.0, 40.0]]),
    np.array([[0.2, 0.6, 1.0], [0.4, 0.8, 1.0]]),
    np.array([1.0, 1.0]),
)


def test_labels_to_reach_and_area_by_hand():
    assert CURVE.labels_to_reach() == pytest.approx(20 + (0.9 - 0.7) / (1.0 - 0.7) * 20)  # 33.3
    # Trapezoids over ln 10, ln 20, ln 40 (equal widths ln 2): (0.5 + 0.85) / 2.
    assert CURVE.area() == pytest.approx(0.675)
    # A resample draws seed 0 twice (35 labels: 20 + 0.3 / 0.4 x 20), seed 1 twice (30), or one of
    # each (33.3); each pure draw has probability 1/4, so the 2.5th and 97.5th percentiles are 30, 35.
    assert CURVE.labels_interval() == pytest.approx((30.0, 35.0))


def test_a_curve_that_never_reaches_the_share_says_so():
    low = Curve(CURVE.budgets, CURVE.labels, CURVE.success / 2, CURVE.oracle)
    assert math.isinf(low.labels_to_reach()) and labels_text(low.labels_to_reach(), 40) == "> 40"
    assert labels_text(33.4, 40) == "33"
    first = Curve(CURVE.budgets, CURVE.labels, np.full((2, 3), 0.95), CURVE.oracle)
    assert first.labels_to_reach() == 10.0  # the smallest budget already reaches it ...
    assert labels_text(first.labels_to_reach(), 40, 10) == "<= 10"  # ... and the curve says no less
    # A share is of the oracle's mean: an oracle at 0.5 doubles every share.
    half = Curve(CURVE.budgets, CURVE.labels, CURVE.success / 2, np.array([0.5, 0.5]))
    assert half.labels_to_reach() == pytest.approx(CURVE.labels_to_reach())


def _run(
    folder: Path,
    preset: str,
    params: dict[str, str],
    seed: int,
    success: float,
    labels: float,
    correlation: float = math.nan,
    per_view: dict[str, float] | None = None,
) -> TrialRun:
    """A finished run whose folder under ``folder`` holds a ``run_info.json`` of 60 CPU-s (the tables
    read it); its agents' success per view is ``per_view`` (one patch agent at ``success`` if None)."""
    run_dir = folder / f"{preset}-{'-'.join(params.values())}-{seed}"
    run_dir.mkdir(parents=True, exist_ok=True)
    (run_dir / "run_info.json").write_text(json.dumps({"cpu_time_s": 60.0}))
    mean = {
        "success": success,
        "labelled_steps": labels,
        "pseudo_accuracy": 0.9 + success / 10,
        "worst_class_recall": success,
    }
    # metrics.csv's rows: the last round's error correlation is the one the tables read.
    rows = [{"round": 1.0, "error_correlation": 0.9}, {"round": 2.0, "error_correlation": correlation}]
    views = {name: {"success": value} for name, value in (per_view or {"patch": success}).items()}
    return TrialRun(Trial(preset, preset, params, seed), {"mean": mean, "per_view": views}, rows, run_dir)


def test_arms_are_named_short_and_curves_keep_seeds_every_budget_and_the_oracle_ran(tmp_path):
    strategy, budget = "training.label_strategy", "training.label_budget"
    disagreement = {strategy: '"outcomes+disagreement"'}
    twin = {**disagreement, "views": '["patch", "patch"]'}
    runs = [
        _run(tmp_path, "grid16-oracle", {}, seed, 1.0, 500.0, per_view={"patch": 1.0, "rays": 1.0})
        for seed in (0, 1)
    ]
    for b, success in (("5", (0.2, 0.4)), ("10", (0.6, 0.8)), ("20", (1.0, 1.0))):
        for seed in (0, 1):
            runs.append(
                _run(
                    tmp_path,
                    "grid16-dospcot",
                    {**disagreement, budget: b},
                    seed,
                    success[seed],
                    2.0 * float(b),
                    correlation=0.1 * seed,
                    # Its patch agent twice as good as the mean (capped at 1), its rays agent the rest.
                    per_view={
                        "patch": min(1.0, 2 * success[seed]),
                        "rays": 2 * success[seed] - min(1.0, 2 * success[seed]),
                    },
                )
            )
            half = success[seed] / 2
            runs.append(
                _run(
                    tmp_path,
                    "grid16-dospcot",
                    {**twin, budget: b},
                    seed,
                    half,
                    float(b),
                    0.8,
                    {"patch": half, "patch-2": half},
                )
            )
    runs.append(_run(tmp_path, "grid16-dospcot", {strategy: '"random"', budget: "20"}, 0, 0.1, 20.0))
    runs.append(
        _run(tmp_path, "grid16-reward-model", {**disagreement, budget: "5"}, 2, 0.5, 5.0)
    )  # no oracle run
    assert [arm_of(r) for r in runs[:4]] == ["oracle", "oracle", "DOSPCoT", "twin"]
    assert arm_of(runs[-2]) == "blind" and arm_of(runs[-1]) == "reward model"
    found = curves(runs)
    assert sorted(found) == ["DOSPCoT", "blind", "twin"]  # seed 2 of the peer has no oracle run
    assert found["DOSPCoT"].budgets.tolist() == [5.0, 10.0, 20.0]
    assert found["DOSPCoT"].labels_to_reach() == pytest.approx(CURVE.labels_to_reach())  # x2 labels
    assert math.isinf(found["twin"].labels_to_reach())
    text = "\n".join(tables(runs))
    # grid16's columns: its lower budgets 1, 2 and 3, then 5, 10, 20 and 40.
    low = "| – | – | – "
    dospcot = f"| DOSPCoT {low}| 0.30 (10) | 0.70 (20) | 1.00 (40) | – | 33 [30, 35] | 0.68 | 2 | 60 CPU-s |"
    assert dospcot in text
    assert f"| twin {low}| 0.15 (5) | 0.35 (10) | 0.50 (20) | – | > 20 [> 20, > 20] |" in text
    assert f"| blind {low}| – | – | 0.10 (20) | – | > 20 [> 20, > 20] | – | 1 |" in text
    # The last round's error correlation, mean over each arm's runs: DOSPCoT's 0 and 0.1, the twin's 0.8.
    assert "| DOSPCoT | – | – | – | 0.050 | 6 |" in text and "| twin | – | – | – | 0.800 | 6 |" in text
    # On the patch agent alone, DOSPCoT's shares are 0.6, 1.0 and 1.0: it reaches 0.9 at 10 + 0.3 / 0.4 x
    # 10 labels (17.5), seed 0 alone at 18.3 and seed 1 alone at 15. The twin's two agents read patch.
    assert f"| DOSPCoT {low}| 0.60 (10) | 1.00 (20) | 1.00 (40) | – | 18 [15, 18] |" in text
    assert text.count(f"| twin {low}| 0.15 (5) | 0.35 (10) | 0.50 (20) | – | > 20 [> 20, > 20] |") == 2
    # The twin's largest budget: 20 labels.
    assert "| grid16 | 0.050 | 0.800 | 33 | twin > 20 | 18 | twin > 20 |" in text
    # Pseudo-reward accuracy (0.9 + success / 10 in these runs), mean over seeds per budget; the blind
    # control is left out, and the peer's one run sits at budget 5.
    assert f"| DOSPCoT {low}| 0.930 | 0.970 | 1.000 | – |" in text
    assert f"| twin {low}| 0.915 | 0.935 | 0.950 | – |" in text
    assert f"| reward model {low}| 0.950 | – | – | – |" in text and "0.910" not in text
    # Worst-class recall (the runs' success here), likewise: DOSPCoT's 0.3, 0.7 and 1 at 5, 10 and 20.
    recall = text.split("Worst-class recall")[1]
    assert f"| DOSPCoT {low}| 0.300 | 0.700 | 1.000 | – |" in recall


def test_the_study_trains_every_arm_under_version_12_at_the_tasks_budgets_with_score_passes():
    study = STUDIES["views"]
    specs = {sweep.name: sweep_spec(sweep, study.seeds) for sweep in study.sweeps}
    assert all(spec.defaults == 12 and name.endswith("-v12") for name, spec in specs.items())
    twin = specs["views-doorkey-twin-v12"]
    assert twin.configs == ("minigrid-doorkey-dospcot",) and twin.grid["views"] == ('["image", "image"]',)
    assert specs["views-grid16-dospcot-v12"].grid["training.label_budget"] == ("5", "10", "20", "40")
    assert specs["views-fasthighway-blind-v12"].grid["training.label_budget"] == ("800",)
    # Version 12 gives DOSPCoT's method its score passes; the reward model takes the same by its grid.
    peer = specs["views-lavagap-reward-model-v12"]
    assert peer.grid["training.pass_kind"] == ('"score"',) and peer.grid["training.cotrain_passes"] == ("10",)
    for name in ("views-lavagap-dospcot-v12", "views-lavagap-self-training-v12"):
        cfg = load_config(specs[name].configs[0], ["defaults=12"])
        assert (cfg.training.pass_kind, cfg.training.cotrain_passes) == ("score", 10)
    # The blind-spot task: every arm with independent blind spots, and DOSPCoT's control with identical.
    identical = specs["views-grid16-blind-spots-dospcot-identical-v12"].grid
    assert identical["env.blind_spots"] == ('"identical"',) and identical["env.blind_spot_rate"] == ("0.5",)
    assert specs["views-grid16-blind-spots-twin-v12"].grid["env.blind_spots"] == ('"independent"',)
    assert "env.blind_spot_rate" not in specs["views-grid16-twin-v12"].grid
    # Below the registered budgets, on grid16 and DoorKey, the four arms that compare views.
    low = [name for name in specs if "-low-" in name]
    assert sorted(low) == sorted(
        f"views-{task}-{arm}-low-v12"
        for task in ("grid16", "doorkey", "fasthighway")
        for arm in ("dospcot", "twin", "reward-model", "self-training")
    )
    assert specs["views-fasthighway-dospcot-low-v12"].grid["training.label_budget"] == ("25", "50")
    assert specs["views-doorkey-twin-low-v12"].grid["training.label_budget"] == ("5", "10")
    assert specs["views-grid16-reward-model-low-v12"].grid["training.pass_kind"] == ('"score"',)
    # 940 registered trials, and 4 arms x (3 budgets on grid16 + 2 on DoorKey + 2 on the fast highway) x
    # 10 seeds below them.
    assert sum(len(spec.trials(check_task=False)) for spec in specs.values()) == 940 + 4 * 7 * 10


@pytest.mark.parametrize(
    ("preset", "params", "task", "arm"),
    [
        (
            "grid16-dospcot",
            {"env.blind_spot_rate": "0.5", "env.blind_spots": '"identical"'},
            "grid16-blind-spots",
            "DOSPCoT, identical blind spots",
        ),
        (
            "grid16-dospcot",
            {"env.blind_spot_rate": "0.5", "views": '["patch", "patch"]'},
            "grid16-blind-spots",
            "twin",
        ),
        ("grid16-reward-model", {}, "grid16", "reward model"),
        ("fasthighway-oracle", {}, "fasthighway", "oracle"),
        ("minigrid-lavagap-self-training", {}, "lavagap", "self-training"),
        ("grid32-dospcot", {}, None, "DOSPCoT"),
    ],
)
def test_each_run_finds_its_task_and_arm_by_its_preset_and_settings(preset, params, task, arm):
    run = TrialRun(Trial(preset, "", params, 0), {}, [], Path())
    assert (task_of(run), arm_of(run)) == (task, arm)
