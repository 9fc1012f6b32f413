"""What a sweep is (:mod:`dospcot.sweeps.sweep` runs it): its spec (configs, a grid of values,
seeds, overrides) stored in ``sweep.json``, its trials and their folders, and the checks that a folder
still matches its spec."""

from __future__ import annotations

import hashlib
import json
import re
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field, replace
from itertools import product
from pathlib import Path
from typing import Any, Literal

from dospcot.config.errors import ConfigError
from dospcot.config.loading import parse_override
from dospcot.config.run_configs import RunConfig
from dospcot.config.versions import ADOPTED, FIRST
from dospcot.run.run_folder import CONFIG_FILE, SUMMARY_FILE, write_json
from dospcot.tasks import get_task, load_config, load_run_config

SWEEP_FILE = "sweep.json"
TRIAL_FILE = "trial.json"
SWEEP_FORMAT = 1
NAME_MAX = 255
"""The longest file name, in bytes, that Linux's and macOS's file systems take."""
Backend = Literal["local", "ray"]


class SweepError(ValueError):
    """A sweep that cannot run as asked (bad grid, a folder holding another sweep, failed trials)."""


@dataclass(frozen=True)
class SweepSpec:
    """What a sweep runs: ``configs`` x the product of ``grid`` x ``seeds``.

    :param configs: preset names or paths to ``.toml`` files, as ``dospcot train`` takes them.
    :param grid: config key -> the values it takes, as text (each read as TOML, else as a string).
    :param seeds: the seeds every combination runs with.
    :param overrides: ``key=value`` settings applied to every trial before the grid's.
    :param defaults: the version of the defaults its trials resolve under where a config names none
        (:mod:`dospcot.config.versions`): the adopted version when the sweep was made, so a sweep
        means what it meant after the adopted version moves.
    """

    configs: tuple[str, ...]
    grid: dict[str, tuple[str, ...]] = field(default_factory=dict)
    seeds: tuple[int, ...] = (0,)
    overrides: tuple[str, ...] = ()
    defaults: int = ADOPTED

    def to_dict(self) -> dict[str, Any]:
        """The spec as ``sweep.json`` holds it, with its format number."""
        return {"format": SWEEP_FORMAT, **asdict(self)}  # tuples become JSON lists

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> SweepSpec:
        """The spec that ``sweep.json`` holds; :class:`SweepError` for another format."""
        if data.get("format") != SWEEP_FORMAT:
            raise SweepError(f"{SWEEP_FILE} is not a dospcot sweep of format {SWEEP_FORMAT}")
        return cls(
            tuple(data["configs"]),
            {k: tuple(v) for k, v in data["grid"].items()},
            tuple(data["seeds"]),
            tuple(data["overrides"]),
            data.get("defaults", FIRST),
        )

    def cell_configs(self) -> list[RunConfig]:
        """The config of each config x grid combination (its first seed's), read but not yet through its
        task's check step: what the size checks (:func:`dospcot.run.sizes.check_sizes`) weigh."""
        seed = self.seeds[0] if self.seeds else 0
        return [
            Trial(
                config, "", dict(zip(self.grid, values, strict=True)), seed, self.overrides, self.defaults
            ).load_config()
            for config in self.configs
            for values in product(*self.grid.values())
        ]

    def trials(self, check_task: bool = True) -> list[Trial]:
        """Every trial, each config's checked now so that a bad grid fails before anything runs: its
        fields, and once per combination of grid values its task's check step (files, imports, the env).

        :param check_task: run the task's check step. Off where the trials are only compared with a
            record (:func:`~dospcot_lab.studies.check_record`): a fresh clone's record lacks the files
            a run read, such as the saved expert agent that recorded its demonstrations.
        :raises ConfigError: a combination the config rejects (naming the key).
        """
        keys = list(self.grid)
        trials, kinds = [], set()
        for config in self.configs:
            for values in product(*self.grid.values()):
                params = dict(zip(keys, values, strict=True))
                first: RunConfig | None = None
                for seed in self.seeds:
                    trial = Trial(config, "", params, seed, self.overrides, self.defaults)
                    # A seed moves no other key: the combination resolves once, and each later seed
                    # is checked as a copy that takes it.
                    cfg = trial.load_config() if first is None else replace(first, seed=seed)
                    if first is None and check_task:  # the seed changes nothing the check step reads
                        get_task(cfg.task).check(cfg)
                    first = first or cfg
                    trials.append(replace(trial, name=cfg.name))
                    kinds.add(type(cfg))
        ids = [t.trial_id for t in trials]
        if len(set(ids)) != len(ids):
            raise SweepError("two trials share a folder name: give each config its own `name`")
        if len(kinds) > 1:
            raise SweepError(
                'a sweep runs paper-protocol configs (task = "paper") or train configs, not both: '
                "sweep them apart"
            )
        return trials


