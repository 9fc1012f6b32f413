"""The study tables of dospcot_lab.studies (the pre-registered second-view tables first): paired
differences and verdicts by hand."""

import json
import subprocess
import sys
import tempfile
from pathlib import Path

import pytest

from dospcot.statistics import SeedSummary
from dospcot.sweeps.report import TrialRun
from dospcot.sweeps.sweep import Trial
from dospcot_lab.studies import STUDIES
from dospcot_lab.studies.grid_studies import grid16_tables, label_fraction_tables
from dospcot_lab.studies.highway_studies import cost_bound
from dospcot_lab.studies.label_sources import (
    DEMO_ARMS,
    EFFORT_ARMS,
    EFFORT_HIGHWAY_ARMS,
    EFFORT_TARGETS,
    EXPERT,
    THIRD_VIEW_ARMS,
    demonstration_tables,
    effort_tables,
    third_view_tables,
)
from dospcot_lab.studies.minigrid import minigrid_tables
from dospcot_lab.studies.provenance import header
from dospcot_lab.studies.second_view import second_view_tables
from dospcot_lab.studies.tables import seeds_to_clear

"""The command the docs name, a shim of :func:`dospcot_lab.studies.main`."""

INDEPENDENT = {"env.blind_spot_rate": "0.5", "env.blind_spots": "independent", "agent": "dqn"}
IDENTICAL = {**INDEPENDENT, "env.blind_spots": "identical"}
MONITOR = {"env.monitored_columns": "8", "training.label_fraction": "0.02", "agent": "dqn"}


def _run(preset: str, params: dict[str, str], seed: int, success: float, accuracy: float) -> TrialRun:
    summary = {"mean": {"success": success, "pseudo_accuracy": accuracy}}
    return TrialRun(Trial(preset, preset, dict(params), seed), summary, [], Path())


def _setting(params, dospcot, patch, rays, zero=(0.0,) * 4):
    """Four seeds of DOSPCoT, self-training on each view and masked-zero: (success, accuracy) each."""
    runs = []
    for seed in range(4):
        runs.append(_run("grid16-dospcot", params, seed, *dospcot[seed]))
        runs.append(_run("grid16-masked-zero", params, seed, zero[seed], float("nan")))
        for view, values in (("patch", patch), ("rays", rays)):
            runs.append(_run("grid16-self-training", {**params, "views": f'["{view}"]'}, seed, *values[seed]))
    return runs


def test_h1_is_confirmed_only_when_both_paired_intervals_clear_zero_by_the_smallest_effect():
    patch = [(0.5, 0.90), (0.5, 0.91), (0.5, 0.92), (0.5, 0.93)]
    rays = [(0.0, 0.95), (0.5, 0.95), (0.0, 0.95), (0.5, 0.95)]  # higher accuracy, lower success
    dospcot = [(1.0, 0.97), (1.0, 0.98), (1.0, 0.97), (1.0, 0.98)]
    lines = second_view_tables(_setting(INDEPENDENT, dospcot, patch, rays))
    text = "\n".join(lines)
    # The better view per metric: rays for accuracy (0.95 > 0.915), patch for success (0.5 > 0.25).
    accuracy = SeedSummary.of([0.02, 0.03, 0.02, 0.03])
    better = "self-training (rays) (the better view, paired by seed)"
    assert f"pseudo-reward accuracy, DOSPCoT minus {better}: {accuracy}" in text
    assert "success, DOSPCoT minus self-training (patch)" in text
    assert "H1 (DOSPCoT above the better self-training view in both): **confirmed**" in text
    # An accuracy gain below the smallest effect (0.01) does not count, however sure.
    small = [(1.0, 0.955), (1.0, 0.955), (1.0, 0.955), (1.0, 0.955)]
    text = "\n".join(second_view_tables(_setting(INDEPENDENT, small, patch, rays)))
    assert "H1 (DOSPCoT above the better self-training view in both): **not confirmed**" in text


def test_h2_asks_both_intervals_to_hold_zero():
    same = [(0.5, 0.9), (1.0, 0.95), (0.5, 0.9), (1.0, 0.95)]
    text = "\n".join(second_view_tables(_setting(IDENTICAL, same, same, same)))
    assert "H2 (no difference: both intervals hold 0): **confirmed**" in text
    better = [(1.0, 0.99)] * 4
    text = "\n".join(second_view_tables(_setting(IDENTICAL, better, same, same)))
    assert "H2 (no difference: both intervals hold 0): **not confirmed**" in text


