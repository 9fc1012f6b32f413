"""``dospcot-lab bench``: performance claims measured against a peer in the same run, written to
BENCHMARKS.md by this module (never by hand).

Every row reports our figure and the peer's, each the median of its repetitions with its min and
max, their ratio, the target, and how the row was made: the benchmark that measured it, its
repetitions, when, the commit and the CPU (:class:`~dospcot_lab.bench_measure.Provenance`).
Repetitions of ours and the peer alternate, so drift in the machine's speed hits both alike.
"""

from __future__ import annotations

import dataclasses
import fcntl
import platform
from collections.abc import Callable, Sequence
from datetime import UTC, datetime
from functools import partial
from pathlib import Path

import torch
from tqdm.auto import tqdm

from dospcot.run.interrupts import Interrupted
from dospcot.run.run_folder import cpu_description
from dospcot_lab.bench_agents import bench_ego_gradient_step
from dospcot_lab.bench_batched import (
    bench_batched_memory,
    bench_batched_seeds,
    bench_batched_wall,
    bench_stacked_update,
)
from dospcot_lab.bench_cost import COST_TASKS, bench_cost, bench_release
from dospcot_lab.bench_env_rows import (
    bench_cotraining_scaling,
    bench_fast_highway,
    bench_minigrid_wrappers,
    bench_store_memory,
)
from dospcot_lab.bench_measure import NOT_RECORDED, Provenance, Row, short_commit
from dospcot_lab.bench_rows import (
    bench_cotraining_overhead,
    bench_esarsa_dqn,
    bench_sweep_throughput,
    bench_tabular,
)


def _esarsa_dqn(net: list[int], batch: int, **options: str) -> Callable[[bool, int], Row]:
    """The ExpectedSarsaDQN-against-DQN row at ``net`` and ``batch`` (``options``: target, greedy, device)."""
    return lambda quick, repeats: bench_esarsa_dqn(3_000 if quick else 20_000, repeats, net, batch, **options)


BENCHMARKS: dict[str, Callable[[bool, int], Row]] = {
    "tabular": bench_tabular,
    # SB3's defaults: a small network, where the fixed per-update cost of the extra target ops shows most.
    "esarsa_dqn": _esarsa_dqn([64, 64], 32),
    "esarsa_dqn_wide": _esarsa_dqn([256, 256], 256),
    # The option the default trades away: pi_eps around the online network's greedy action.
    "esarsa_dqn_online_wide": _esarsa_dqn([256, 256], 256, greedy="online"),
    # The same agent with SB3's max target: what relabelling and weighting alone cost.
    "esarsa_dqn_q_target": _esarsa_dqn([256, 256], 256, target="q"),
    "cotraining_overhead": bench_cotraining_overhead,
    "sweep_throughput": bench_sweep_throughput,
    "store_memory": bench_store_memory,
    "cotraining_scaling": bench_cotraining_scaling,
    "fast_highway": bench_fast_highway,
    "minigrid_wrappers": bench_minigrid_wrappers,
    "stacked_update": bench_stacked_update,
    "batched_seeds": bench_batched_seeds,
    "batched_seeds_grid32": lambda quick, repeats: bench_batched_seeds(quick, repeats, "grid32-dospcot", 0.4),
    "batched_seeds_fasthighway": lambda quick, repeats: bench_batched_seeds(
        quick, repeats, "fasthighway-dospcot", 0.25
    ),
    "batched_wall": bench_batched_wall,
    "batched_memory": bench_batched_memory,
    **{f"cost_{task}": partial(bench_cost, task) for task in COST_TASKS},
    **{f"release_{task}": partial(bench_release, task) for task in COST_TASKS},
    "release_memory": partial(bench_release, "lavagap", memory=True),
    "ego_gradient_step": bench_ego_gradient_step,
}

GPU_BENCHMARKS: dict[str, Callable[[bool, int], Row]] = {
    "esarsa_dqn": _esarsa_dqn([64, 64], 32, device="cuda"),
    "esarsa_dqn_wide": _esarsa_dqn([256, 256], 256, device="cuda"),
    "stacked_update": lambda quick, repeats: bench_stacked_update(quick, repeats, device="cuda"),
    "batched_seeds": lambda quick, repeats: bench_batched_seeds(quick, repeats, device="cuda"),
}
"""The rows ``dospcot-lab bench --device cuda`` measures on a GPU, into the GPU column of the row of the same
benchmark and setting: both sides on the GPU, in wall time."""

