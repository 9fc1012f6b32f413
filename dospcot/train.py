"""``dospcot train`` and ``dospcot evaluate``: one neural run of a config, with its run folder.

A run writes ``runs/<name>/<stamp>/`` (docs/design.md section 5):

- ``config.toml``: the resolved config (rerun it with ``dospcot train runs/<name>/<stamp>/config.toml``);
- ``tb/agent_<view>/``: TensorBoard events, SB3's ``rollout/`` and ``train/`` scalars plus ``dospcot/``
  scalars per round (pace, eps, lambda, coverage, pseudo-reward accuracy and its worst class,
  classifier loss, greedy return, agreement, ...), against the agent's env steps;
- ``metrics.csv``: one row per round and view; ``summary.json``: the last round, per view and averaged;
- ``agent_<view>.zip`` (loads with plain ``stable_baselines3.DQN.load``; a ``tabular`` agent's where
  dospcot is importable), ``classifier_<view>.pt``
  (:func:`dospcot.classifier.load_classifier`) and ``reward_classes.json`` (class index -> reward);
- ``learning_curves.png``; ``run_info.json`` (command, versions, wall time);
- ``summary.json`` is written last: a folder that has it holds a finished run;
- ``checkpoint.pkl``: the state after the last finished round, for ``dospcot train --resume``;
  removed when the run finishes (a finished run is not resumed).

``metrics.csv``, the agents, the classifiers and the checkpoint are rewritten at the end of every
round, the plot, ``run_info.json`` and ``summary.json`` when the run finishes; every file atomically,
so a killed run resumes from its last finished round and ends with the same ``summary.json`` as an
uninterrupted run. ``dospcot evaluate`` adds ``evaluation.json``.
"""

from __future__ import annotations

import csv
import dataclasses
import math
import shutil
import time
from collections.abc import Callable
from functools import partial
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import stable_baselines3
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.logger import configure
from torch.utils.tensorboard import SummaryWriter
from tqdm.auto import tqdm

from dospcot.classifier import save_classifier
from dospcot.cotraining_round import CoTrainingRun
from dospcot.envs import (
    GridLayout,
    GridWorld,
    grid_views,
    make_masked_gym,
    make_masked_highway,
    monitored_states,
    view_blind_spots,
)
from dospcot.envs.views import View
from dospcot.neural_cotraining import GridTask, MakeEnv, NeuralConfig, NeuralCoTraining, NeuralRunSpec
from dospcot.paper import episodes_per_seed, train_protocol_at
from dospcot.plots import plot_learning_curves
from dospcot.run_folder import (
    CHECKPOINT_FILE,
    CONFIG_FILE,
    METRICS_FILE,
    REWARD_CLASSES_FILE,
    SUMMARY_FILE,
    RunFolderError,
    atomic_write,
    new_run_dir,
    read_checkpoint,
    remove_stale_temporaries,
    source_commit,
    write_checkpoint,
    write_csv,
    write_json,
    write_run_info,
    write_toml,
)
from dospcot.train_config import PaperConfig, TrainConfig, load_config
from dospcot.transition_cotraining import SensorTask, TransitionConfig, TransitionCoTraining

ROUND_SCALARS = (
    "pace", "eps", "lambda", "coverage", "view_coverage", "pseudo_accuracy", "view_pseudo_accuracy",
    "worst_class_recall", "worst_class_precision", "classifier_loss", "greedy_return", "success",
    "normalised_score", "agreement", "labelled_steps",
)  # fmt: skip
"""The per-round, per-view TensorBoard scalars, under ``dospcot/``."""
SEGMENT_SCALARS = ("step_reward_error",)
"""The further per-round scalars of a run on segment labels."""
SUMMARY_METRICS = (
    "normalised_score", "agreement", "greedy_return", "success", "pseudo_accuracy",
    "worst_class_recall", "worst_class_precision", "coverage", "labelled_steps", "step_reward_error",
)  # fmt: skip