@pytest.mark.parametrize(
    ("zero", "verdict"), [((0.0, 0.0, 0.5, 0.0), "confirmed"), ((1.0,) * 4, "not confirmed")]
)
def test_h3_compares_masked_zero_with_the_better_self_training_view_and_dospcot(zero, verdict):
    ones = [(1.0, 0.9)] * 4
    text = "\n".join(second_view_tables(_setting(MONITOR, ones, ones, ones, zero)))
    assert f"H3 (masked-zero below self-training and DOSPCoT): **{verdict}**" in text
    assert "success, DOSPCoT minus masked-zero (paired by seed)" in text


def test_a_monitor_setting_also_reports_dospcot_against_the_better_self_training_view():
    patch = [(1.0, 0.90)] * 4
    rays = [(0.5, 0.96)] * 4
    dospcot = [(1.0, 0.95), (0.5, 0.94), (1.0, 0.95), (1.0, 0.94)]
    text = "\n".join(second_view_tables(_setting(MONITOR, dospcot, patch, rays)))
    accuracy = SeedSummary.of([-0.01, -0.02, -0.01, -0.02])  # against rays, the more accurate view
    success = SeedSummary.of([0.0, -0.5, 0.0, 0.0])  # against patch, the more successful one
    minus = "DOSPCoT minus self-training"
    better = "(the better view, paired by seed)"
    assert f"pseudo-reward accuracy, {minus} (rays) {better}: {accuracy} (no hypothesis)" in text
    assert f"success, {minus} (patch) {better}: {success} (no hypothesis)" in text
    assert text.index("H3 (") < text.index("(no hypothesis)")


def test_a_setting_with_a_method_not_yet_run_says_so():
    runs = [r for r in _setting(INDEPENDENT, [(1.0, 0.9)] * 4, [(1.0, 0.9)] * 4, [(1.0, 0.9)] * 4)]
    text = "\n".join(second_view_tables([r for r in runs if r.trial.name != "grid16-dospcot"]))
    assert "H1 (DOSPCoT above the better self-training view in both): not yet run" in text


def test_the_minigrid_table_gives_each_method_its_share_of_its_own_tasks_oracle_success(tmp_path):
    from dospcot.run.run_folder import write_toml
    from dospcot.tasks import load_config

    config = load_config("minigrid-lavagap-oracle").to_dict()

    def run(preset: str, seed: int, success: float, rewards: tuple[float, ...] = (0.0, 0.9)) -> TrialRun:
        view = {"success": success, "greedy_return": success / 2}
        summary = {"mean": dict(view), "views": ["image"], "per_view": {"image": view}, "rounds": 5}
        run_dir = tmp_path / preset / str(seed)
        run_dir.mkdir(parents=True)
        write_toml(run_dir / "config.toml", config)
        (run_dir / "reward_classes.json").write_text(json.dumps({"rewards": rewards}))
        return TrialRun(Trial(preset, preset, {}, seed), summary, [], run_dir)

    runs = [
        *(run("minigrid-lavagap-oracle", s, v) for s, v in enumerate((1.0, 0.8))),
        *(run("minigrid-lavagap-dospcot", s, v) for s, v in enumerate((0.45, 0.45))),
        *(run("minigrid-doorkey-oracle", s, 0.0) for s in range(2)),
        run("minigrid-doorkey-dospcot", 0, 0.5, (0.0,)),  # its labels hold no goal pair
        run("minigrid-doorkey-dospcot", 1, 0.5),
    ]
    rows = {line.split(" | ")[2]: line for line in minigrid_tables(runs) if line.startswith("| MiniGrid")}
    # The share of the oracle's success, then the labels used (these runs did not count theirs).
    assert rows["`minigrid-lavagap-oracle`"].endswith("| 100% | every reward |")
    assert rows["`minigrid-lavagap-dospcot`"].endswith("| 50% | unknown |")  # 0.45 of the oracle's 0.9
    assert rows["`minigrid-doorkey-dospcot`"].endswith("| n/a (oracle 0) | unknown |")
    lines = minigrid_tables(runs)
    assert "20 greedy episodes per agent" in lines[0]
    text = "\n".join(lines)
    assert "| MiniGrid-DoorKey-5x5-v0 | DOSPCoT | image | 0.500" in text
    assert (
        "- MiniGrid-LavaGapS7-v0: seeds whose DOSPCoT run met a labelled goal pair: 0, 1 (of 0, 1)." in text
    )
    assert "- MiniGrid-DoorKey-5x5-v0: seeds whose DOSPCoT run met a labelled goal pair: 1 (of 0, 1)." in text


