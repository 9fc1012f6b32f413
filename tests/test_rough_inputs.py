"""What a new user types that is wrong ends in one line (no traceback), exit status 2 and no folder; what
would hang or run for ever is refused at once; what would be silently ignored is named."""

from __future__ import annotations

import contextlib
import io
import subprocess
import sys
import typing
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from test_bad_inputs import _keys

from dospcot.cli import main
from dospcot.config.errors import ConfigError
from dospcot.config.run_configs import PaperConfig, TrainConfig
from dospcot.tasks import load_config
from dospcot_lab.cli import main as lab_main

SHORT = ["training.rounds=1", "training.steps_per_round=60", "dqn.learning_starts=20"]


LAB_COMMANDS = ("study", "bench")
"""The commands of the repository's lab, ``dospcot-lab``."""


def _refused(argv: list[str], where: Path) -> str:
    """Run ``dospcot ARGV`` (``dospcot-lab ARGV`` for a lab command) in this process; assert exit status
    2, one line on stderr and nothing in ``where``; return the line."""
    out, err = io.StringIO(), io.StringIO()
    command = lab_main if argv[0] in LAB_COMMANDS else main
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            status = command(argv)
        except SystemExit as stop:  # argparse's own errors
            status = stop.code
    line = err.getvalue()
    assert status == 2, (argv, line, out.getvalue())
    assert line.count("\n") == 1 and "Traceback" not in line, line
    assert not where.exists() or list(where.iterdir()) == [], f"{argv} left {list(where.iterdir())}"
    return line.strip()


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        # Names and folders: one rule, and nothing outside --runs-dir.
        (["sweep", "tiny", "--name", "../../escaped"], "expected one folder's name, got '../../escaped'"),
        (["sweep", "tiny", "--name", "a/b"], "a path, not one folder's name"),
        (["sweep", "tiny", "--name", ".."], "a name starting with '.'"),
        (["sweep", "tiny", "--name", ""], "an empty name"),
        (["train", "tiny", "--set", 'name="../x"'], "name: must be a plain folder name"),
        (["train", "tiny", "--runs-dir", ""], "expected a folder, got an empty path"),
        (["sweep", "tiny", "--runs-dir", " "], "expected a folder, got an empty path"),
        (["reproduce-paper", "--out", ""], "expected a folder, got an empty path"),
        (["bench", "--quick", "--out", ""], "expected a file, got an empty path"),
        (["train", "tiny", "--seeds", "99999999999999999999,1"], "--seeds takes seeds up to"),
        (["sweep", "tiny", "--seeds", "1,99999999999999999999"], "--seeds takes seeds up to"),
        # A --set that something else would replace.
        (["train", "tiny", "--seeds", "2", "--set", "seed=5"], "--seeds gives the seeds here"),
        (["sweep", "tiny", "--set", "seed=5"], "give the seed as --seeds 5-5 instead"),
        # A prefix of an option is not that option: --seed 3 is not a batch of seeds 0-2.
        (["sweep", "tiny", "--seed", "3"], "unrecognized arguments: --seed 3; did you mean '--seeds'"),
        (["train", "tiny", "--see", "3"], "unrecognized arguments: --see 3"),
        (["train", "tiny", "--seed", "3", "--seeds", "2"], "--seed and --seeds: give one"),
        (["train", "tiny", "--seed", "3", "--set", "seed=4"], "give the seed as --seed 4 instead"),
        (["train", "tiny", "--seed", "-1"], "--seed takes a seed from 0 to"),
        (["train", "--resume", "x", "--seed", "1"], "takes no CONFIG, --set, --seed or --seeds"),
        (["train", "tiny", "--seeds", "5-3"], "a range runs from a seed >= 0 up to a seed no smaller"),
        (["sweep", "tiny", "--seeds", "1-x"], "a list (0,3,7) or a range (100-104)"),
        (
            ["sweep", "tiny", "--grid", "training.rounds=1,2", "--set", "training.rounds=3"],
            "--grid training.rounds sets training.rounds in every trial",
        ),
        (
            ["sweep", "tiny", "--grid", "training.rounds=1,2", "--set", "training={rounds=3}"],
            "--grid training.rounds sets training",
        ),
        (
            ["train", "tiny", "--set", "training.rounds=1", "--set", "training.rounds=2"],
            "both set training.rounds: give it once",
        ),
        (
            ["study", "grid16-layouts", "--set", "env.layout_seed=3"],
            "env.layout_seed sets env.layout_seed in every trial, which would replace it",
        ),
        # Integers TOML cannot hold.
        (["train", "tiny", "--set", "seed=99999999999999999999"], "seed: 99999999999999999999 is beyond"),
        (["train", "tiny", "--set", "dqn.net_arch=[32, 99999999999999999999]"], "dqn.net_arch: 9999"),
        (["train", "tiny", "--set", "env.layout_seed=-99999999999999999999"], "is beyond a 64-bit"),
        # Keys the method never reads, and settings it cannot use.
        (["train", "tiny", "--set", "cotraining.ensemble_size=5"], 'method = "dospcot" never reads it'),
        (
            ["train", "grid16-reward-model", "--set", "cotraining.consensus_weight=0.5"],
            'cotraining.consensus_weight: method = "reward-model" never reads it',
        ),
        (
            ["train", "tiny", "--set", "method=oracle", "--set", "cotraining.classifier.epochs=5"],
            'method = "oracle" never reads it',
        ),
        (
            ["train", "grid16-reward-model", "--set", "cotraining.ensemble_size=1"],
            "raise ensemble_size to 2 or more",
        ),
        (
            [
                "train",
                "tiny",
                "--set",
                "training.label_strategy=random",
                "--set",
                "training.label_budget=1000000000000",
            ],
            "1,000,000,000,000 answers cannot be spent: the run meets at most 144 samples",
        ),
        # What would have been a traceback.
        (["train", "tiny", "--threads", "100000"], "expected a thread count from 1 to this machine's"),
        (["rate", "x", "--port", "99999"], "expected a port from 1 to 65535"),
        (["rate", "x", "--port", "-1"], "expected a port from 1 to 65535"),
        (
            ["train", "tiny", "--set", "cotraining.max_classes=1000000000"],
            "the reward classifiers would need at least",
        ),
        # What would have run for ever.
        (["study", "grid16", "--seeds", "0"], "expected a positive integer, got 0"),
        (
            ["train", "tiny", "--set", "method=reward-model", "--set", "cotraining.ensemble_size=100000"],
            "lower cotraining.max_classes, cotraining.classifier.hidden or cotraining.ensemble_size",
        ),
        (
            ["train", "tiny", "--set", "cotraining.classifier.epochs=1000000000"],
            "lower cotraining.classifier.epochs",
        ),
        (
            ["train", "tiny", "--set", "training.update_steps=1000000000000"],
            "lower dqn.gradient_steps, training.update_steps",
        ),
        (
            ["train", "tiny", "--set", "dqn.gradient_steps=1000000000"],
            "or allow more: DOSPCOT_MAX_RUN_CPU_DAYS",
        ),
        (
            [
                "train",
                "tiny",
                "--set",
                "agent=tabular",
                "--set",
                "tabular_agent.gradient_steps=1000000000000",
            ],
            "lower tabular_agent.gradient_steps",
        ),
        (
            ["train", "paper-text", "--set", "tabular.replay_sweeps=1000000000000"],
            "lower tabular.replay_sweeps",
        ),
        (
            ["train", "tiny", "--set", "dqn.net_arch=[1000000, 1000000]"],
            "the Q-networks of dqn.net_arch",
        ),
        # Misleading answers, now the right ones.
        (["train", "/dev/zero"], "/dev/zero is not a regular file"),
        (["train", "TINY"], "no preset 'TINY'; did you mean 'tiny'?"),
        (["trian", "tiny"], "invalid choice: 'trian'; did you mean 'train'?"),
        (["train", "tiny", "--set", "task=paper"], 'task = "paper" makes this a paper-protocol config'),
        (
            ["sweep", "tiny", "--grid", "training.rounds=[1,2"],
            "--grid training.rounds=[1,2: '[1,2' opens and closes a different number of [ and ]",
        ),
        (
            ["study", "grid16", "--set", "training.nokey=1", "--render-only"],
            "unknown key 'training.nokey'",
        ),
    ],
)
def test_a_rough_input_is_one_line_exit_2_and_no_folder(argv, message, tmp_path):
    where = tmp_path / "runs"
    options = {
        "train": ["--runs-dir", str(where)],
        "sweep": ["--runs-dir", str(where)],
        "study": ["--runs-dir", str(where)],
        "reproduce-paper": [],
    }
    extra = [] if "--runs-dir" in argv or "--out" in argv else options.get(argv[0], [])
    line = _refused([*argv, *extra], where)
    assert message in line, line


