"""The label-budget studies' tables and figure (lab/studies/budget*.py): labels to reach a share of the
oracle interpolated by hand, arms paired by seed with their labels counted, the confirmatory study's
verdicts as registered, and the trials it trains."""

from __future__ import annotations

import re

from dospcot.sweeps.report import TrialRun
from dospcot.sweeps.sweep import Trial
from dospcot_lab.studies import budget, budget_arms, sweep_spec
from dospcot_lab.studies.budget import labels_to_reach
from dospcot_lab.studies.budget_arms import STRATEGY
from dospcot_lab.studies.budget_confirm import STUDIES as BUDGET_CONFIRM
from dospcot_lab.studies.budget_explore import STUDIES as BUDGET_STUDIES


def test_labels_to_reach_interpolates_between_budgets_or_says_not_reached():
    points = [(300.0, 0.9), (100.0, 0.5)]
    assert labels_to_reach(points, 0.8) == 250.0  # 100 + (0.8 - 0.5) / (0.9 - 0.5) x 200
    assert labels_to_reach(points, 0.4) == 100.0  # the smallest budget already reaches it
    assert labels_to_reach(points, 0.95) is None


def _budget_run(tmp_path, config: str, params: dict, seed: int, success: list[float], labels: float):
    """A finished run of the budget study: its summary and a metrics.csv with one row per round."""
    run_dir = tmp_path / f"{config}-{'-'.join(params.values())}-{seed}"
    run_dir.mkdir()
    rows = ["round,agent,success"] + [f"{r},0,{s}" for r, s in enumerate(success, 1)]
    (run_dir / "metrics.csv").write_text("\n".join(rows) + "\n")
    mean = {"success": success[-1], "labelled_steps": labels, "pseudo_accuracy": 1.0}
    return TrialRun(Trial(config, config, params, seed), {"mean": mean}, [], run_dir)


def test_the_budget_tables_pair_arms_by_seed_and_count_their_labels(tmp_path):
    even = {
        "training.label_budget": "100",
        "training.label_strategy": "disagreement",
        "training.query_schedule": "even",
        "training.exploration": "rounds",
    }
    asap = {**even, "training.query_schedule": "asap"}
    runs = []
    for seed in range(3):
        runs.append(_budget_run(tmp_path, "minigrid-doorkey-oracle", {}, seed, [0.5, 1.0], 900))
        runs.append(
            _budget_run(tmp_path, "minigrid-doorkey-dospcot", even, seed, [0.0, 0.8 + 0.05 * seed], 100)
        )
        runs.append(_budget_run(tmp_path, "minigrid-doorkey-dospcot", asap, seed, [0.0, 0.6], 100))
    text = "\n".join(BUDGET_STUDIES["budget-explore"].tables(runs))
    # The tables name the arms by what sets them apart; what they share is said once above.
    assert "Every arm but the oracle: disagreement, exploration by rounds." in text
    assert "| dospcot even | 100 | 100 | 0.850 [0.800, 0.900] |" in text
    assert "| oracle | preset | every reward | 1.000 [1.000, 1.000] |" in text
    assert "| dospcot even | 100 | 0.00 | 0.85 |" in text  # success after each round, at its budget
    # Even minus asap, paired by seed: 0.2, 0.25, 0.3.
    assert "the budget spread evenly against spent at once: success of " in text
    assert "paired: 0.250 [0.200, 0.300] over 3 seeds." in text
    # 90% of the oracle's 1.0 is 0.9: the even arm's one budget (0.85) does not reach it.
    assert "| dospcot even | 100 | not reached |" in text