def _labelled_run(preset: str, seed: int, labels: int | None, fraction: str | None = None) -> TrialRun:
    """A grid run of one view that held ``labels`` labels at its end (None: written before the count)."""
    mean = {"success": 1.0} | ({} if labels is None else {"labelled_steps": float(labels)})
    summary = {"mean": mean, "views": ["patch"], "per_view": {"patch": mean}, "rounds": 5}
    params = {} if fraction is None else {"training.label_fraction": fraction}
    return TrialRun(Trial(preset, preset, params, seed), summary, [], Path())


def test_the_grid_tables_give_the_labels_each_method_used_per_run():
    """Each method's runs' mean of the labels they held at their end; "every reward" for the oracle,
    whose count is the samples it met; the runs that counted them where some did not; "unknown" where
    none did."""
    runs = [
        *(_labelled_run("grid16-oracle", seed, 816) for seed in range(3)),
        *(_labelled_run("grid16-dospcot", seed, n) for seed, n in enumerate((40, 43, 47))),
        _labelled_run("grid16-self-training", 0, 41),
        _labelled_run("grid16-self-training", 1, None),
        *(_labelled_run("grid16-masked-zero", seed, None) for seed in range(2)),
    ]
    lines = grid16_tables(runs)
    # Every method once, in the presets' order, with the views its agents saw.
    assert lines[0] == (
        "Each method's views: oracle: patch; masked-zero: patch; self-training: patch; DOSPCoT: patch."
    )
    assert "| pseudo-reward accuracy | worst-class precision | coverage | labels used per run |" in lines[4]
    rows = {line.split(" | ")[1]: line for line in lines if line.startswith("| ") and "`" in line}
    assert rows["`grid16-oracle`"].endswith("| every reward |")
    assert rows["`grid16-dospcot`"].endswith("| 43 |")  # (40 + 43 + 47) / 3 = 43.3
    assert rows["`grid16-self-training`"].endswith("| 41 |")  # seed 1 predates the count
    assert rows["`grid16-masked-zero`"].endswith("| unknown |")
    assert "| DOSPCoT | patch | 1.000 [1.000, 1.000] | n/a | n/a | 43 |" in lines


def test_the_label_fraction_tables_give_each_cells_labels_in_the_same_shape():
    runs = [
        *(_labelled_run("grid16-dospcot", seed, n, "0.01") for seed, n in enumerate((8, 12))),
        *(_labelled_run("grid16-dospcot", seed, n, "0.05") for seed, n in enumerate((40, 45, 47))),
        _labelled_run("grid16-masked-zero", 0, 9, "0.01"),  # not run at 0.05
    ]
    lines = label_fraction_tables(runs)
    at = lines.index(
        "Labels used per run by label fraction (the labels each run held at its end, mean over seeds):"
    )
    assert lines[at + 2 : at + 6] == [
        "| method | 0.01 | 0.05 |",
        "|---|---|---|",
        "| DOSPCoT | 10 | 44 |",  # 20 / 2; 132 / 3
        "| masked-zero | 9 | n/a |",
    ]


def test_the_third_view_table_pairs_three_views_with_two_by_seed():
    two, three = THIRD_VIEW_ARMS
    success = {two: [0.0, 0.5, 1.0, 0.0], three: [1.0, 0.5, 1.0, 1.0]}
    runs = [
        _run("minigrid-doorkey-dospcot", THIRD_VIEW_ARMS[arm], seed, value, 0.99)
        for arm, values in success.items()
        for seed, value in enumerate(values)
    ]
    text = "\n".join(third_view_tables(runs))
    assert "| arm | seeds | success | pseudo-reward accuracy | labels used per run |" in text
    assert f"| {three} | 4 | {SeedSummary.of(success[three])} |" in text
    diff = SeedSummary.of([1.0, 0.0, 0.0, 1.0])  # three views minus two, seed by seed
    assert f"(paired by seed): {diff}; " in text