NOTES = [
    "Notes:",
    "- The tabular row times the collection phase of the paper protocol (each agent's epsilon-greedy "
    "episodes with an online weighted TD update per step) inside full co-training runs. Ours steps every "
    "agent of every run at once in numpy; the reference (`PerStepTabularCoTraining` in "
    "`lab/bench.py`) "
    "loops over agents and steps in Python with the same update and random streams, and ends with the "
    "same Q-tables (`tests/test_tabular.py`). The loop's cost per step does not depend on how many runs "
    "follow, so it is timed on one seed's runs; ours gains from batching, so it runs the protocol's "
    "seeds together, as `dospcot reproduce-paper` does in each worker.",
    "- ExpectedSarsaDQN's Expected-SARSA target takes pi_eps around the target network's greedy action "
    "at s' by default (`greedy='target'`): it reads only the target network's values, which DQN's max "
    "target computes anyway, so it costs no forward pass more than DQN. `greedy='online'` picks the "
    "greedy action with the online network, as Double DQN does; even as one online forward over s and "
    "s' together it costs a wider forward and backward per gradient step, which the `greedy='online'` "
    "row measures (the trade is written up in the `ExpectedSarsaDQN` docstring). The `target='q'` row "
    "runs the same agent with DQN's max target, so it shows what relabelling and self-paced weighting cost.",
    "- The ExpectedSarsaDQN rows count env steps per second of the process's CPU time "
    "(`time.process_time`, on one torch thread), not of wall time: on a shared machine the wall clock also "
    "runs while other tenants hold the core (a virtual machine's steal time), which moved the [64, 64] "
    "row's ratio between 0.82 and 1.08 from one rerun to the next on this 2-core machine. On a machine of "
    "one's own the two agree.",
    "- The co-training overhead row times `CoTrainingRun.run()` (learning, the shared store, one "
    "classifier fit and scoring per view and round, relabelling and the per-round evaluation) against "
    "each agent's `learn()` over the same steps without a co-trainer, summed over the agents; the peer "
    "also takes no gradient step before the preset's `training.learn_from_round`.",
    "- The sweep row runs the same trials in fresh sweep folders with a pool of 2 worker processes and "
    "of 1 (each on one torch thread), timing the whole `run_sweep` call, worker start-up included; the "
    "ratio is the speed-up on this machine's cores.",
    "- The highway row steps 64 of our envs at once in numpy (`dospcot.envs.FastHighwayVec`; ended envs "
    "reset inside `step`) and one highway-fast-v0 env in its Python simulator, both with uniformly random "
    "meta-actions and their default Kinematics observation; the ratio counts env steps of all 64 envs.",
    "- The store rows fill a `grid16-dospcot` co-trainer's shared store with random steps. On a grid the "
    "store keeps per-key arrays only (the pool is deduplicated by (s, a) key, each view's features are "
    "computed per key when the classifiers need them, and the reward table is indexed by key), so its "
    "size does not grow with the steps; the steps themselves live in the agents' SB3 replay buffers. "
    "The peer is the raw arrays a store of observations would hold. The scaling row times `cotrain()` "
    "(classes, features, select, fit, score, Eq. 9, writing the table) at each size; the peer "
    "column is the n log n growth over the same sizes, so a ratio at most 1 means no faster growth.",
    "- The batched-seeds CPU-time rows train the same seeds of a shortened preset (two rounds) as one "
    "batch (`dospcot.core.batched_runs.BatchedRuns`, one process) and as runs of their own one after "
    "another (the same process), counting the process's CPU time per seed, run set-up included. The "
    "targets (4x for grid16 and the fast highway, 2.5x for grid32) are the batched-seeds aims; the batch "
    "shares the networks' arithmetic, not the classifiers' fits or the envs' steps, which "
    "docs/batched_seeds.md measures as what limits the ratio.",
    "- The batched wall-time row runs `dospcot sweep --workers 2` over the same cell twice in fresh "
    "folders: once with `--batch-seeds K` (two processes, a batch of K seeds each) and once with every "
    "run alone, process start-up included; it needs both cores to itself.",
    "- The batched memory row trains in a fresh process each (spawned): a batch of the cell's seeds, "
    "and one run of seed 0. Each figure is the peak resident memory the training adds to a process that "
    "has already imported the package (Linux's `VmHWM`, its peak reset after the imports, less the "
    "`VmRSS` then), divided by the seeds it trained.",
    "- The stacked-update row takes the gradient steps of 10 ExpectedSarsaDQN members (seeds 0-9, each "
    "with its own replay buffer of random steps) as one stacked step of all members "
    "(`dospcot.policies.stacked_esarsa.StackedExpectedSarsa`, as a batch of seeds takes them) and as each "
    "member's own `train()`, one member after another; it isolates what stacking saves per update, "
    "without the envs and classifiers of the batched-seeds rows.",
    "- The cost rows (`cost_TASK`, `release_TASK`, `release_memory`) train whole `dospcot train` runs, each "
    "a subprocess on one torch thread, at the preset's full length over seeds 0-2 (the seeds are the "
    "repetitions), and read each run's CPU time (user + system) and peak resident memory from `os.wait4`: "
    "the interpreter's start and imports count, as in a user's run. A cost row's peer is the DOSPCoT "
    "run's agents trained alone: per seed, the sum of the preset's self-training run on each of the "
    "DOSPCoT preset's views (`views = [VIEW]`), so the ratio is what co-training adds to its agents' own "
    "cost. The last release (the peer of the "
    "release rows) runs from commit 700346f's source installed into the user's cache (`pip install "
    "--target`); a run serves every row that needs it, so a task's rows cost one set of runs.",
    "- The GPU column holds the rows that have a GPU form, measured by `dospcot-lab bench --device cuda` on "
    "the machine its line above the table names: ours and the peer both on the GPU (`dqn.device = "
    "'cuda'` for the batched-seeds row, whose classifiers and envs stay on the CPU), in wall time, since "
    "the CPU only queues a GPU's work; the cell gives the ratio, whether it meets the row's target, and "
    "the two medians. A dash: not measured on a GPU.",
]