def test_the_third_exploration_names_the_admitted_share_and_pairs_all_against_half_per_task(tmp_path):
    half = {"training.label_fraction": "0.1", "training.exploration": "rounds"}
    every = {**half, "cotraining.add_fraction_start": "1.0"}
    grid_half = {
        "env.layout_seed": "11",
        "cotraining.add_fraction_start": "0.5",
        "training.exploration": "rounds",
    }
    grid_all = {**grid_half, "cotraining.add_fraction_start": "1.0"}
    runs = []
    for seed in range(2):
        runs.append(_budget_run(tmp_path, "minigrid-doorkey-dospcot", half, seed, [0.0, 0.4], 90))
        runs.append(
            _budget_run(tmp_path, "minigrid-doorkey-dospcot", every, seed, [0.5, 0.9 - 0.1 * seed], 90)
        )
        runs.append(_budget_run(tmp_path, "grid16-dospcot", grid_half, seed, [0.0, 0.7], 40))
        runs.append(_budget_run(tmp_path, "grid16-dospcot", grid_all, seed, [0.2, 0.5], 40))
    text = "\n".join(BUDGET_STUDIES["budget-explore-admit"].tables(runs))
    doorkey, grid = text.split("### grid16, layout 11")
    arm = "dospcot uniform exploration by rounds admitting 100% of U in round 1"
    # A name still over 30 characters is shown as a letter, its settings in a table under the task's.
    assert "| arm A | share 0.1 | 0.50 | 0.85 |" in doorkey  # success after each round, mean over seeds
    assert f"| arm A | {arm} |" in doorkey and "| dospcot | share 0.1 | 0.00 | 0.40 |" in doorkey
    # All minus half, paired by seed: DoorKey 0.5 and 0.4; grid16 -0.2 on both seeds.
    assert "a blind 10% mask, admitting all of U in round 1 against half: success of " in doorkey
    assert "paired: 0.450 [0.400, 0.500] over 2 seeds." in doorkey
    assert "grid16's 5% mask, admitting all of U in round 1 against half: success of " in grid
    assert "paired: -0.200 [-0.200, -0.200] over 2 seeds." in grid
    assert "grid16's 5% mask" not in doorkey and "a blind 10% mask" not in grid


def test_the_budget_figure_draws_each_task_in_its_own_panel(tmp_path, monkeypatch):
    drawn = {}
    monkeypatch.setattr(budget, "plot_bands", lambda panels, *args, **kwargs: drawn.update(panels))
    mask = {"training.label_fraction": "0.1"}
    runs = [
        _budget_run(tmp_path, "minigrid-doorkey-oracle", {}, 0, [1.0], 900),
        _budget_run(tmp_path, "minigrid-doorkey-dospcot", mask, 0, [0.5], 90),
        _budget_run(tmp_path, "grid16-dospcot", mask, 0, [0.8], 40),
    ]
    BUDGET_STUDIES["budget-explore-admit"].figure(runs, tmp_path / "figure.png")
    assert list(drawn) == ["MiniGrid-DoorKey-5x5-v0", "grid16, layout 11"]
    doorkey, grid = drawn.values()
    # DoorKey's mask arm at its 90 labels and the oracle's line across it; grid16's arm alone, at 40.
    assert [(b.label, list(b.x), list(b.mean)) for b in doorkey] == [
        ("dospcot", [90.0], [0.5]),  # one arm: every setting of it is shared
        ("oracle (every reward)", [90.0, 90.0], [1.0, 1.0]),
    ]
    assert [(b.label, list(b.x)) for b in grid] == [("dospcot", [40.0])]


def _confirmatory_runs(tmp_path, success) -> list[TrialRun]:
    """Every trial of the confirmatory study, finished with ``success(sweep name, params, seed)``."""
    runs = []
    for sweep in BUDGET_CONFIRM["budget"].sweeps:
        for trial in sweep_spec(sweep, 10, (), 100).trials(check_task=False):
            labels = float(trial.params.get("training.label_budget", 900))
            run = _budget_run(tmp_path, trial.config, trial.params, trial.seed, [0.0, 0.0], labels)
            run.summary["mean"]["success"] = success(sweep.name, trial.params, trial.seed)
            runs.append(run)
    return runs


