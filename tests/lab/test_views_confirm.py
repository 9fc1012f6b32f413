"""The confirmatory views study (lab/studies/views_confirm.py): its hypotheses marked by their rules on
runs made here, the paired ratio of two curves' labels worked out by hand, the trials it trains, and
its refusal to train before its preregistration is committed."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from dospcot.sweeps.report import TrialRun
from dospcot.sweeps.sweep import Trial
from dospcot_lab.studies import sweep_spec
from dospcot_lab.studies import views_confirm as confirm
from dospcot_lab.studies.label_curves import Curve, area_difference, labels_ratio
from dospcot_lab.studies.step_class import steps_paid
from dospcot_lab.studies.views import arm_of

PRESETS = {
    "grid16": "grid16",
    "doorkey": "minigrid-doorkey",
    "lavagap": "minigrid-lavagap",
    "fasthighway": "fasthighway",
}
ARMS = {
    "DOSPCoT": ("dospcot", {}),
    "twin": ("dospcot", {"views": "twin"}),
    "reward model": ("reward-model", {}),
    "self-training": ("self-training", {}),
}


def _run(
    task: str, preset: str, params: dict[str, str], seed: int, success: float, correlation: float
) -> TrialRun:
    """A finished run: its agent on the task's one-view arms' view succeeds ``success`` of the time, and
    its last round's error correlation is ``correlation``."""
    view = confirm.TASKS[task][1]
    budget = params.get("training.label_budget")
    summary = {
        "mean": {"success": success, "labelled_steps": float(budget) if budget else 0.0},
        "per_view": {view: {"success": success}},
    }
    rows = [{"round": 5.0, "error_correlation": correlation}]
    return TrialRun(Trial(f"{PRESETS[task]}-{preset}", "", params, seed), summary, rows, Path())


def _task_runs(task: str, reach: dict[str, int | None], correlation: float) -> list[TrialRun]:
    """Two seeds of every arm on ``task``: an arm succeeds from the budget of index ``reach[arm]`` on
    (never where None); the oracle always does. DOSPCoT's classifiers' errors correlate ``correlation``,
    every other arm's 0.5."""
    runs = [_run(task, "oracle", {}, seed, 1.0, math.nan) for seed in (0, 1)]
    for arm, (preset, params) in ARMS.items():
        for i, budget in enumerate(confirm.BUDGETS[task]):
            success = 1.0 if reach[arm] is not None and i >= reach[arm] else 0.0
            for seed in (0, 1):
                # The twin names its one view twice (its sweep's "views" setting).
                settings = {**params, "training.label_budget": budget}
                mine = correlation if arm == "DOSPCoT" else 0.5
                runs.append(_run(task, preset, settings, seed, success, mine))
    blind = {"training.label_strategy": '"random"', "training.label_budget": confirm.BUDGETS[task][-1]}
    return runs + [_run(task, "dospcot", blind, seed, 0.0, 0.5) for seed in (0, 1)]


SAVES = {"DOSPCoT": 0, "twin": None, "reward model": 2, "self-training": 3}
"""DOSPCoT reaches the oracle at the smallest budget, the best peer at the third, the twin never."""
TIE = dict.fromkeys(ARMS, 1)


@pytest.fixture()
def two_pairs(monkeypatch):
    monkeypatch.setattr(confirm, "PAIRS", dict.fromkeys(confirm.BUDGETS, 2))


def test_two_curves_ratio_of_labels_and_difference_of_areas_are_paired_and_read_never_reached():
    budgets = np.array([10.0, 20.0, 40.0])
    labels = np.tile(budgets, (2, 1))
    oracle = np.ones(2)
    fast = Curve(budgets, labels, np.array([[1.0, 1.0, 1.0], [0.8, 1.0, 1.0]]), oracle, (0, 1))
    slow = Curve(budgets, labels, np.array([[0.0, 0.5, 1.0], [0.0, 1.0, 1.0]]), oracle, (0, 1))
    never = Curve(budgets, labels, np.zeros((2, 3)), oracle, (0, 1))
    # fast: the mean share reaches 0.9 at 10 labels; seed 0 alone at 10, seed 1 alone at 10 + 0.1 / 0.2
    # x 10 = 15. slow: the mean (0, 0.75, 1) at 20 + 0.15 / 0.25 x 20 = 32; seed 0 alone at 20 + 0.4 /
    # 0.5 x 20 = 36, seed 1 alone at 10 + 0.9 x 10 = 19. A resample of seed 0 twice: 10 / 36; of seed 1
    # twice: 15 / 19.
    point, low, high = labels_ratio(fast, slow)
    assert point == pytest.approx(10 / 32) and (low, high) == pytest.approx((10 / 36, 15 / 19))
    assert labels_ratio(fast, never)[:3] == (0.0, 0.0, 0.0)
    assert labels_ratio(never, fast)[0] == math.inf and labels_ratio(never, never)[0] == 1.0
    unpaired = Curve(budgets, labels, never.success, oracle, (2, 3))
    assert all(math.isnan(v) for v in labels_ratio(fast, unpaired))
    # Areas over ln 10, ln 20, ln 40 (equal widths): fast's mean (0.9, 1, 1) 0.975, slow's (0, 0.75, 1)
    # 0.625; seed 0 alone 1 and 0.5 (+0.5), seed 1 alone 0.95 and 0.75 (+0.2).
    assert area_difference(fast, slow) == pytest.approx((0.35, 0.2, 0.5))
    assert all(math.isnan(v) for v in area_difference(fast, unpaired))


