"""The lab's command, ``dospcot-lab study|bench``, as a newcomer meets it: a misspelled study, more seeds
than a machine finishes, a bench output that would land in the published BENCHMARKS.md, a stop between
two sweeps, and the library's ``dospcot study`` pointing at the lab."""

from __future__ import annotations

import pytest

from dospcot.cli.parser import build_parser
from dospcot.config.presets import preset_names
from dospcot.run.cores import usable_cores
from dospcot.run.sizes import check_sizes
from dospcot.tasks import load_config


def test_the_bench_refuses_an_output_it_would_misread(capsys, tmp_path):
    from dospcot_lab.cli import main as lab_main

    cases = [
        (["bench", "--quick", "--out", str(tmp_path / "x" / "BENCHMARKS.md")], "never go into BENCHMARKS.md"),
        (["bench", "--quick", "--out", "/proc/nope/bench.md"], "cannot make its folder"),
    ]
    for argv, message in cases:
        assert lab_main(argv) == 2, argv
        err = capsys.readouterr().err
        assert message in err and err.count("\n") == 1, err


def test_a_misspelled_study_is_answered_with_the_name_meant(capsys):
    from dospcot_lab.cli import main as lab_main

    assert lab_main(["study", "grid61"]) == 2
    assert capsys.readouterr().err == (
        "dospcot-lab study: error: no study 'grid61'; did you mean 'grid16' or 'grid32'?\n"
    )


def test_every_preset_and_every_studys_sweeps_pass_the_size_checks():
    from dospcot_lab.studies import STUDIES, sweep_spec

    for name in preset_names():
        assert check_sizes([load_config(name)], 10, workers=1) == [], name
    for study in STUDIES.values():
        for sweep in study.sweeps:
            cfgs = sweep_spec(sweep, study.seeds).cell_configs()
            check_sizes(cfgs, study.seeds, workers=1, batch=1)  # refuses nothing; a warning may say how long


def test_a_study_with_too_many_seeds_is_refused_before_any_sweep(capsys, tmp_path):
    from dospcot_lab.cli import main as lab_main

    assert lab_main(["study", "grid16", "--seeds", "100000", "--runs-dir", str(tmp_path)]) == 2
    err = capsys.readouterr().err.rstrip("\n")
    assert "\n" not in err
    assert err.startswith("dospcot-lab study: error: 100,000 seeds would take about ")
    assert err.endswith("CPU-days (an estimate) and make a run folder each; give at most 10,000")
    assert list(tmp_path.iterdir()) == []


def test_a_stop_between_two_sweeps_of_a_study_says_what_it_kept_and_how_to_go_on(
    tmp_path, capsys, monkeypatch
):
    """SIGTERM after one sweep's last trial, before the next sweep starts: one line, not a bare
    "interrupted", and the study's own command to go on."""
    from types import SimpleNamespace

    from dospcot_lab import studies
    from dospcot_lab.cli import main as lab_main

    started = []

    def run_sweep(sweep_dir, spec, **options):
        started.append(sweep_dir.name)
        if len(started) == 2:
            raise KeyboardInterrupt  # what SIGTERM raises (stop_on_signals)
        return SimpleNamespace(failed={})

    monkeypatch.setattr(studies, "run_sweep", run_sweep)
    runs = tmp_path / "sweeps"
    assert lab_main(["study", "minigrid", "--runs-dir", str(runs)]) == 130
    assert len(started) == 2
    err = capsys.readouterr().err
    assert err == (
        f"dospcot-lab study: interrupted; kept every trial that finished, under {runs}; "
        f"resume with: dospcot-lab study minigrid --runs-dir {runs}\n"
    )