def test_the_demonstrations_table_names_each_arm_and_pairs_the_target_by_seed():
    runs = []
    success = {  # per arm, four seeds
        "labels 5%": [1.0, 0.5, 1.0, 0.5],
        "labels 1%": [0.0, 0.0, 0.5, 0.0],
        "labels 1% + 10 demonstrations": [1.0, 1.0, 1.0, 0.5],
    }
    for arm, values in success.items():
        for seed, value in enumerate(values):
            runs.append(_run("grid16-dospcot", DEMO_ARMS[arm], seed, value, 0.9))
    text = "\n".join(demonstration_tables(runs))
    assert "| worst-class precision | labels used per run |" in text
    for arm, values in success.items():
        assert f"| {arm} | 4 | {SeedSummary.of(values)} |" in text
    assert "as labels only" not in text  # an arm not run has no row
    diff = SeedSummary.of([0.0, 0.5, 0.0, 0.0])  # 1% + demonstrations minus 5%, seed by seed
    assert (
        f"(paired by seed): {diff}; F1, target (at least 0): **met**; "
        "demonstrations pay (the interval above 0): no" in text
    )
    worse = [run for run in runs if run.trial.params != DEMO_ARMS["labels 5%"]] + [
        _run("grid16-dospcot", DEMO_ARMS["labels 5%"], seed, 1.0, 0.9) for seed in range(4)
    ]
    assert "F1, target (at least 0): **not met**" in "\n".join(demonstration_tables(worse))
    assert STUDIES["demo-labels"].glance(runs).verdict.startswith("F1, target (at least 0): **met**; ")


def test_the_equal_effort_table_leads_with_effort_and_pairs_each_arm_with_per_step_labels():
    runs = []
    arms = {  # per arm, three seeds of (effort, success); the demonstrations arm predates the effort
        "per-step labels, 5% of keys": [(40, 1.0), (44, 0.5), (42, 1.0)],
        "segments of 4, equal effort": [(48, 0.0), (40, 0.5), (52, 0.0)],
        "labels 1% + 10 demonstrations": [(None, 1.0), (None, 1.0), (None, 1.0)],
    }
    for arm, values in arms.items():
        for seed, (effort, success) in enumerate(values):
            mean = {"success": success, "pseudo_accuracy": 0.9}
            if effort is not None:
                mean["labelled_steps"] = effort
            trial = Trial("grid16-dospcot", "grid16-dospcot", dict(EFFORT_ARMS[arm]), seed)
            runs.append(TrialRun(trial, {"mean": mean}, [], Path()))
    text = "\n".join(effort_tables(runs))
    effort, success = SeedSummary.of([40, 44, 42]), SeedSummary.of([1.0, 0.5, 1.0])
    assert f"| per-step labels, 5% of keys | 3 | {effort} | {success} |" in text
    assert "| labels 1% + 10 demonstrations | 3 | n/a | 1.000 [1.000, 1.000] |" in text
    assert "segments of 8" not in text  # an arm not run has no row
    diff = SeedSummary.of([-1.0, 0.0, -1.0])
    assert (
        f"- success, segments of 4, equal effort minus per-step labels, 5% of keys (paired by seed): {diff}"
        "; F2: **not met**" in text
    )
    # The demonstrations arm is compared, but F2 grades only the segments at equal effort.
    assert (
        "- success, labels 1% + 10 demonstrations minus per-step labels, 5% of keys (paired by seed): "
        in text
    )
    assert text.count("F2:") == 1
    glance = STUDIES["equal-effort"].glance(runs)
    assert glance.headline.endswith(f"paired by seed: {diff}")
    assert glance.verdict.startswith("F2: **not met**; ")