def test_the_hangs_answer_at_once_in_a_process_of_their_own(tmp_path):
    """Ray's retries and the costs no machine finishes: a fresh process answers long before a hang
    would (Ray retried for 86 s), and writes nothing."""
    cases = [
        ["sweep", "tiny", "--backend", "ray", "--ray-address", "127.0.0.1:1", "--runs-dir", str(tmp_path)],
        ["train", "tiny", "--set", "cotraining.classifier.epochs=1000000000", "--runs-dir", str(tmp_path)],
        ["study", "grid16", "--seeds", "0", "--runs-dir", str(tmp_path)],
    ]
    for argv in cases:
        program = "dospcot_lab" if argv[0] in LAB_COMMANDS else "dospcot.cli"
        done = subprocess.run(
            [sys.executable, "-m", program, *argv], capture_output=True, text=True, timeout=60
        )
        assert done.returncode == 2 and done.stderr.count("\n") == 1, done.stderr
    assert list(tmp_path.iterdir()) == []


def test_the_run_bound_can_be_raised_from_the_environment(monkeypatch):
    from dospcot.run.sizes import RUN_LIMIT_VARIABLE, check_sizes

    cfg = load_config("tiny", ["cotraining.classifier.epochs=1000000000"])
    with pytest.raises(ConfigError, match=f"more than the 3.0 CPU-days a run may; .*{RUN_LIMIT_VARIABLE}"):
        check_sizes([cfg])
    monkeypatch.setenv(RUN_LIMIT_VARIABLE, "1000")
    assert check_sizes([cfg]) == []
    monkeypatch.setenv(RUN_LIMIT_VARIABLE, "lots")
    with pytest.raises(ConfigError, match="give the most CPU-days one seed may take"):
        check_sizes([cfg])