def test_the_confirmatory_study_decides_b1_to_b4_as_registered(tmp_path):
    def success(name: str, params: dict, seed: int) -> float:
        budget = params.get("training.label_budget")
        if name.endswith("-oracle"):
            return 0.4 if "unlock" in name else 1.0
        if name.endswith("-random"):  # the blind control: 0.95 at 400 labels, 0.5 at 200
            return 0.95 if budget == "400" else 0.5
        if name.endswith("-asap"):
            return 0.8 - 0.01 * (seed % 2)
        if "grid16" in name:  # DOSPCoT ahead of both peers on one layout, behind on another
            step = {"404": 0.1, "505": -0.1, "606": 0.0}[params["env.layout_seed"]]
            return 0.9 + step if name.endswith("-dospcot") else 0.9
        if name.endswith("-dospcot") or name.endswith("-dospcot-200"):
            return 0.92
        return 0.7 if "doorkey" in name else 0.95  # the peers: behind on DoorKey, ahead on LavaGap

    runs = _confirmatory_runs(tmp_path, success)
    text = "\n".join(BUDGET_CONFIRM["budget"].tables(runs))
    # B1: 0.92 minus 0.80 or 0.79 on 20 pairs, pooled over the two tasks.
    assert re.search(r"paired: 0\.125 \[0\.12\d, 0\.12\d\] over 20 pairs; interval above 0: \*\*held", text)
    # B2: only DoorKey beat both peers (grid16's 30 pairs, by layout and seed, average 0; LavaGap's
    # and the highway's peers lead): 1 of 4 tasks.
    assert re.search(
        r"B2 \(grid16\): success of DOSPCoT minus the reward-model peer, paired: -?0\.000 \[", text
    )
    assert "over 30 pairs (20 against 20 labels a run); interval above 0: **not met**." in text
    assert "DOSPCoT beat both peers on 1 of 4 tasks; at least two: **not met**." in text
    # B3: DOSPCoT's 0.92 at 100 labels reaches 0.9; the control's 0.5 at 200 does not: held on both.
    assert "- B3 (doorkey): target 0.900; DOSPCoT at 100 labels 0.920, the blind control at 200 0.500" in text
    assert "- B3: held on both MiniGrid tasks: **held**." in text
    # B4: the oracle reaches the door in 0.4 of its episodes, too few to anchor the share.
    assert (
        "B4 (Unlock): DOSPCoT at 100 labels 0.920, the oracle 0.400; the oracle is below 0.5, so B4 is not"
        in text
    )
    assert BUDGET_CONFIRM["budget"].glance(runs).verdict.endswith("B4: not testable")


def test_the_confirmatory_verdicts_wait_for_every_pair(tmp_path):
    runs = [r for r in _confirmatory_runs(tmp_path, lambda *_: 0.5) if r.trial.seed < 105]
    text = "\n".join(BUDGET_CONFIRM["budget"].tables(runs))
    assert "over 10 pairs; interval above 0: not decided yet." in text  # B1 on half the seeds
    assert "**held**" not in text and "**not met**" not in text


def test_the_confirmatory_comparisons_flag_arms_whose_labels_differ_by_more_than_2_percent(tmp_path):
    runs = _confirmatory_runs(tmp_path, lambda *_: 0.5)
    for run in runs:  # the reward-model peer's runs on grid16 held 21 labels against DOSPCoT's 20
        if run.trial.config == "grid16-reward-model":
            run.summary["mean"]["labelled_steps"] = 21.0
    text = "\n".join(BUDGET_CONFIRM["budget"].tables(runs))
    assert "(20 against 21 labels a run (labels unequal: more than 2% apart))" in text
    assert "(20 against 20 labels a run); interval" in text  # grid16's self-training arm: equal
    # An arm with no run yet has no labels to compare: the line waits rather than warns.
    text = "\n".join(
        BUDGET_CONFIRM["budget"].tables([r for r in runs if r.trial.config != "grid16-reward-model"])
    )
    assert "(20 against n/a labels a run); interval above 0: not decided yet." in text


def test_long_arm_names_take_short_words_said_above_the_tables(tmp_path):
    decay = {
        "training.label_budget": "100",
        "training.query_schedule": "decay",
        "training.exploration": "rounds",
    }
    refit = {**decay, "cotraining.refit_new_classes": "true"}
    runs = [
        _budget_run(
            tmp_path, "minigrid-doorkey-dospcot", {**refit, STRATEGY: '"outcomes+disagreement"'}, 0, [1], 1
        ),
        _budget_run(
            tmp_path, "minigrid-doorkey-self-training", {**refit, STRATEGY: '"uncertainty"'}, 0, [1], 1
        ),
        _budget_run(
            tmp_path, "minigrid-doorkey-reward-model", {**decay, STRATEGY: '"disagreement"'}, 0, [1], 1
        ),
    ]
    shared, names, used = budget_arms.short_names(budget_arms.by_arm(runs))
    assert shared == ["decay", "exploration by rounds"]  # said once; the refit is not every arm's
    assert list(names.values()) == [
        "DOSPCoT o+d refit",
        "ST unc refit",
        "reward-model disagreement",
    ]
    # 31 characters and more take the short words; a name that fits keeps its words.
    assert used == {
        "o+d": "outcomes+disagreement",
        "refit": "refit on a new class",
        "ST": "self-training",
        "unc": "uncertainty",
    }
    assert all(len(name) <= budget_arms.SHORT_NAME for name in names.values())