@pytest.mark.parametrize(
    ("differences", "grade"),
    [
        ((0.5, 0.5, 1.0), "F2: **met** (segments pay per unit of effort)"),
        ((0.0, 0.0, -0.05), "F2: **no worse** (the interval's lower end is at least -0.1)"),
        ((0.0, 0.5, -0.5), "F2: **not met**"),
    ],
)
def test_f2_grades_segments_at_equal_effort_by_their_interval(differences, grade):
    diff = SeedSummary.of(differences)
    assert EFFORT_TARGETS[0].grade(diff) == grade
    assert EFFORT_TARGETS[0].grade(SeedSummary.of([])) == "F2: not run"
    # The arm shared with the demo-labels study runs once, in that study's sweep.
    names = [sweep.name for sweep in STUDIES["equal-effort"].sweeps]
    assert "demonstrations-labels-1-10-demonstrations" in names
    assert names[0] == "effort-per-step-labels-5-of-keys"
    demo_names = [sweep.name for sweep in STUDIES["demo-labels"].sweeps]
    assert demo_names[:2] == [names[0], "demonstrations-labels-1-10-demonstrations"]


def test_the_highway_equal_effort_table_reads_returns_and_shows_the_experts_oracle_runs():
    runs = []
    for seed, (ret, crash_free) in enumerate([(20.0, 0.8), (22.0, 1.0)]):
        for arm, shift in (("per-step labels, 5% of steps", 0.0), ("segments of 4, 5% of segments", -2.0)):
            mean = {"greedy_return": ret + shift, "success": crash_free + shift / 10, "labelled_steps": 2000}
            params = dict(EFFORT_HIGHWAY_ARMS[arm])
            runs.append(TrialRun(Trial("fasthighway-dospcot", "x", params, seed), {"mean": mean}, [], Path()))
        oracle = {"greedy_return": 25.0, "success": 1.0}
        runs.append(TrialRun(Trial("fasthighway-oracle", "x", {}, seed), {"mean": oracle}, [], Path()))
    study_ = STUDIES["equal-effort-highway"]
    text = "\n".join(study_.tables(runs))
    assert "| return | no-crash episodes |" in text
    assert (
        f"| segments of 4, 5% of segments | 2 | 2000.0 [2000.0, 2000.0] | {SeedSummary.of([18.0, 20.0])} |"
        in text
    )
    assert (
        "| oracle (`fasthighway-oracle`) | 2 | every step | 25.0 [25.0, 25.0] | 1.000 [1.000, 1.000] |"
        in text
    )
    diff = SeedSummary.of([-0.2, -0.2])
    pair = "segments of 4, 5% of segments minus per-step labels, 5% of steps (paired by seed)"
    assert f"- no-crash episodes, {pair}: {diff}" in text
    assert f"- return, {pair}: {SeedSummary.of([-2.0, -2.0])}; F3: **not met**" in text  # graded in return
    assert "no-crash episodes, segments of 4, 5% of segments minus per-step labels, 5% of steps" in text
    assert "F2" not in text and text.count("F3:") == 1
    assert study_.glance(runs).verdict.startswith("F3: **not met**; ")
    # The expert trains first; the demonstrations arm reads its seed-0 agent.
    assert study_.sweeps[0].configs == ("fasthighway-oracle",)
    assert EXPERT.startswith(f"runs/sweeps/{study_.sweeps[0].name}/")


def _render_only(name: str, runs_dir: Path) -> subprocess.CompletedProcess:
    """``dospcot-lab study <name> --render-only`` on the sweeps under ``runs_dir``, in a process of its
    own."""
    command = [
        sys.executable,
        "-m",
        "dospcot_lab",
        "study",
        name,
        "--render-only",
        "--runs-dir",
        str(runs_dir),
    ]
    return subprocess.run(command, capture_output=True, text=True)


def test_render_only_with_no_finished_run_stops_with_one_line(tmp_path):
    empty = _render_only("equal-effort", tmp_path)
    assert empty.returncode == 1
    assert empty.stderr.strip() == (
        f"dospcot-lab study: error: no finished run of this study under {tmp_path}; run it without "
        "--render-only"
    )