@pytest.mark.parametrize(
    ("commit", "where"), [("abc123+dirty", "with uncommitted changes"), (None, "not from a git")]
)
def test_a_confirmatory_study_trains_only_from_a_committed_clean_checkout(
    commit, where, tmp_path, capsys, monkeypatch
):
    from dospcot_lab import studies
    from dospcot_lab.cli import main as lab_main

    started = []
    monkeypatch.setattr(studies, "source_commit", lambda: commit)
    monkeypatch.setattr(studies, "run_sweep", lambda sweep_dir, spec, **options: started.append(sweep_dir))
    with pytest.raises(SystemExit) as stop:
        lab_main(["study", "defaults", "--runs-dir", str(tmp_path)])
    assert "defaults is confirmatory and trains only from a committed checkout" in str(stop.value)
    assert where in str(stop.value) and started == [] and list(tmp_path.iterdir()) == []
    # An exploratory study trains from any checkout; a confirmatory one renders from any.
    assert not studies.get_study("minigrid").confirmatory and studies.get_study("budget").confirmatory
    with pytest.raises(SystemExit) as stop:
        lab_main(["study", "defaults", "--render-only", "--runs-dir", str(tmp_path)])
    assert "no finished run of this study" in str(stop.value)


def test_the_studies_are_the_labs_command_and_the_library_says_where_they_are(capsys, tmp_path):
    from dospcot.cli import main
    from dospcot_lab.cli import main as lab_main

    for command in ("study", "bench"):
        assert main([command, "grid16"]) == 2
        err = capsys.readouterr().err
        assert err.startswith(f"dospcot {command}: error: the studies and benchmarks are the repository's")
        assert f"`dospcot-lab {command} ...`" in err and err.count("\n") == 1
    assert lab_main(["study", "nope"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("dospcot-lab study: error: no study 'nope'; the studies: grid16,")
    assert err.count("\n") == 1
    with pytest.raises(SystemExit, match="no finished run of this study under"):
        lab_main(["study", "grid16", "--render-only", "--runs-dir", str(tmp_path)])


@pytest.mark.parametrize(
    ("command", "what"),
    [("sweep", "trials at once"), ("study", "trials at once"), ("reproduce-paper", "processes")],
)
def test_workers_default_to_the_cores_this_process_may_use(command, what, capsys):
    from dospcot_lab.cli import build_parser as lab_parser

    cores = usable_cores()
    parser = lab_parser() if command == "study" else build_parser()
    assert parser.parse_args([command, *(["grid16"] if command == "study" else [])]).workers == cores
    with pytest.raises(SystemExit):
        parser.parse_args([command, "--help"])
    help_text = " ".join(capsys.readouterr().out.split())
    assert f"--workers WORKERS {what} (default: the cores this process may use, {cores} here)" in help_text


def test_a_study_trains_the_sweeps_named_alone_and_its_header_names_the_whole_study(
    tmp_path, capsys, monkeypatch
):
    from types import SimpleNamespace

    from dospcot_lab import studies
    from dospcot_lab.cli import main as lab_main

    started = []
    monkeypatch.setattr(
        studies,
        "run_sweep",
        lambda sweep_dir, spec, **options: started.append(sweep_dir.name) or SimpleNamespace(failed={}),
    )
    runs = tmp_path / "sweeps"
    argv = ["study", "true-rewards", "--sweep", "true-rewards-doorkey-rounds", "--runs-dir", str(runs)]
    with pytest.raises(SystemExit, match="no finished run of this study"):
        lab_main([*argv, "--sweep=true-rewards-grid16"])
    assert started == ["true-rewards-doorkey-rounds", "true-rewards-grid16"]
    # A sweep the study lacks is one line naming the one meant, before anything trains.
    assert lab_main(["study", "true-rewards", "--sweep", "true-rewards-doorkey-round"]) == 2
    err = capsys.readouterr().err
    assert err.startswith(
        "dospcot-lab study: error: true-rewards has no sweep 'true-rewards-doorkey-round'; "
        "did you mean 'true-rewards-doorkey-rounds' or "
    )
    assert err.count("\n") == 1
    assert started == ["true-rewards-doorkey-rounds", "true-rewards-grid16"]
    header = studies.header_command(("dospcot-lab", "study"), "x", ["--sweep", "a", "--docs", "--sweep=b"])
    assert header == "dospcot-lab study x --docs"