def build_task(cfg: TrainConfig) -> tuple[partial[GridWorld], dict[str, View], GridLayout]:
    """The env factory, the views (with the run's blind spots, if any) and the map of a config."""
    env = cfg.env
    layout = GridLayout.random(env.size, env.layout_seed, env.lava_density, env.wall_density)
    make_env = partial(
        GridWorld, layout, step_cost=env.step_cost, lava_penalty=env.lava_penalty,
        goal_reward=env.goal_reward, exploring_starts=env.exploring_starts,
    )  # fmt: skip
    blind = (
        view_blind_spots(layout, env.blind_spot_rate, cfg.seed, identical=env.blind_spots == "identical")
        if env.blind_spot_rate > 0
        else None
    )
    return make_env, grid_views(layout, env.patch_size, env.compass, blind, env.ray_encoding), layout


def agent_kwargs(cfg: TrainConfig) -> dict[str, Any]:
    """The SB3 ``DQN`` arguments of every neural agent of a config."""
    return _capped_buffer(cfg.dqn.sb3_kwargs(), cfg)


def tabular_agent_kwargs(cfg: TrainConfig) -> dict[str, Any]:
    """The :class:`~dospcot.policies.TabularExpectedSarsa` arguments of every tabular agent of a config."""
    return _capped_buffer(dataclasses.asdict(cfg.tabular_agent), cfg)


def _capped_buffer(kwargs: dict[str, Any], cfg: TrainConfig) -> dict[str, Any]:
    # Steps beyond a run's total never enter the buffer: capping it changes nothing but memory and
    # the size of every checkpoint.
    kwargs["buffer_size"] = min(kwargs["buffer_size"], cfg.training.rounds * cfg.training.steps_per_round)
    return kwargs


def _sensor_parts(
    cfg: TrainConfig,
) -> tuple[Callable[..., gym.Env], NeuralRunSpec, TransitionConfig, Callable[..., gym.Env]]:
    """A sensor task's parts (one pool sample per step), a highway's or any gymnasium env's: the
    training env's builder, the run, its hyperparameters and the evaluation env's builder."""
    extra: dict[str, Any] = {}
    if cfg.task == "highway":
        task = cfg.highway
        make_env = make_eval_env = partial(
            make_masked_highway, task.env_id, config=task.config, reveal_first_steps=task.reveal_first_steps
        )
    else:
        task = cfg.gym
        make_eval_env = partial(
            make_masked_gym,
            task.env_id,
            view_specs=task.views,
            env_kwargs=task.env_kwargs,
            wrappers=task.wrappers,
            state_key=task.state_key,
        )
        make_env = partial(make_eval_env, train_wrappers=task.train_wrappers)
        extra = {
            "success_return": task.success_return,
            "max_return": task.max_return,
            "keyed": bool(task.state_key),
            "read_termination": task.read_termination,
            "episode_end_classes": task.episode_end_classes,
        }
    config = TransitionConfig(
        **_common_kwargs(cfg), max_episode_steps=task.episode_steps, reward_classes=task.reward_classes,
        eval_episodes=task.eval_episodes, **extra,
    )  # fmt: skip
    return make_env, _spec(cfg), config, make_eval_env


def _grid_parts(
    cfg: TrainConfig,
) -> tuple[MakeEnv, dict[str, View], NeuralRunSpec, NeuralConfig, np.ndarray | None]:
    make_env, views, layout = build_task(cfg)
    config = NeuralConfig(
        **_common_kwargs(cfg), max_episode_steps=cfg.env.episode_steps,
        train_episode_steps=cfg.env.train_episode_steps,
    )  # fmt: skip
    columns = cfg.env.monitored_columns
    return make_env, views, _spec(cfg), config, monitored_states(layout.size, columns) if columns else None