@pytest.mark.parametrize(
    ("content", "message"),
    [
        ("ﾃｿﾃｾ".encode(), None),  # UTF-8, not TOML: the TOML error
        ('name = "x"\n'.encode("utf-16"), "is not UTF-8 text"),
        (bytes(range(256)), "is not UTF-8 text"),
        (b"x" * (2 << 20), "more than a config's"),
    ],
)
def test_a_config_file_that_is_not_utf8_toml_is_one_line(tmp_path, content, message):
    path = tmp_path / "c.toml"
    path.write_bytes(content)
    line = _refused(["train", str(path), "--runs-dir", str(tmp_path / "runs")], tmp_path / "runs")
    assert (message or "is not valid TOML") in line


def test_a_bom_is_read_past_and_extends_is_read_from_the_configs_own_folder(tmp_path, monkeypatch):
    folder = tmp_path / "configs"
    folder.mkdir()
    (folder / "good.toml").write_text('extends = "tiny"\n[training]\nrounds = 1\n')
    (folder / "mine.toml").write_bytes('\ufeffextends = "good.toml"\nname = "mine"\n'.encode())
    monkeypatch.chdir(tmp_path)  # not the configs' folder
    cfg = load_config(str(folder / "mine.toml"))
    assert (cfg.name, cfg.training.rounds, cfg.env.size) == ("mine", 1, 6)
    # A key the file states, under a method that never reads it, is named.
    (folder / "rm.toml").write_text('extends = "tiny"\nmethod = "reward-model"\n[cotraining]\ntol = 0.1\n')
    with pytest.raises(ConfigError, match=r'cotraining\.tol: method = "reward-model" never reads it'):
        load_config(str(folder / "rm.toml"))


def test_a_section_inside_another_is_named_as_a_section(tmp_path):
    path = tmp_path / "c.toml"
    path.write_text('extends = "tiny"\n[env.training]\nrounds = 1\n')
    with pytest.raises(ConfigError, match=r"\[training\] is a section of its own, not one of \[env\]"):
        load_config(str(path))


def test_a_config_toml_that_is_a_folder_is_named(tmp_path):
    run = tmp_path / "run"
    (run / "config.toml").mkdir(parents=True)
    line = _refused(["train", "--resume", str(run)], tmp_path / "none")
    assert f"{run / 'config.toml'} is not a file" in line
    line = _refused(["train", str(run)], tmp_path / "none")
    assert "holds a config.toml that is not a file" in line


def test_every_shipped_preset_still_loads_and_prints():
    from dospcot.config.presets import preset_names

    for name in preset_names():
        load_config(name)
        with contextlib.redirect_stdout(io.StringIO()):
            assert main(["config", name]) == 0, name


def test_a_run_folders_whole_config_trains_again(tmp_path):
    """A whole config written out holds every key, the method's unread ones at their defaults: it is
    no setting of them, and trains again."""
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        assert main(["config", "grid16-reward-model"]) == 0
    (tmp_path / "c.toml").write_text(out.getvalue())
    assert load_config(str(tmp_path / "c.toml")) == load_config("grid16-reward-model")