TABLE_HEADER = (
    "| benchmark | setting | ours | peer | ratio | target | met | made by | GPU: ratio, met (ours vs peer) |"
)
SEPARATOR = "|---|---|---|---|---|---|---|---|---|"
WITHOUT_PROVENANCE = (
    "| benchmark | setting | ours | peer | ratio | target | met | GPU: ratio, met (ours vs peer) |"
)
"""The header of a table written before rows carried their provenance: a rerun gives it the *made by*
column, each old row's cell not recorded."""
WITHOUT_GPU = "| benchmark | setting | ours | peer | ratio | target | met |"
"""The header of a table written before the GPU column, which a rerun gives the column."""
FIGURES = (
    "Each figure: the median of its row's repetitions [min, max]; ours and the peer alternate in the same "
    "run. A row's *made by* cell says how it was made: the benchmark (`dospcot-lab bench --only NAME` "
    "measures it again), its repetitions, when (UTC), the commit of the source that measured it (`+dirty`: "
    "with uncommitted changes) and the CPU with torch's kernels."
)
"""The line above the table that says what a figure is; it replaces a file's older line (which claimed
one repetition count for every row) whenever the file is written."""
RECOVERED = "that wrote the row"
"""How the *made by* cell of a row written before rows carried their provenance names the commit it was
recovered from: the one that wrote the row into BENCHMARKS.md (``git log -- BENCHMARKS.md``)."""
RECOVERED_NOTE = "Provenance recovered:"
"""The paragraph above the table that says how such rows' provenance was recovered; a rerun drops it
once no row of the table is one of them."""
RERUN_NOTE = "Rerun alone by"
GPU_NOTE = "GPU column by"
NO_FIGURE = "–"


def _cells(line: str) -> list[str]:
    return [cell.strip() for cell in line.strip().strip("|").split(" | ")]