@dataclass(frozen=True)
class Trial:
    """One run of a sweep: a config with some grid values and a seed."""

    config: str
    name: str
    params: dict[str, str]
    seed: int
    base_overrides: tuple[str, ...] = ()
    defaults: int = ADOPTED

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> Trial:
        """The trial that its ``trial.json`` holds."""
        return cls(
            data["config"],
            data["name"],
            dict(data["params"]),
            int(data["seed"]),
            tuple(data["base_overrides"]),
            data.get("defaults", FIRST),
        )

    def load_config(self) -> RunConfig:
        """The trial's checked config, under its sweep's version of the defaults."""
        return load_config(self.config, self.overrides(), self.defaults)

    def overrides(self) -> list[str]:
        """The ``--set`` list of this trial: the sweep's overrides, the grid values, the seed."""
        return [*self.base_overrides, *(f"{k}={v}" for k, v in self.params.items()), f"seed={self.seed}"]

    @property
    def trial_id(self) -> str:
        """``<config name>/<key=value>__...__seed=<s>``: the trial's folder under ``trials/``. A folder
        name past :data:`NAME_MAX` bytes, which no file system would take, keeps its start and its seed
        with a digest of its grid values between them, so trials still get a folder each."""
        params = "__".join(f"{key}={_folder_text(value)}" for key, value in self.params.items())
        seed = f"seed={self.seed}"
        folder = f"{params}__{seed}" if params else seed
        if len(folder.encode()) > NAME_MAX:
            digest = hashlib.sha256(params.encode()).hexdigest()[:16]
            tail = f"__{digest}__{seed}"
            folder = params.encode()[: NAME_MAX - len(tail)].decode(errors="ignore") + tail
        return f"{self.name}/{folder}"


def _folder_text(value: str) -> str:
    return re.sub(r"[^\w.+-]", "", value.replace(",", "+"))


def parse_grid(items: Sequence[str]) -> dict[str, tuple[str, ...]]:
    """``["training.label_fraction=0.01,0.1", 'views=["patch"],["rays"]']`` -> key -> values.

    Commas inside brackets or quotes belong to a value, so lists (agent pairs, view sets) can be swept.

    :raises ConfigError: an item without ``=``, without values, or with a key given twice.
    """
    grid: dict[str, tuple[str, ...]] = {}
    for item in items:
        name, _, text = item.partition("=")
        name = name.strip()
        values = tuple(v.strip() for v in _split_top_level(text))
        if not re.fullmatch(r"[A-Za-z_][\w.]*", name) or not text or any(not v for v in values):
            raise ConfigError(
                f"--grid takes key=v1,v2,... (e.g. training.label_fraction=0.05,0.1), got {item!r}"
            )
        if name in grid or name == "seed":
            raise ConfigError(
                f"--grid {name}: " + ("use --seeds for seeds" if name == "seed" else "given twice")
            )
        for value in values:  # each value is TOML or a bare word, as --set's (named as --grid's)
            parse_override(f"{name}={value}", "--grid")
        repeated = sorted({v for v in values if values.count(v) > 1})
        if repeated:
            raise ConfigError(f"--grid {name}: {repeated[0]} is given twice; each value once")
        grid[name] = values
    return grid