def test_the_round_and_class_tables_keep_one_row_per_arm_and_budget(tmp_path):
    runs = []
    for labels, success in (("100", [0.0, 0.9]), ("200", [0.4, 1.0])):
        params = {"training.label_budget": labels, "training.label_strategy": "disagreement"}
        run = _budget_run(tmp_path, "minigrid-doorkey-dospcot", params, 0, success, float(labels))
        (run.run_dir / "pseudo_rewards.csv").write_text(
            f"round,class,reward,samples,labelled,admitted,recall,precision\n2,0,0.0,{labels},1,5,1.0,1.0\n"
        )
        runs.append(run)
    arms = budget_arms.by_arm(runs)
    assert list(arms) == ["dospcot disagreement"]  # one arm, two budgets: two rows, never pooled
    assert budget._rounds_table(arms)[2:] == [
        "| dospcot disagreement | 100 | 0.00 | 0.90 |",
        "| dospcot disagreement | 200 | 0.40 | 1.00 |",
    ]
    assert budget._class_table(arms)[2:] == [
        "| dospcot disagreement | 100 | 0 | 100 | 1 | 1.000 | 1.000 | 1 |",
        "| dospcot disagreement | 200 | 0 | 200 | 1 | 1.000 | 1.000 | 1 |",
    ]


def test_the_class_table_groups_goal_rewards_that_differ_by_run_under_one_class():
    def rows(*classes):
        return [
            {"class": c, "reward": r, "samples": "10", "labelled": "1", "recall": "1", "precision": "1"}
            for c, r in classes
        ]

    # MiniGrid: the goal pays by the step count, so each run's goal reward differs; one run never saw it.
    minigrid = budget._by_class(
        [
            rows(("0", "0.0"), ("1", "0.6")),
            rows(("0", "0.0"), ("1", "0.9")),
            rows(("-1", "nan"), ("0", "0.0")),
        ]
    )
    assert {key: len(value) for key, value in minigrid.items()} == {
        "never labelled": 1,
        "0": 3,
        "0.6 to 0.9": 2,
    }
    # Shared rewards, one run short of a class: by value, as the grid and the highway read.
    grid = budget._by_class(
        [rows(("0", "-1.0"), ("1", "0.0"), ("2", "10.0")), rows(("0", "-1.0"), ("1", "10.0"))]
    )
    assert {key: len(value) for key, value in grid.items()} == {"-1": 2, "0": 1, "10": 2}
    # grid16: each run numbers its classes in the order it met them, and one never saw the lava.
    met = budget._by_class(
        [
            rows(("0", "-1.0"), ("1", "0.0"), ("2", "-100.0")),
            rows(("0", "-1.0"), ("1", "-100.0"), ("2", "0.0")),
            rows(("-1", "nan"), ("0", "-1.0"), ("1", "0.0")),
        ]
    )
    assert [(key, len(value)) for key, value in met.items()] == [
        ("never labelled", 1),
        ("-100", 2),
        ("-1", 3),
        ("0", 3),
    ]


def test_the_confirmatory_study_trains_what_its_pre_registration_names():
    from dospcot_lab.studies import budget_confirm

    trials = [
        (sweep, trial)
        for sweep in BUDGET_CONFIRM["budget"].sweeps
        for trial in sweep_spec(sweep, 10, (), 100).trials(check_task=False)
    ]
    assert len(trials) == 310 and {t.seed for _, t in trials} == set(range(100, 110))
    for sweep, trial in trials:
        assert sweep.numerics == 2 and trial.params["training.exploration"] == "rounds"
        assert trial.params["training.agent_draws"] == "own"
        schedule = trial.params.get("training.query_schedule")  # the oracles buy no labels
        assert schedule == ("asap" if sweep.name.endswith("-asap") else budget_confirm.SCHEDULE) or (
            schedule is None and sweep.name.endswith("-oracle")
        )
    layouts = {t.params["env.layout_seed"] for _, t in trials if "env.layout_seed" in t.params}
    assert layouts == {"404", "505", "606"}
    # Every co-training arm refits on a new class; every grid16 arm keeps the goal to episode ends.
    for sweep, trial in trials:
        oracle_or_peer = trial.config.endswith(("-oracle", "-reward-model"))
        assert (trial.params.get("cotraining.refit_new_classes") == "true") != oracle_or_peer, sweep.name
        grid = trial.config.startswith("grid16-")
        assert (trial.params.get("env.episode_end_classes") == "true") == grid, sweep.name
    # Each task's peers buy DOSPCoT's budget.
    for task, labels in budget_confirm.LABELS.items():
        named = {
            t.params["training.label_budget"]
            for s, t in trials
            if s.name.startswith(f"budget-confirm-{task}-")
            and s.name.split("-")[-1] in ("dospcot", "training", "model")
        }
        assert named == {labels}, task