def test_v1_and_v2_are_met_on_two_tasks_of_four_and_v3_reads_dependence_against_margin(two_pairs):
    runs = [
        *_task_runs("grid16", SAVES, 0.1),
        *_task_runs("doorkey", SAVES, 0.2),
        *_task_runs("lavagap", TIE, 0.9),
        *_task_runs("fasthighway", {**TIE, "DOSPCoT": None}, 1.0),
    ]
    lines, verdicts, parts = confirm.hypotheses(runs)
    # grid16: DOSPCoT at 2 labels; the reward model (the best peer) fails at 5 and succeeds at 10, so it
    # reaches 0.9 at 5 + 0.9 x 5 = 9.5 labels: 2 / 9.5 = 0.21 whichever seeds are drawn. DoorKey: 5 /
    # (10 + 0.9 x 15) = 0.21. The twin never reaches it there, so its ratio is inf. LavaGap: every arm at
    # once. The fast highway: DOSPCoT never (inf), the twin does (0).
    # V4's areas over log labels: on DoorKey the reward model's shares (0, 0, 1, 1) at 5, 10, 25 and 50
    # labels make (0.5 ln 2.5 + ln 2) / ln 10 = 0.50 against DOSPCoT's 1; on grid16 (ln 2 / 2 + ln 2) /
    # ln 10 = 0.45; on the fast highway the twin's (0, 1, 1, 1) make 2.5 ln 2 / ln 8 = 0.83.
    rows = {line.split(" | ")[0][2:]: line for line in lines[2:]}
    assert rows["grid16"] == (
        "| grid16 | reward model | 0.21 [0.21, 0.21] | yes | inf [inf, inf] | yes | 0.100 | reward model | "
        "+0.55 [+0.55, +0.55] | yes |"
    )
    assert rows["doorkey"].startswith(
        "| doorkey | reward model | 0.21 [0.21, 0.21] | yes | inf [inf, inf] | yes |"
    )
    assert rows["doorkey"].endswith("| 0.200 | reward model | +0.50 [+0.50, +0.50] | yes |")
    assert rows["lavagap"] == (
        "| lavagap | twin | 1.00 [1.00, 1.00] | no | 1.00 [1.00, 1.00] | no | 0.900 | twin | "
        "+0.00 [+0.00, +0.00] | no |"
    )
    assert rows["fasthighway"].endswith(
        "| 0.00 [0.00, 0.00] | no | 1.000 | twin | -0.83 [-0.83, -0.83] | no |"
    )
    # Margins 4.75, 4.7, 1 and 0 against correlations 0.1, 0.2, 0.9 and 1.0: a rank correlation of -1.
    v3 = "met (rank correlation -1.00 over 4 tasks)"
    assert verdicts == {"V1": "met", "V2": "met", "V3": v3, "V4": "met"}
    assert "grid16 0.21 [0.21, 0.21]" in parts and len(parts) == 4
    # One run missing, of a peer or of the blind control, which no hypothesis reads: nothing is decided.
    peer = next(i for i, r in enumerate(runs) if arm_of(r) == "self-training")
    for left_out in (peer, len(runs) - 1):
        rest = runs[:left_out] + runs[left_out + 1 :]
        assert set(confirm.hypotheses(rest)[1].values()) == {"not decided yet"}