def _split_top_level(text: str) -> list[str]:
    parts, depth, quote, start = [], 0, "", 0
    for i, char in enumerate(text):
        if quote:
            quote = "" if char == quote else quote
        elif char in "\"'":
            quote = char
        elif char in "[{":
            depth += 1
        elif char in "]}":
            depth -= 1
        elif char == "," and depth == 0:
            parts.append(text[start:i])
            start = i + 1
    return [*parts, text[start:]]


def seeds_option(seeds: Sequence[int]) -> str:
    """``seeds`` as ``--seeds`` reads them: a range (``100-104``) where they run up one by one, else a
    comma list. A lone seed is a range of one (``--seeds 5`` would be the count, seeds 0-4)."""
    first, last = seeds[0], seeds[-1]
    if list(seeds) == list(range(first, last + 1)):
        return f"{first}-{last}"
    return ",".join(map(str, seeds))


def open_sweep(sweep_dir: Path, spec: SweepSpec | None) -> SweepSpec:
    """Create ``sweep_dir`` for ``spec``, or reopen it (``spec=None`` or the same spec) to resume.

    :raises SweepError: the folder holds a different sweep, or (to resume) no sweep at all.
    """
    path = sweep_dir / SWEEP_FILE
    if path.is_file():
        try:
            stored = SweepSpec.from_dict(json.loads(path.read_text()))
        except (ValueError, KeyError, TypeError) as err:
            raise SweepError(
                f"{path} is damaged ({type(err).__name__}); start the sweep in a new folder"
            ) from None
        if spec is not None and spec != stored:
            if replace(spec, seeds=stored.seeds) == stored and set(stored.seeds) <= set(spec.seeds):
                raise SweepError(
                    f"{sweep_dir} holds another sweep (these configs and grid, with seeds "
                    f"{', '.join(map(str, stored.seeds))}); to add seeds to it: dospcot sweep --resume "
                    f"{sweep_dir} --seeds {seeds_option(spec.seeds)}"
                )
            raise SweepError(
                f"{sweep_dir} holds another sweep ({', '.join(stored.configs)}, grid "
                f"{_grid_text(stored.grid)}, {len(stored.seeds)} seeds); pick another --name or resume "
                f"it with --resume {sweep_dir}"
            )
        return stored
    if spec is None:
        raise SweepError(f"{sweep_dir} is not a sweep folder: it has no {SWEEP_FILE}")
    try:
        sweep_dir.mkdir(parents=True, exist_ok=True)
    except OSError as err:  # a file on the way, or a folder that cannot be created
        raise SweepError(f"cannot make the sweep folder {sweep_dir}: {err.strerror}") from None
    write_json(path, spec.to_dict())
    return spec


def add_seeds(sweep_dir: Path, seeds: Sequence[int]) -> SweepSpec:
    """Give the sweep in ``sweep_dir`` the seeds ``seeds``, a superset of its own, keeping its finished
    trials: its ``sweep.json`` is rewritten, and a resume then runs only the new seeds' trials.

    :raises SweepError: no sweep there, or ``seeds`` lacks some of the sweep's seeds.
    """
    stored = open_sweep(sweep_dir, None)
    dropped = [seed for seed in stored.seeds if seed not in seeds]
    if dropped:
        raise SweepError(
            f"--seeds would drop seed(s) {', '.join(map(str, dropped))} of the sweep in {sweep_dir}: "
            f"give all of its seeds ({', '.join(map(str, stored.seeds))}) and the new ones"
        )
    spec = replace(stored, seeds=tuple(stored.seeds) + tuple(s for s in seeds if s not in stored.seeds))
    batch_seeds = stored_batch_seeds(sweep_dir)
    write_json(sweep_dir / SWEEP_FILE, spec.to_dict())
    store_batch_seeds(sweep_dir, batch_seeds)
    return spec