def _gpu_cell(row: Row) -> str:
    return f"{row.ratio:.3f}, {'yes' if row.met else 'no'} ({row.ours.brief} vs {row.peer.brief})"


def _target(row: Row) -> str:
    return f"{'>=' if row.higher_is_better else '<='} {row.target_text}"


def _table_line(row: Row, gpu: str = NO_FIGURE) -> str:
    made = row.made or Provenance.unknown()
    return (
        f"| {row.name} | {row.setting} | {row.ours} | {row.peer} | {row.ratio:.3f} | "
        f"{_target(row)} | {'yes' if row.met else 'no'} | {made} | {gpu} |"
    )


def _row_at(lines: list[str], row: Row) -> int | None:
    """The index of ``row``'s line in ``lines``: the same benchmark name and setting; None if none."""
    key = f"| {row.name} | {row.setting} |"
    return next((i for i, line in enumerate(lines) if line.startswith(key)), None)


def _after_table(lines: list[str]) -> int:
    """The index just past the table's last row: where a row the table lacks goes."""
    return max(i for i, line in enumerate(lines) if line.startswith("| ")) + 1


def render(rows: list[Row], command: str, kept: str = "") -> str:
    """The text of BENCHMARKS.md: its header, the table of ``rows`` (each with its *made by* cell) and
    the notes.

    :param kept: the file a full run replaces: its GPU figures and notes stay, where a row's benchmark
        and setting are unchanged (they were measured on another machine, which this run does not use).
    """
    lines = [
        "# Benchmarks",
        "",
        f"Written by `{command}` on {datetime.now(UTC):%Y-%m-%d %H:%M} UTC.  ",
        f"Machine: {cpu_description()} ({platform.machine()}), torch threads: {torch.get_num_threads()}, "
        f"Python {platform.python_version()}, torch {torch.__version__}; no GPU.  ",
        FIGURES,
    ]
    old = _table_lines(kept) if any(h in kept for h in (TABLE_HEADER, WITHOUT_PROVENANCE)) else []
    gpu = {tuple(_cells(line)[:2]): _cells(line)[-1] for line in old if line.startswith("| ")}
    lines += [part for line in old if line.startswith(GPU_NOTE) for part in ("", line)]
    lines += ["", TABLE_HEADER, SEPARATOR]
    lines += [_table_line(row, gpu.get((row.name, row.setting), NO_FIGURE)) for row in rows]
    lines += ["", *NOTES]
    return "\n".join(lines) + "\n"