def test_report_names_and_leaves_out_a_trial_it_cannot_read(tmp_path, capsys):
    sets = [a for s in SHORT for a in ("--set", s)]
    argv = ["sweep", "tiny", "--seeds", "2", "--workers", "1", "--runs-dir", str(tmp_path), "--name", "s"]
    assert main([*argv, *sets, "--no-progress"]) == 0
    summaries = sorted((tmp_path / "s").glob("trials/*/*/summary.json"))
    assert len(summaries) == 2
    summaries[0].write_text("{not json")
    capsys.readouterr()
    assert main(["report", str(tmp_path / "s")]) == 0
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err
    assert err.startswith(f"dospcot report: warning: left out trial {summaries[0].parent}: cannot be read")
    assert (tmp_path / "s" / "report.md").is_file()
    for summary in summaries:
        summary.write_text("[]")
    assert main(["report", str(tmp_path / "s")]) == 2
    assert "has no finished trial yet" in capsys.readouterr().err.splitlines()[-1]


def test_integers_at_int64s_bounds_load():
    assert load_config("tiny", [f"env.layout_seed={2**63 - 1}"]).env.layout_seed == 2**63 - 1
    with pytest.raises(ConfigError, match="is beyond a 64-bit integer"):
        load_config("tiny", [f"env.layout_seed={2**63}"])


# --- Property tests: any --set value and any TOML file of config keys ---------------------------------


TRAIN_KEYS = [key for key, _ in _keys(TrainConfig)]
PAPER_KEYS = [key for key, _ in _keys(PaperConfig)]
SCALARS = st.one_of(
    st.integers(),
    st.integers(-(2**70), 2**70),
    st.floats(allow_nan=True, allow_infinity=True),
    st.booleans(),
    st.text(max_size=12),
    st.sampled_from(["dospcot", "reward-model", "oracle", "grid", "paper", "gym", "disagreement", "random"]),
)
VALUES = st.recursive(
    SCALARS,
    lambda inner: st.one_of(
        st.lists(inner, max_size=3), st.dictionaries(st.text(min_size=1, max_size=6), inner, max_size=3)
    ),
    max_leaves=6,
)


def _one_line_or_config(load: typing.Callable[[], typing.Any]) -> None:
    """``load()`` returns a config that the size checks take or refuse in one line, or raises one
    ConfigError line; nothing else."""
    from dospcot.run.sizes import check_sizes

    try:
        cfg = load()
        check_sizes([cfg])
    except ConfigError as err:
        assert str(err) and "\n" not in str(err), str(err)


@settings(max_examples=400, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(key=st.sampled_from(TRAIN_KEYS), value=VALUES, raw=st.text(max_size=20))
def test_any_set_value_of_any_key_loads_or_is_one_config_error(key, value, raw):
    from dospcot.config.reference import toml_value

    try:
        text = toml_value(value)
    except (TypeError, ValueError):
        text = raw
    for override in (f"{key}={text}", f"{key}={raw}"):
        _one_line_or_config(lambda override=override: load_config("tiny", [override]))


@settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    paper=st.booleans(),
    table=st.dictionaries(st.integers(0, 10**6), VALUES, max_size=6),
    extends=st.sampled_from([None, "tiny", "paper-text", "grid16-reward-model"]),
    prefix=st.sampled_from([b"", b"\xef\xbb\xbf", b"\xff\xfe", b"\x00"]),
)
def test_any_toml_file_of_config_keys_loads_or_is_one_config_error(
    paper, table, extends, prefix, tmp_path_factory
):
    """TOML files that set any keys (of either kind of config) to any values, from any preset or none,
    some starting with a byte-order mark or bytes no UTF-8 text holds."""
    from dospcot.config.reference import toml_value

    keys = PAPER_KEYS if paper else TRAIN_KEYS
    sections: dict[str, list[str]] = {}
    for index, value in table.items():
        key = keys[index % len(keys)]
        section, _, name = key.rpartition(".")
        try:
            sections.setdefault(section, []).append(f"{name} = {toml_value(value)}")
        except (TypeError, ValueError):
            continue
    lines = [f'extends = "{extends}"'] if extends else []
    lines += sections.pop("", [])
    for section, items in sections.items():
        lines += [f"[{section}]", *items]
    path = tmp_path_factory.mktemp("toml") / "c.toml"
    path.write_bytes(prefix + "\n".join(lines).encode("utf-8", "surrogatepass"))
    _one_line_or_config(lambda: load_config(str(path)))