BATCH_SEEDS = "batch_seeds"
"""The key of ``sweep.json`` that holds the sweep's ``--batch-seeds`` where it is above 1."""


def stored_batch_seeds(sweep_dir: Path) -> int:
    """The ``--batch-seeds`` the sweep in ``sweep_dir`` trains its trials with (1 where not stored)."""
    return int(json.loads((sweep_dir / SWEEP_FILE).read_text()).get(BATCH_SEEDS, 1))


def store_batch_seeds(sweep_dir: Path, batch_seeds: int) -> None:
    """Make ``batch_seeds`` the ``--batch-seeds`` of the sweep in ``sweep_dir`` (kept in ``sweep.json``)."""
    data = json.loads((sweep_dir / SWEEP_FILE).read_text())
    data.pop(BATCH_SEEDS, None)
    write_json(sweep_dir / SWEEP_FILE, data | ({BATCH_SEEDS: batch_seeds} if batch_seeds > 1 else {}))


def _grid_text(grid: dict[str, tuple[str, ...]]) -> str:
    return " ".join(f"{key}={','.join(values)}" for key, values in grid.items()) or "none"


def trial_dir(sweep_dir: Path, trial: Trial) -> Path:
    """The run folder of ``trial`` in the sweep folder."""
    return sweep_dir / "trials" / trial.trial_id


def is_finished(sweep_dir: Path, trial: Trial) -> bool:
    """Whether the trial finished: its folder holds ``summary.json``, which a run writes last."""
    return (trial_dir(sweep_dir, trial) / SUMMARY_FILE).is_file()


def stale_trials(sweep_dir: Path, trials: Sequence[Trial]) -> list[tuple[str, str]]:
    """The trials whose folder holds a config other than the one their config name and overrides
    resolve to now (a preset changed since they ran), each with the first key that differs.

    A sweep folder can outlive its code (the README's studies keep theirs in the repository), and
    without this check a finished trial would be counted, and an unfinished one resumed, under
    settings the sweep no longer means.
    """
    stale = []
    # A combination's trials differ by their seed alone, which moves no other key: each combination is
    # resolved once, where a record's pages would otherwise resolve its configs once per run.
    resolved: dict[tuple[Any, ...], RunConfig] = {}
    for trial in trials:
        path = trial_dir(sweep_dir, trial) / CONFIG_FILE
        if not path.is_file():
            continue
        combination = (trial.config, trial.base_overrides, tuple(trial.params.items()), trial.defaults)
        if combination not in resolved:
            resolved[combination] = trial.load_config()
        stored, current = load_run_config(path), replace(resolved[combination], seed=trial.seed)
        if stored != current:
            old, new = _flat(stored.to_dict()), _flat(current.to_dict())
            key = next(k for k in sorted(old.keys() | new.keys()) if old.get(k) != new.get(k))
            stale.append((trial.trial_id, f"{key} was {old.get(key)!r}, is {new.get(key)!r}"))
    return stale


def check_not_stale(sweep_dir: Path, trials: Sequence[Trial]) -> None:
    """:raises SweepError: one line naming the stale trials' count and the first one's changed key."""
    stale = stale_trials(sweep_dir, trials)
    if stale:
        trial_id, key = stale[0]
        raise SweepError(
            f"{len(stale)} trial(s) in {sweep_dir} were trained with another config than their preset "
            f"and overrides give now (e.g. {trial_id}: {key}); move the sweep folder away, or delete "
            "those trials' folders, to run them again"
        )


def _flat(data: dict[str, Any], prefix: str = "") -> dict[str, Any]:
    flat: dict[str, Any] = {}
    for key, value in data.items():
        if isinstance(value, dict):
            flat |= _flat(value, f"{prefix}{key}.")
        else:
            flat[f"{prefix}{key}"] = value
    return flat