def test_the_header_names_the_commits_that_trained_the_runs(tmp_path):
    """A study resumed across sessions may mix sources: the header counts the runs of each commit."""
    runs = []
    a, b = "a" * 40, "b" * 40
    resumed = {"commit": a, "session_commits": [None, b, a, a]}  # a run trained in four sessions
    for seed, info in enumerate([{"commit": a}, {"commit": b + "+dirty"}, {}, {"commit": a}, resumed]):
        run_dir = tmp_path / str(seed)
        run_dir.mkdir()
        (run_dir / "run_info.json").write_text(json.dumps({"wall_time_s": 48.0, **info}))
        (run_dir / "config.toml").write_text('name = "tiny"\n')  # written before versions: the first
        runs.append(TrialRun(Trial("tiny", "tiny", {}, seed), {}, [], run_dir))
    line = header(runs, "dospcot-lab study x", [tmp_path])[0]
    assert line.endswith(
        "; 4 minutes of training, the runs' wall times summed (one torch thread per run); source commits "
        "aaaaaaa (2), "
        "bbbbbbb with uncommitted changes (1), not recorded (1), not recorded then bbbbbbb then aaaaaaa (1)"
        "; defaults version 1 (5)."
    )
    for run, cpu in zip(runs, (6.0, 30.0, 36.0, 36.0, 72.0), strict=True):
        # every run with its CPU time: the header counts that, not the wall time, and per run
        info = json.loads((run.run_dir / "run_info.json").read_text())
        (run.run_dir / "run_info.json").write_text(json.dumps({**info, "cpu_time_s": cpu}))
    line = header(runs, "dospcot-lab study x", [tmp_path])[0]
    # 180 CPU-s in all over 5 runs: 36 a run (0.60 CPU-minutes), from 6 s (0.10) to 72 s (1.2)
    assert (
        "; 3 CPU-minutes of training (one torch thread per run; 0.60 a run on average, from 0.10 to 1.2); "
        in line
    )


def test_the_header_counts_the_cpu_models_and_kernels_where_runs_recorded_them(tmp_path):
    """Runs are deterministic on one CPU model: a study trained on two shows it."""
    cpus = ["Xeon, torch kernels AVX512", "EPYC, torch kernels AVX2", None]
    runs = []
    for seed, cpu in enumerate(cpus):
        run_dir = tmp_path / str(seed)
        run_dir.mkdir()
        info = {"wall_time_s": 60.0, "commit": "a" * 40} | ({"cpu": cpu} if cpu else {})
        (run_dir / "run_info.json").write_text(json.dumps(info))
        (run_dir / "config.toml").write_text(f"defaults = {1 + (seed == 0)}\n")
        runs.append(TrialRun(Trial("tiny", "tiny", {}, seed), {}, [], run_dir))
    line = header(runs, "dospcot-lab study x", [tmp_path])[0]
    # The versions of the defaults the runs resolved under, counted as the CPUs are.
    assert line.endswith(
        "source commit aaaaaaa (3); CPUs EPYC with torch kernels AVX2 (1), Xeon with torch kernels "
        "AVX512 (1), not recorded (1); "
        "defaults versions 1 (2), 2 (1)."
    )


def test_render_only_refuses_a_trial_trained_under_another_config(tmp_path, capfd):
    """A table rebuilt from a record must not count a run under a preset that has changed since."""
    from dospcot.run.run_folder import write_toml
    from dospcot.tasks import load_config
    from dospcot_lab.cli import main

    trial = "grid16-masked-zero/training.label_fraction=0.01__seed=0"
    stored = tmp_path / "label-fraction/trials" / trial / "config.toml"
    stored.parent.mkdir(parents=True)
    # the trial as the study resolves it: under the version of the defaults and numerics its sweep pins
    overrides = ["cotraining.numerics=1", "training.label_fraction=0.01", "seed=0"]
    current = load_config("grid16-masked-zero", overrides, defaults=1)
    write_toml(stored, current.to_dict())
    stored.write_text(stored.read_text().replace("steps_per_round = 8000", "steps_per_round = 7000"))
    # The command's main in this process (test_render_only_with_no_finished_run_stops_with_one_line runs
    # it in its own): its exit, a message, is what the process prints on stderr with exit status 1.
    with pytest.raises(SystemExit) as stale:
        main(["study", "label-fraction", "--render-only", "--runs-dir", str(tmp_path)])
    assert stale.value.code == (
        f"dospcot-lab study: error: 1 trial(s) in {tmp_path / 'label-fraction'} were trained with another "
        f"config than their preset and overrides give now (e.g. {trial}: training.steps_per_round was "
        "7000, is 8000); move the sweep folder away, or delete those trials' folders, to run them again"
    )
    assert capfd.readouterr().err == ""