def _common_kwargs(cfg: TrainConfig) -> dict[str, Any]:
    return {
        **dataclasses.asdict(cfg.training),
        "dqn": agent_kwargs(cfg), "tabular": tabular_agent_kwargs(cfg), "cotraining": cfg.cotraining,
        "demonstrations": cfg.demonstrations,
    }  # fmt: skip


def _spec(cfg: TrainConfig) -> NeuralRunSpec:
    return NeuralRunSpec(cfg.method, cfg.agent_kinds, cfg.views, gamma=cfg.cotraining.gamma, seed=cfg.seed)


def build_run(cfg: TrainConfig) -> CoTrainingRun:
    """The co-trainer of a config, before its first round: the grid adapter's on a grid
    (:class:`~dospcot.neural_cotraining.NeuralCoTraining`), the sensor adapter's on a highway or any
    gymnasium env (:class:`~dospcot.transition_cotraining.TransitionCoTraining`)."""
    if cfg.task == "grid":
        return NeuralCoTraining(*_grid_parts(cfg))
    return TransitionCoTraining(*_sensor_parts(cfg))


class _StepBar(BaseCallback):
    """Advance a tqdm bar by every env step an agent takes."""

    def __init__(self, bar: tqdm) -> None:
        super().__init__()
        self.bar = bar

    def _on_step(self) -> bool:
        self.bar.update(1)
        return True


def train(
    cfg: TrainConfig | PaperConfig,
    runs_root: Path = Path("runs"),
    *,
    show_progress: bool = True,
    command: str = "",
) -> Path:
    """Train ``cfg`` in a new folder ``runs_root/<name>/<stamp>/``; return that folder."""
    return train_at(new_run_dir(runs_root, cfg.name), cfg, show_progress=show_progress, command=command)


def train_at(
    run_dir: Path, cfg: TrainConfig | PaperConfig, *, show_progress: bool = True, command: str = ""
) -> Path:
    """Train ``cfg`` in ``run_dir`` (created if missing, as ``dospcot sweep`` names its trials)."""
    run_dir.mkdir(parents=True, exist_ok=True)
    if isinstance(cfg, PaperConfig):  # writes its own config.toml, as a batch of seeds does
        return _train_paper(run_dir, cfg, show_progress, command)
    write_toml(run_dir / CONFIG_FILE, cfg.to_dict())
    return _train_in(run_dir, cfg, None, show_progress, command)


def _train_paper(run_dir: Path, cfg: PaperConfig, show_progress: bool, command: str) -> Path:
    """One seed of the paper protocol, in one go: its tabular runs take seconds and keep no checkpoint."""
    with tqdm(
        total=episodes_per_seed(cfg), unit="ep", desc=f"{cfg.name} seed {cfg.seed}",
        disable=not show_progress, mininterval=1.0, dynamic_ncols=True,
    ) as bar:  # fmt: skip
        train_protocol_at(cfg, {cfg.seed: run_dir}, commands={cfg.seed: command}, progress=bar.update)
    return run_dir


def resume(run_dir: Path, *, show_progress: bool = True, command: str = "") -> Path:
    """Continue a killed run from the checkpoint of its last finished round, or from the start if it
    finished none (a paper-protocol run always starts again: it keeps no checkpoint)."""
    cfg = _run_config(run_dir)
    if (run_dir / SUMMARY_FILE).is_file():  # resuming it would train past its last round
        raise RunFolderError(
            f"{run_dir} is a finished run (it has {SUMMARY_FILE}): nothing to resume; to train its "
            f"config again: dospcot train {run_dir / CONFIG_FILE}"
        )
    remove_stale_temporaries(run_dir)
    if isinstance(cfg, PaperConfig):
        return _train_paper(run_dir, cfg, show_progress, command)
    if not (run_dir / CHECKPOINT_FILE).is_file():
        # Killed in its first round: only the config is worth keeping, and old events would repeat.
        shutil.rmtree(run_dir / "tb", ignore_errors=True)
        return _train_in(run_dir, cfg, None, show_progress, command)
    return _train_in(run_dir, cfg, read_checkpoint(run_dir), show_progress, command)