def run_benchmarks(
    out: Path, quick: bool, repeats: int, command: str, only: Sequence[str] = (), device: str = "cpu"
) -> list[Row]:
    """Run every benchmark and write ``out`` (on one torch thread, as ``dospcot train`` runs).

    :param only: run these benchmarks (names of :data:`BENCHMARKS`) alone and put their rows into
        ``out``, a file a full run wrote: each replaces its row of the same benchmark and setting
        (or the benchmark's only row, whose setting has changed), or goes last, and a line above the
        table names them, the command and the time. Every row is written as it lands; a full run
        then writes the file whole.
    :param device: ``"cuda"``: run :data:`GPU_BENCHMARKS` (those of ``only``, or all) on the GPU and
        write their figures into the GPU column of ``out``'s rows of the same benchmark and setting,
        leaving the rest of each row as it was; a line above the table names the GPU and the rows.
    :raises ValueError: ``only`` names an unknown benchmark (or one without a GPU form, on a GPU),
        ``out`` holds no benchmark table where one is needed, or torch sees no GPU for ``device``.
    """
    catalogue = BENCHMARKS if device == "cpu" else GPU_BENCHMARKS
    unknown = [name for name in only if name not in catalogue]
    if unknown:
        what = "benchmark(s)" if device == "cpu" else f"benchmark(s) on {device}"
        raise ValueError(f"unknown {what} {unknown}; allowed: {', '.join(catalogue)}")
    if device != "cpu" and not torch.cuda.is_available():
        raise ValueError(f"--device {device}: torch {torch.__version__} sees no CUDA device")
    # Each row goes into the file as it lands, so that a stop or a failing row an hour in keeps the
    # rows before it: merged into the table already there, or, where there is none, a table of its own.
    text = out.read_text() if out.is_file() else ""
    table = text if any(h in text for h in (TABLE_HEADER, WITHOUT_PROVENANCE, WITHOUT_GPU)) else None
    if (only or device != "cpu") and table is None:
        raise ValueError(
            f"--only and --device update the table of a file a full `dospcot-lab bench` wrote; {out} holds "
            "none"
        )
    try:  # before the rows, which take most of an hour, not after
        out.parent.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise ValueError(f"--out {out}: cannot make its folder ({err.strerror or err})") from None
    torch.set_num_threads(1)
    # The source's commit as the run starts: a row landing in a tracked --out (BENCHMARKS.md), this
    # run's or another's, leaves the checkout dirty for the rows after it, with the source unchanged.
    commit = short_commit()
    rows: list[Row] = []
    chosen = {name: catalogue[name] for name in only} if only else catalogue
    with tqdm(chosen.items(), desc="dospcot-lab bench", unit="row", dynamic_ncols=True) as bar:
        for name, bench in bar:
            bar.set_postfix_str(name)
            try:
                row = bench(quick, repeats)
            except KeyboardInterrupt:
                done = ", ".join(row.name for row in rows)
                raise Interrupted(
                    f"the rows measured before the stop, in {out}: {done}" if rows else "nothing"
                ) from None
            rows.append(dataclasses.replace(row, made=Provenance.now(name, row, commit)))
            names = list(chosen)[: len(rows)]
            if device != "cpu":
                _landed(out, lambda now: _with_gpu_rows(now, rows, names, command, repeats, commit))  # noqa: B023
            elif table is None:
                out.write_text(render(rows, command))
            else:
                _landed(out, lambda now: _with_rows(now, rows, names, command))  # noqa: B023
    if not only and device == "cpu":  # a full run's rows are the whole table
        out.write_text(render(rows, command, text))
    return rows


def _table_lines(text: str) -> list[str]:
    """``text``'s lines in today's form: a table written before the GPU column given it (no figure in
    it yet), one written before rows carried their provenance given the *made by* column (each old
    row's cell not recorded), and the line that says what a figure is, today's (:data:`FIGURES`)."""
    lines = text.splitlines()
    if WITHOUT_GPU in lines:
        at = lines.index(WITHOUT_GPU)
        lines[at : at + 2] = [WITHOUT_PROVENANCE, "|---|---|---|---|---|---|---|---|"]
        lines = [
            f"{line} {NO_FIGURE} |" if line.startswith("| ") and i > at + 1 else line
            for i, line in enumerate(lines)
        ]
    if WITHOUT_PROVENANCE in lines:
        at = lines.index(WITHOUT_PROVENANCE)
        lines[at : at + 2] = [TABLE_HEADER, SEPARATOR]
        for i in range(at + 2, len(lines)):
            if lines[i].startswith("| "):
                cells = _cells(lines[i])
                lines[i] = "| " + " | ".join([*cells[:-1], str(Provenance.unknown()), cells[-1]]) + " |"
    return [FIGURES if line.startswith("Each figure:") else line for line in lines]


def _drop_superseded(lines: list[str], prefix: str, rerun: set[str]) -> None:
    """Delete the notes starting ``prefix`` whose benchmarks are all in ``rerun`` (rewritten now).

    A note names benchmarks (:data:`BENCHMARKS`' keys), not rows: two rows can share a name (the
    ExpectedSarsaDQN rows differ in their setting alone), and a rerun of one must keep the other's note.
    """
    for i in reversed(range(len(lines))):
        if lines[i].startswith(prefix) and set(lines[i].split(" UTC: ", 1)[1][:-1].split("; ")) <= rerun:
            del lines[i - 1 : i + 1]  # the note and the blank line above it


def _add_note(lines: list[str], note: str) -> None:
    """``note`` as a paragraph of its own above the table; the code's notes below it."""
    if "Notes:" in lines:  # the notes say how rows are measured: the code's are the current ones
        lines[lines.index("Notes:") :] = NOTES
    header = lines.index(TABLE_HEADER)
    lines[header - 1 : header - 1] = ["", note]


