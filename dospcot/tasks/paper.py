"""The seed paper's protocol (``task = "paper"``, a :class:`~dospcot.config.run_configs.PaperConfig`):
one seed is 26 tabular runs on masked CliffWalking (:mod:`dospcot.paper.protocol`), trained in one
vectorised batch that keeps no checkpoint and no agents. Several seeds train together in one process."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

from tqdm.auto import tqdm

from dospcot.config.run_configs import PaperConfig
from dospcot.experiment.interrupts import Interrupted
from dospcot.experiment.run_folder import METRICS_FILE, RunFolderError
from dospcot.paper.protocol import episodes_per_seed, train_protocol_at
from dospcot.tasks.registry import Task, register

if TYPE_CHECKING:
    from dospcot.experiment.sweep_spec import SweepSpec


@register
class PaperTask(Task):
    """The paper protocol: its runs take seconds, so a killed seed trains again from the start."""

    name = "paper"
    section = "tabular"
    seeds_train_together = True

    def config_type(self) -> type:
        return PaperConfig

    def train_at(self, run_dir: Path, cfg: PaperConfig, *, show_progress: bool, command: str) -> Path:
        with tqdm(
            total=episodes_per_seed(cfg), unit="ep", desc=f"{cfg.name} seed {cfg.seed}",
            disable=not show_progress, mininterval=1.0, dynamic_ncols=True,
        ) as bar:  # fmt: skip
            try:
                train_protocol_at(cfg, {cfg.seed: run_dir}, commands={cfg.seed: command}, progress=bar.update)
            except KeyboardInterrupt:  # a seed keeps no checkpoint: it trains again from the start
                raise Interrupted(
                    f"nothing of seed {cfg.seed}", f"dospcot train --resume {run_dir}"
                ) from None
        return run_dir

    def resume(self, run_dir: Path, cfg: PaperConfig, *, show_progress: bool, command: str) -> Path:
        return self.train_at(run_dir, cfg, show_progress=show_progress, command=command)

    def evaluate(self, run_dir: Path, cfg: PaperConfig) -> dict[str, Any]:
        raise RunFolderError(
            f"{run_dir} is a paper-protocol run: it keeps no agents (its figures are in {METRICS_FILE})"
        )

    def write_report(self, spec: SweepSpec, runs: list[Any], out_dir: Path) -> list[Path]:
        from dospcot.experiment.report import write_paper_report

        return write_paper_report(spec, runs, out_dir)

    def train_seeds_at(  # what seeds_train_together promises
        self,
        cfg: PaperConfig,
        run_dirs: dict[int, Path],
        commands: dict[int, str],
        progress: Callable[[float], None] | None,
    ) -> None:
        episodes = episodes_per_seed(cfg)
        train_protocol_at(
            cfg, run_dirs, commands=commands,
            progress=None if progress is None else lambda done: progress(done / episodes),
        )  # fmt: skip

    def result_line(self, run_dir: Path, summary: dict[str, Any]) -> str:
        mean = summary["mean"]
        return (
            f"{run_dir}: ESARSA-ESARSA DOSPCoT agreement {mean['dospcot_agreement']:.3f}, oracle "
            f"{mean['oracle_agreement']:.3f} (seed {summary['seed']}, {summary['runs']} runs, round "
            f"{summary['rounds']}; every run in metrics.csv)"
        )