def _run_config(run_dir: Path) -> TrainConfig | PaperConfig:
    config_path = run_dir / CONFIG_FILE
    if not config_path.is_file():
        raise RunFolderError(f"{run_dir} is not a run folder: it has no {CONFIG_FILE}")
    return load_config(str(config_path))


def _train_in(
    run_dir: Path, cfg: TrainConfig, state: dict[str, Any] | None, show_progress: bool, command: str
) -> Path:
    started, started_cpu = time.perf_counter(), time.process_time()
    run = build_run(cfg)
    records: list[dict] = []
    elapsed, cpu, sessions, commits = 0.0, 0.0, 1, [source_commit()]
    if state is not None:
        run.load_state_dict(state["run"])
        records, elapsed, sessions = state["records"], state["elapsed_s"], state["sessions"] + 1
        cpu = state.get("cpu_s", float("nan"))  # a checkpoint older than this field: unknown
        # A resumed run may have been trained by other code before: each session's commit is kept (a
        # checkpoint older than this field names none for its sessions).
        commits = state.get("commits", [None] * (sessions - 1)) + commits
    for agent, view in zip(run.agents, cfg.views, strict=True):
        folder = str(run_dir / "tb" / f"agent_{view}")
        if state is not None:
            # The killed session logged part of the round resumed now: TensorBoard drops every event
            # from this step on in the files before this marker, so each step appears once.
            SummaryWriter(folder, purge_step=agent.num_timesteps).close()
        agent.set_logger(configure(folder, ["tensorboard"]))
    per_round = cfg.training.steps_per_round * len(run.agents)
    bar = tqdm(
        total=cfg.training.rounds * per_round, initial=run.round * per_round, unit="step",
        desc=f"{cfg.name} round {run.round + 1}/{cfg.training.rounds}", disable=not show_progress,
        dynamic_ncols=True,
    )  # fmt: skip
    while run.round < cfg.training.rounds and not run.stopped:
        bar.set_description(f"{cfg.name} round {run.round + 1}/{cfg.training.rounds}")
        rows = run.run_round(callback=_StepBar(bar))
        records += rows
        _log_round(run, rows)
        score = np.mean([r["normalised_score"] for r in rows])
        bar.set_postfix(score=f"{score:.2f}", pace=f"{rows[0]['pace']:.2f}")
        _write_round_files(run_dir, run, cfg, records)
        write_checkpoint(
            run_dir,
            {
                "run": run.state_dict(),
                "records": records,
                "elapsed_s": elapsed + time.perf_counter() - started,
                "cpu_s": cpu + time.process_time() - started_cpu,
                "sessions": sessions,
                "commits": commits,
            },
        )
    bar.close()
    for agent in run.agents:
        agent.logger.close()
    plot_learning_curves(records, run_dir / "learning_curves.png", title=f"{cfg.name} (seed {cfg.seed})")
    resumed = {"session_commits": commits} if sessions > 1 else {}
    cpu += time.process_time() - started_cpu
    times = {} if np.isnan(cpu) else {"cpu_time_s": round(cpu, 2)}  # NaN: a session's CPU time unknown
    write_run_info(
        run_dir, command, elapsed + time.perf_counter() - started, sessions=sessions, **times, **resumed
    )
    # Last, so that its presence marks a finished run (``dospcot sweep`` skips those on resume).
    write_json(run_dir / SUMMARY_FILE, run_summary(records, run))
    # A finished run is never resumed, and its checkpoint holds every replay buffer (about a GB on
    # a 32 x 32 grid): a sweep of finished runs would fill a disk.
    (run_dir / CHECKPOINT_FILE).unlink(missing_ok=True)
    return run_dir