def _old_row(lines: list[str], row: Row, rows: list[Row]) -> int | None:
    """The index of the row that ``row`` replaces where its setting changed: the one row of its name
    that its benchmark wrote (by the *made by* cell), or, where none did, the one row of its name
    written before rows carried their provenance, unless another row of this run (``rows``) shares
    the name and might be the one it describes. Rows of one name from other benchmarks (the cost rows,
    one per task) are never its. None: no such row."""
    own, unknown = [], []
    for i, line in enumerate(lines):
        if line.startswith(f"| {row.name} | "):
            try:
                bench = Provenance.parse(_cells(line)[-2]).bench
            except ValueError:
                bench = NOT_RECORDED
            if bench == NOT_RECORDED:
                unknown.append(i)
            elif row.made is not None and bench == row.made.bench:
                own.append(i)
    if own:
        return own[0] if len(own) == 1 else None
    alone = [r.name for r in rows].count(row.name) == 1
    return unknown[0] if len(unknown) == 1 and alone else None


def _landed(out: Path, update: Callable[[str], str]) -> None:
    """Write ``update`` of ``out``'s text as it reads now, holding a lock on the file meanwhile: two
    ``--only`` runs into one file (each on its own core) keep each other's rows."""
    with out.open("r+") as handle:
        fcntl.flock(handle, fcntl.LOCK_EX)  # released as the file closes
        text = update(handle.read())
        handle.seek(0)
        handle.write(text)
        handle.truncate()


def _with_rows(text: str, rows: list[Row], names: list[str], command: str) -> str:
    """``text`` (a BENCHMARKS.md) with ``rows`` (of the benchmarks ``names``) in its table and a line
    saying when they were rerun; each row keeps its GPU figure."""
    lines = _table_lines(text)
    for row in rows:
        at = _row_at(lines, row)
        same = at is not None  # only then does the old GPU figure describe this row
        if at is None:  # the benchmark's setting changed: its one old row describes it no more
            at = _old_row(lines, row, rows)
        if at is None:  # a new row
            at = _after_table(lines)
            lines.insert(at, _table_line(row))
        else:
            lines[at] = _table_line(row, _cells(lines[at])[-1] if same else NO_FIGURE)
    _drop_superseded(lines, RERUN_NOTE, set(names))
    if not any(line.startswith("| ") and RECOVERED in line for line in lines):
        for i in reversed(range(len(lines))):
            if lines[i].startswith(RECOVERED_NOTE):
                del lines[i - 1 : i + 1]  # the paragraph and the blank line above it
    _add_note(
        lines, f"{RERUN_NOTE} `{command}` on {datetime.now(UTC):%Y-%m-%d %H:%M} UTC: {'; '.join(names)}."
    )
    return "\n".join(lines) + "\n"


def _with_gpu_rows(
    text: str, rows: list[Row], names: list[str], command: str, repeats: int, commit: str
) -> str:
    """``text`` (a BENCHMARKS.md) with ``rows`` (of the benchmarks ``names``), measured on the GPU, in
    the GPU column of its rows of the same benchmark and setting (a row the table lacks goes last, with
    no CPU figure), and a line naming the GPU, the command, ``commit`` (the source's as the run started)
    and the benchmarks."""
    lines = _table_lines(text)
    for row in rows:
        at = _row_at(lines, row)
        if at is None:
            at = _after_table(lines)
            cpu = [NO_FIGURE] * 3 + [_target(row), NO_FIGURE, NO_FIGURE]
            lines.insert(at, "| " + " | ".join([row.name, row.setting, *cpu, NO_FIGURE]) + " |")
        lines[at] = "| " + " | ".join([*_cells(lines[at])[:-1], _gpu_cell(row)]) + " |"
    _drop_superseded(lines, GPU_NOTE, set(names))
    gpu = f"{torch.cuda.get_device_name()}, torch {torch.__version__}, Python {platform.python_version()}"
    _add_note(
        lines,
        f"{GPU_NOTE} `{command}` ({gpu}; CPU {cpu_description()}; commit {commit}; wall time, "
        f"median of {repeats} repetitions) on {datetime.now(UTC):%Y-%m-%d %H:%M} UTC: {'; '.join(names)}.",
    )
    return "\n".join(lines) + "\n"