def _queries_arm(
    folder: Path, fraction: str, seeds: range, accuracy: float, queries: str = "", **strategy: str
) -> list[TrialRun]:
    """Runs of one grid16-dospcot arm; ``queries`` the body of each run's queries.csv."""
    mean = {"success": 1.0, "pseudo_accuracy": accuracy, "worst_class_precision": 0.8, "labelled_steps": 17}
    params = {"env.layout_seed": "101", "training.label_fraction": fraction, **strategy}
    runs = []
    for seed in seeds:
        run_dir = folder / f"{fraction}-{strategy}-{seed}"
        run_dir.mkdir(parents=True)
        (run_dir / "queries.csv").write_text("round,sample,strategy,answer\n" + queries)
        (run_dir / "metrics.csv").write_text(f"round,pseudo_accuracy\n1,{accuracy}\n")
        runs.append(TrialRun(Trial("grid16-dospcot", "x", params, seed), {"mean": mean}, [], run_dir))
    return runs


def test_the_queries_tables_say_who_chose_each_active_arms_queries(tmp_path):
    disagreement = {"training.label_strategy": "disagreement"}
    # Per run: 3 queries at random in round 1 (no classifier yet), then in round 2 one at random (the
    # random share) and one by disagreement. Pooled over 2 runs: 5 per run, 2 of 5 after round 1, 1 of
    # 5 chosen by the strategy.
    log = "1,4,random,0\n1,7,random,0\n1,9,random,-1\n2,3,random,0\n2,5,disagreement,1\n"
    runs = _queries_arm(tmp_path, "0.02", range(2), 0.9, log, **disagreement)
    runs += _queries_arm(tmp_path, "0.05", range(2), 0.9)  # the uniform mask asks nothing: no row
    lines = STUDIES["queries"].tables(runs)
    at = lines.index(
        "| grid16, layouts 101, 202, 303: queries | per run | after round 1 | chosen by the strategy | runs |"
    )
    assert lines[at + 2 :][:2] == ["| dospcot disagreement @ 0.02 | 5.0 | 40.0% | 20.0% | 2 |", ""]


def test_a_queries_hypothesis_waits_for_every_pair_of_its_arms(tmp_path):
    def arm(fraction: str, seeds: range, accuracy: float, **strategy: str) -> list[TrialRun]:
        return _queries_arm(Path(tempfile.mkdtemp(dir=tmp_path)), fraction, seeds, accuracy, **strategy)

    def runs_of(reference_seeds: range) -> list[TrialRun]:
        disagreement = arm("0.02", range(4), 0.95, **{"training.label_strategy": "disagreement"})
        return disagreement + arm("0.05", reference_seeds, 0.99)

    tables = STUDIES["queries"].tables
    assert "lower bound >= -0.05: not decided yet (2 of 4 pairs run)." in "\n".join(tables(runs_of(range(2))))
    assert "lower bound >= -0.05: **held**." in "\n".join(tables(runs_of(range(4))))


def test_the_minigrid_tables_count_goal_labels_and_compare_outcomes_with_the_blind_mask(tmp_path):
    """On MiniGrid a seed whose labels hold no goal step cannot learn the goal: the table counts them,
    and the unregistered differences are paired by seed over the pairs both arms have run."""

    def arm(strategy: str, successes: list[float], goal: list[bool]) -> list[TrialRun]:
        params = {"training.label_fraction": "0.1", "training.label_strategy": strategy}
        runs = []
        for seed, (success, labelled) in enumerate(zip(successes, goal, strict=True)):
            run_dir = tmp_path / f"{strategy}-{seed}"
            run_dir.mkdir()
            (run_dir / "reward_classes.json").write_text(
                json.dumps({"rewards": [0.0, 0.5 if labelled else 0.0]})
            )
            (run_dir / "queries.csv").write_text("round,sample,strategy,answer\n")
            (run_dir / "metrics.csv").write_text(f"round,success\n1,{success}\n")
            mean = {
                "success": success,
                "pseudo_accuracy": 1.0,
                "worst_class_precision": 1.0,
                "labelled_steps": 9,
            }
            runs.append(
                TrialRun(Trial("minigrid-lavagap-dospcot", "x", params, seed), {"mean": mean}, [], run_dir)
            )
        return runs

    # outcomes minus uniform over seeds 0-2 (the pairs both have): 0.9 - 0.1, 0.8 - 0.8, 0.7 - 0.4.
    runs = arm("outcomes", [0.9, 0.8, 0.7, 0.6], [True] * 4) + arm(
        "uniform", [0.1, 0.8, 0.4], [False, True, True]
    )
    lines = STUDIES["queries"].tables(runs)
    assert (
        "| MiniGrid-LavaGapS7-v0 | success | pseudo_accuracy | worst_class_precision | labelled_steps "
        "| goal labelled | seeds |" in lines
    )
    assert [line.split(" | ")[-2] for line in lines if line.startswith("| dospcot ")][:2] == ["4/4", "2/3"]
    diff = SeedSummary.of([0.8, 0.0, 0.3])
    assert (
        "- Descriptive, not registered (MiniGrid-LavaGapS7-v0): success of dospcot outcomes minus dospcot "
        f"uniform (labels placed on episode ends against the blind mask), paired: {diff} over 3 pairs."
    ) in lines
    assert diff.mean == pytest.approx(1.1 / 3)
    assert not any("dospcot disagreement minus" in line for line in lines)  # one arm of it has not run