def test_the_answer_tables_each_arms_labels_per_task_and_the_readme_block_copies_it(two_pairs):
    runs = [*_task_runs("grid16", SAVES, 0.1), *_task_runs("doorkey", SAVES, 0.2)]
    # DoorKey's seed 1 of the reward model at its smallest budget is missing: its curve holds one pair.
    runs = [r for r in runs if not (r.trial.config == "minigrid-doorkey-reward-model" and r.trial.seed == 1)]
    # And DoorKey's blind control has not run.
    runs = [r for r in runs if not (r.trial.config == "minigrid-doorkey-dospcot" and arm_of(r) == "blind")]
    answer = confirm.answer(runs, confirm.hypotheses(runs)[1])
    # The study's tables put the answer between the hypotheses and the exploration's tables.
    text = "\n".join(
        ["### Hypotheses", "", "- **V1**: not decided yet.", "", *answer, "", "Each budget's cell"]
    )
    block = confirm.readme_block(text)
    rows = {line.split(" | ")[0][2:]: line for line in block.splitlines() if line.startswith("| ")}
    # grid16: DOSPCoT at its smallest budget (2), the reward model at 5 + 0.9 x 5 = 9.5 labels (shown
    # 10), self-training at 10 + 0.9 x 10 = 19, the twin and the blind control never within 20. DoorKey:
    # the reward model at 10 + 0.9 x 15 = 23.5 on its one pair left, self-training at 25 + 0.9 x 25 = 47.5.
    assert rows["grid16"] == "| grid16 | <= 2 | > 20 | 10 | 19 | > 20 |"
    assert rows["doorkey"] == "| doorkey | <= 5 | > 50 | 24 (1 of 2 pairs so far) | 48 | not run yet |"
    assert rows["lavagap"] == "| lavagap | " + " | ".join(["not run yet"] * 5) + " |"
    assert block.endswith(
        "Pre-registered verdicts: V1 (the second view saves labels): not decided yet; V2 (the view pays, "
        "not the second model): not decided yet."
    )
    assert block.startswith("Labels each arm needed") and "Each budget's cell" not in block


def test_v3_is_not_testable_where_the_views_errors_depend_alike_on_every_task(two_pairs):
    runs = [*(r for task in confirm.BUDGETS for r in _task_runs(task, TIE, 1.0))]
    verdicts = {"V1": "not met", "V2": "not met", "V3": "not testable", "V4": "not met"}
    assert confirm.hypotheses(runs)[1] == verdicts


def test_the_study_trains_seeds_200_209_on_unseen_layouts_at_four_budgets_per_task():
    study = confirm.STUDIES["views-confirm"]
    assert study.confirmatory and study.preregistration == "docs/preregistration-views.md"
    specs = {s.name: sweep_spec(s, study.seeds, [], study.first_seed) for s in study.sweeps}
    assert all(spec.seeds == tuple(range(200, 210)) and spec.defaults == 12 for spec in specs.values())
    grid = specs["views-confirm-grid16-twin-v12"]
    assert grid.grid["env.layout_seed"] == ("707", "808", "909") and grid.grid["views"] == (
        '["patch", "patch"]',
    )
    assert all(len(confirm.BUDGETS[task]) >= 4 for task in confirm.BUDGETS)
    assert specs["views-confirm-doorkey-blind-v12"].grid["training.label_budget"] == (
        confirm.BUDGETS["doorkey"][-1],
    )
    # Per task: the oracle, four arms at every budget and the blind control, over its pairs.
    expected = sum(confirm.PAIRS[task] * (2 + 4 * len(b)) for task, b in confirm.BUDGETS.items())
    assert sum(len(spec.trials(check_task=False)) for spec in specs.values()) == expected


def test_it_refuses_to_train_until_its_preregistration_is_committed(tmp_path, monkeypatch):
    from dospcot_lab import studies
    from dospcot_lab.cli import main as lab_main

    started = []
    monkeypatch.setattr(studies, "source_commit", lambda: "abc123")
    monkeypatch.setattr(studies, "added_in", lambda page, checkout: None)
    monkeypatch.setattr(studies, "run_sweep", lambda sweep_dir, spec, **options: started.append(sweep_dir))
    with pytest.raises(SystemExit) as stop:
        lab_main(["study", "views-confirm", "--runs-dir", str(tmp_path)])
    assert "follows docs/preregistration-views.md, which this checkout has not committed" in str(stop.value)
    assert started == [] and list(tmp_path.iterdir()) == []


def test_steps_paid_counts_the_runs_whose_steps_class_paid_above_0(tmp_path):
    # DoorKey, DOSPCoT at 5 labels: two runs, one whose lowest class paid 0.2228 (a late goal's pay
    # merged with the steps'), one 0; at 10 labels one run paying 0. The twin never ran.
    runs = []
    for i, (budget, classes) in enumerate((("5", [0.2228, 0.94]), ("5", [0.0, 0.9]), ("10", [0.0, None]))):
        folder = tmp_path / str(i)
        folder.mkdir()
        (folder / "reward_classes.json").write_text(f'{{"rewards": {classes}}}'.replace("None", "null"))
        params = {"training.label_budget": budget}
        runs.append(TrialRun(Trial("minigrid-doorkey-dospcot", "", params, i), {}, [], folder))
    lines = steps_paid(runs, {"doorkey": ("5", "10", "25", "50")}.__getitem__)
    assert lines[-3:] == [
        "| arm | budget 5 | budget 10 | budget 25 | budget 50 |",
        "|---|---|---|---|---|",
        "| DOSPCoT | 1 of 2 | 0 of 1 | – | – |",
    ]