def _log_round(run: CoTrainingRun, rows: list[dict]) -> None:
    for agent, row in zip(run.agents, rows, strict=True):
        for key in (*ROUND_SCALARS, *SEGMENT_SCALARS):
            if math.isfinite(row[key]):
                agent.logger.record(f"dospcot/{key}", row[key])
        agent.logger.record("dospcot/round", run.round)
        agent.logger.dump(step=agent.num_timesteps)


def _write_round_files(run_dir: Path, run: CoTrainingRun, cfg: TrainConfig, records: list[dict]) -> None:
    write_csv(run_dir / METRICS_FILE, records)
    for agent, view in zip(run.agents, cfg.views, strict=True):
        atomic_write(run_dir / f"agent_{view}.zip", agent.save)
    if run.trainer is not None:
        for clf, view in zip(run.trainer.classifiers, cfg.views, strict=True):
            atomic_write(run_dir / f"classifier_{view}.pt", partial(save_classifier, clf))
        rewards = run.classes.values[0][run.classes.mask[0]]
        write_json(run_dir / REWARD_CLASSES_FILE, {"rewards": [float(v) for v in rewards]})


def run_summary(records: list[dict], run: CoTrainingRun) -> dict[str, Any]:
    """The last round's metrics per view and averaged over the views (no timings: a resumed run
    ends with the summary of the uninterrupted one)."""
    last = [r for r in records if r["round"] == run.round]
    return {
        "method": run.spec.method,
        "views": list(run.spec.views),
        "agents": list(run.spec.agents),
        "m": len(run.spec.views),
        "seed": run.spec.seed,
        "rounds": run.round,
        "stopped_early": run.stopped,
        "env_steps_per_agent": int(last[0]["env_steps"]),
        **run.reference_returns(),
        "mean": {key: float(np.mean([r[key] for r in last])) for key in SUMMARY_METRICS},
        "per_view": {r["view"]: {key: r[key] for key in (*SUMMARY_METRICS, "eps", "pace")} for r in last},
    }


def evaluate(run_dir: Path) -> dict[str, Any]:
    """Re-evaluate a run's saved agents (loaded with plain ``stable_baselines3.DQN.load``) on its task.

    :return: per view and averaged: greedy return, success, normalised score and agreement.
    """
    cfg = _run_config(run_dir)
    if isinstance(cfg, PaperConfig):
        raise RunFolderError(
            f"{run_dir} is a paper-protocol run: it keeps no agents (its figures are in {METRICS_FILE})"
        )
    agents = [_load_agent(run_dir, f"agent_{v}.zip") for v in cfg.views]
    # The task adapter's evaluator, as during training: no training run, no fresh agents.
    task = GridTask(*_grid_parts(cfg)) if cfg.task == "grid" else SensorTask(*_sensor_parts(cfg))
    policy = task.evaluate(agents)
    per_view = {v: {key: float(value[k]) for key, value in policy.items()} for k, v in enumerate(cfg.views)}
    result = {"per_view": per_view, "mean": {key: float(np.mean(value)) for key, value in policy.items()}}
    write_json(run_dir / "evaluation.json", result)
    return result


def _load_agent(run_dir: Path, name: str) -> stable_baselines3.DQN:
    path = run_dir / name
    if not path.is_file():
        if not (run_dir / METRICS_FILE).is_file():
            raise RunFolderError(f"{path} does not exist: the run finished no round")
        with (run_dir / METRICS_FILE).open() as rows:
            rounds = max(int(row["round"]) for row in csv.DictReader(rows))
        raise RunFolderError(
            f"{path} is missing, though the run finished {rounds} round(s): the folder is incomplete"
        )
    try:
        return stable_baselines3.DQN.load(path, device="cpu")
    except Exception as err:  # zipfile, pickle and torch raise many types for a damaged file
        raise RunFolderError(f"{path} is not a readable SB3 agent ({type(err).__name__}: {err})") from None