def test_the_queries_tables_name_arms_that_trained_the_same_runs(tmp_path):
    """Two strategies that asked the same queries train the same agents: the tables count the seeds
    whose metrics.csv match byte for byte, over the pairs both arms have run."""
    runs = _queries_arm(tmp_path / "a", "0.02", range(3), 0.9, **{"training.label_strategy": "uncertainty"})
    runs += _queries_arm(tmp_path / "b", "0.02", range(2), 0.9, **{"training.label_strategy": "random"})
    for run in runs:
        same = run.trial.seed == 0 or run.trial.params["training.label_strategy"] == "uncertainty"
        (run.run_dir / "metrics.csv").write_text(
            "round,success\n1,1.0\n" if same else "round,success\n1,0.5\n"
        )
    assert (
        "- Identical runs (grid16, layouts 101, 202, 303): dospcot uncertainty @ 0.02 and dospcot random "
        "@ 0.02 trained byte-identical runs (metrics.csv) on 1 of their 2 pairs."
    ) in STUDIES["queries"].tables(runs)


def test_highway_envs_cost_bound_judges_its_first_dospcot_run_and_trains_it_first(tmp_path):
    def run(seed: int, minutes: float, preset: str = "highway-dospcot") -> TrialRun:
        folder = tmp_path / f"{preset}-{seed}"
        folder.mkdir()
        (folder / "run_info.json").write_text(json.dumps({"cpu_time_s": minutes * 60}))
        return TrialRun(Trial(preset, preset, {}, seed), {"mean": {}}, [], folder)

    within = cost_bound([run(1, 95.0), run(0, 42.0), run(0, 10.0, "highway-oracle")])
    assert within[0] == (
        "Cost bound (pre-registered): `highway-dospcot` runs took 42 (seed 0), 95 (seed 1) CPU-minutes; "
        "the first, seed 0, within the bound of 80: the study runs."
    )
    over = cost_bound([run(2, 81.0)])
    assert over[0].endswith("the first, seed 2, over the bound of 80: the study is withdrawn.")
    assert cost_bound([run(3, 5.0, "highway-oracle")]) == []  # no DOSPCoT run yet
    # The bounded run trains first; the fast highway's sweep keeps the order its runs were trained in.
    assert STUDIES["highway"].sweeps[0].configs[0] == "highway-dospcot"
    assert STUDIES["fasthighway"].sweeps[0].configs == tuple(
        f"fasthighway-{m}" for m in ("oracle", "masked-zero", "self-training", "dospcot")
    )


def test_seeds_to_clear_is_the_normal_approximations_count_of_pairs():
    # sd of (0.1, -0.1) is sqrt(0.02); (1.959964 + 0.841621) * 0.141421 / 0.1 = 3.96206, squared 15.70.
    assert seeds_to_clear([0.1, -0.1], 0.1) == 16
    # Twice the margin takes a quarter of the pairs: 3.92 rounds up to 4.
    assert seeds_to_clear([0.1, -0.1], 0.2) == 4
    assert seeds_to_clear([0.0, 0.0, 0.0], 0.1) == 2  # no spread: an interval still needs two
    assert seeds_to_clear([0.5], 0.1) is None
