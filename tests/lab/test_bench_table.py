"""``dospcot-lab bench``: the table it writes (rows replaced alone, kept across a stop, a GPU column,
older tables brought to today's columns) and the one-line refusals of its command."""

import dataclasses
import re

import pytest

from dospcot_lab import bench, bench_measure
from dospcot_lab.cli import main

OLD_HEADER = (
    "# Benchmarks\n\nEach figure: median of 3 repetitions [min, max]; ours and the peer alternate.\n\n"
)


def test_bench_quick_never_writes_benchmarks_md(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)  # as in a checkout: BENCHMARKS.md beside the command
    out = tmp_path / "BENCHMARKS.md"
    assert main(["bench", "--quick", "--out", "BENCHMARKS.md"]) == 2
    err = capsys.readouterr().err
    assert "--quick figures are a smoke test and never go into BENCHMARKS.md" in err
    assert err.count("\n") == 1 and not out.exists()


@pytest.mark.slow  # over 30 s on 2 cores: `make test-slow`
def test_bench_quick_writes_every_row(tmp_path):
    out = tmp_path / "bench-quick.md"
    assert main(["bench", "--quick", "--repeats", "3", "--out", str(out)]) == 0
    text = out.read_text()
    assert text.count("ExpectedSarsaDQN (target=") == 4 and "median of 3 repetitions" in text
    assert "DOSPCoT run vs its two ExpectedSarsaDQN agents alone: wall time" in text
    assert "`dospcot sweep` local backend, 2 workers vs 1: throughput" in text
    assert "Shared transition store vs the raw arrays: memory per million steps" in text
    assert "One co-training step, 100,000 vs 10,000 stored steps: growth against n log n" in text
    assert "FastHighwayVec vs highway-env's highway-fast-v0: env steps per second" in text
    assert "Tabular agents, vectorised vs a per-step Python loop: agent steps per second" in text
    assert "| ratio | target | met |" in text
    cost = "A DOSPCoT run vs its agents alone (a self-training run per view): CPU time per run"
    assert text.count(cost) == 4
    assert text.count("This release vs the last (700346f): CPU time per DOSPCoT run") == 4
    assert "This release vs the last (700346f): peak memory per DOSPCoT run" in text


def _row(name: str, ours: float) -> bench_measure.Row:
    steps = bench_measure.Measurement.of([ours, ours, ours], "steps/s")
    return bench_measure.Row(
        name, "setting", steps, bench_measure.Measurement.of([10.0] * 3, "steps/s"), True, 0.5
    )


def test_bench_only_replaces_its_row_and_appends_a_new_one(tmp_path, capsys, monkeypatch):
    out = tmp_path / "BENCHMARKS.md"
    out.write_text(bench.render([_row("A", 5.0), _row("B", 6.0)], "dospcot-lab bench"))
    rerun = {"A": lambda quick, repeats: _row("A", 20.0), "C": lambda quick, repeats: _row("C", 2.0)}
    monkeypatch.setattr(bench, "BENCHMARKS", rerun)
    assert main(["bench", "--only", "A", "--only", "C", "--out", str(out)]) == 0
    lines = out.read_text().splitlines()
    table = [line for line in lines if line.startswith("| ") and not line.startswith("| benchmark")]
    assert [line.split(" | ")[0] for line in table] == ["| A", "| B", "| C"]
    assert "| 2.000 | >= 0.5 | yes |" in table[0] and "| 0.600 |" in table[1]  # A rerun, B kept
    assert "| 0.200 | >= 0.5 | no |" in table[2]
    assert any(line.startswith("Rerun alone by `dospcot-lab bench --only A --only C") for line in lines)
    assert lines[-1] == bench.NOTES[-1]
    # Rerunning A alone keeps the note on A and C (C's figure is still from then), then adds one.
    assert main(["bench", "--only", "A", "--out", str(out)]) == 0
    notes = [line for line in out.read_text().splitlines() if line.startswith("Rerun alone by")]
    assert len(notes) == 2 and notes[1].startswith("Rerun alone by `dospcot-lab bench --only A --out")
    assert main(["bench", "--only", "A", "--out", str(out)]) == 0  # the same again: replaces its note
    notes = [line for line in out.read_text().splitlines() if line.startswith("Rerun alone by")]
    assert len(notes) == 2
    # An unknown name, or a file no full run wrote, fails with one line.
    assert main(["bench", "--only", "Z", "--out", str(out)]) == 2
    assert "unknown benchmark(s) ['Z']" in capsys.readouterr().err
    assert main(["bench", "--only", "A", "--out", str(tmp_path / "none.md")]) == 2
    err = capsys.readouterr().err
    assert "holds none" in err and err.count("\n") == 1
    # A benchmark whose setting changed replaces its one old row rather than sitting beside it.
    changed = dataclasses.replace(_row("B", 30.0), setting="new setting")
    monkeypatch.setattr(bench, "BENCHMARKS", {"B": lambda quick, repeats: changed})
    assert main(["bench", "--only", "B", "--out", str(out)]) == 0
    table = [line for line in out.read_text().splitlines() if line.startswith("| B | ")]
    assert len(table) == 1 and table[0].startswith("| B | new setting |") and "| 3.000 |" in table[0]
    # The notes say how rows are measured: a rerun writes the code's notes over the file's.
    monkeypatch.setattr(bench, "NOTES", ["Notes:", "- measured another way."])
    assert main(["bench", "--only", "B", "--out", str(out)]) == 0
    assert out.read_text().endswith("\nNotes:\n- measured another way.\n")


def test_bench_keeps_the_rows_measured_before_a_failing_row_or_a_stop(tmp_path, capsys, monkeypatch):
    out = tmp_path / "BENCHMARKS.md"
    out.write_text(bench.render([_row("A", 5.0), _row("B", 6.0)], "dospcot-lab bench"))

    def fails(error: type[BaseException]):
        def row(quick: bool, repeats: int) -> bench_measure.Row:
            raise error()

        return row

    # A row that crashes an hour in: the row measured before it is already in the file.
    monkeypatch.setattr(
        bench, "BENCHMARKS", {"A": lambda quick, repeats: _row("A", 40.0), "B": fails(RuntimeError)}
    )
    with pytest.raises(RuntimeError):
        bench.run_benchmarks(
            out, quick=False, repeats=3, command="dospcot-lab bench --only A --only B", only=["A", "B"]
        )
    table = {line.split(" | ")[0]: line for line in out.read_text().splitlines() if line.startswith("| ")}
    assert "| 4.000 |" in table["| A"] and "| 0.600 |" in table["| B"]  # A rerun, B as it was
    # Ctrl-C in the second row of a full run: the first row kept, and said so in one line.
    monkeypatch.setattr(
        bench, "BENCHMARKS", {"A": lambda quick, repeats: _row("A", 20.0), "B": fails(KeyboardInterrupt)}
    )
    assert main(["bench", "--out", str(out)]) == 130
    last = capsys.readouterr().err.splitlines()[-1]  # the lines before it are the progress bar's
    assert last == f"dospcot-lab bench: interrupted; kept the rows measured before the stop, in {out}: A"
    table = {line.split(" | ")[0]: line for line in out.read_text().splitlines() if line.startswith("| ")}
    assert "| 2.000 |" in table["| A"] and "| 0.600 |" in table["| B"]


def test_bench_gpu_column_holds_the_gpu_figures_beside_the_cpu_ones(tmp_path, capsys, monkeypatch):
    out = tmp_path / "BENCHMARKS.md"
    out.write_text(bench.render([_row("A", 5.0), _row("B", 6.0)], "dospcot-lab bench"))
    assert main(["bench", "--device", "cuda", "--out", str(out)]) == 2  # this machine has no GPU
    err = capsys.readouterr().err
    assert "sees no CUDA device" in err and err.count("\n") == 1
    monkeypatch.setattr(bench.torch.cuda, "is_available", lambda: True)
    monkeypatch.setattr(bench.torch.cuda, "get_device_name", lambda: "Test GPU")
    assert main(["bench", "--device", "cuda", "--only", "tabular", "--out", str(out)]) == 2
    assert "unknown benchmark(s) on cuda ['tabular']" in capsys.readouterr().err
    gpu = {"A": lambda quick, repeats: _row("A", 8.0), "D": lambda quick, repeats: _row("D", 40.0)}
    monkeypatch.setattr(bench, "GPU_BENCHMARKS", gpu)
    assert main(["bench", "--device", "cuda", "--repeats", "3", "--out", str(out)]) == 0
    lines = out.read_text().splitlines()
    table = {line.split(" | ")[0]: line for line in lines if line.startswith("| ")}
    # A's CPU figures stay (ratio 0.5); its GPU cell: ratio 8/10, target 0.5 met, the two medians.
    unknown = str(bench_measure.Provenance.unknown())  # rows that render() wrote without run_benchmarks
    gpu_a = "0.800, yes (8.00 steps/s vs 10.00 steps/s)"
    assert table["| A"].endswith(f"| 0.500 | >= 0.5 | yes | {unknown} | {gpu_a} |")
    assert table["| B"].endswith(f"| >= 0.5 | yes | {unknown} | – |")  # no GPU form: a dash
    assert (
        table["| D"]  # no CPU figure, so nothing made it on the CPU
        == "| D | setting | – | – | – | >= 0.5 | – | – | 4.000, yes (40.00 steps/s vs 10.00 steps/s) |"
    )
    gpu_notes = [line for line in lines if line.startswith("GPU column by")]
    assert len(gpu_notes) == 1 and "(Test GPU, torch " in gpu_notes[0] and gpu_notes[0].endswith(": A; D.")
    assert "; CPU " in gpu_notes[0] and "; commit " in gpu_notes[0]  # the GPU note says what made it
    # A CPU rerun of A keeps its GPU figure; a full CPU run keeps every GPU figure and the GPU note.
    monkeypatch.setattr(bench, "BENCHMARKS", {"A": lambda quick, repeats: _row("A", 20.0)})
    assert main(["bench", "--only", "A", "--out", str(out)]) == 0
    table = {line.split(" | ")[0]: line for line in out.read_text().splitlines() if line.startswith("| ")}
    assert table["| A"].endswith(f" | >= 0.5 | yes | {bench._cells(table['| A'])[-2]} | {gpu_a} |")
    assert "| 2.000 |" in table["| A"] and _made("A", table["| A"])
    monkeypatch.setattr(
        bench,
        "BENCHMARKS",
        {"A": lambda quick, repeats: _row("A", 2.0), "B": lambda quick, repeats: _row("B", 1)},
    )
    assert main(["bench", "--out", str(out)]) == 0
    lines = out.read_text().splitlines()
    table = {line.split(" | ")[0]: line for line in lines if line.startswith("| ")}
    assert table["| A"].endswith(f"| 0.200 | >= 0.5 | no | {bench._cells(table['| A'])[-2]} | {gpu_a} |")
    assert _made("A", table["| A"])
    assert (
        set(table) == {"| benchmark", "| A", "| B"}
        and [line for line in lines if line.startswith("GPU")] == gpu_notes
    )
    # A GPU rerun of A alone keeps the note that names A and D (D's figure is from then), and adds one.
    monkeypatch.setattr(bench, "GPU_BENCHMARKS", {"A": lambda quick, repeats: _row("A", 9.0)})
    assert main(["bench", "--device", "cuda", "--only", "A", "--out", str(out)]) == 0
    notes = [line for line in out.read_text().splitlines() if line.startswith("GPU column by")]
    assert len(notes) == 2 and notes[0] == gpu_notes[0] and notes[1].endswith(": A.")


def _made(bench_name: str, line: str) -> bool:
    """Whether ``line``'s *made by* cell is the one run_benchmarks writes for a row of :func:`_row` that
    benchmark ``bench_name`` measured on this machine (3 repetitions; the date, a minute's, aside)."""
    made = bench_measure.Provenance.parse(bench._cells(line)[-2])
    now = bench_measure.Provenance.now(bench_name, _row(bench_name, 1.0), bench_measure.short_commit())
    return dataclasses.replace(made, date=now.date) == now


@pytest.mark.parametrize("gpu_column", [False, True], ids=["before-the-gpu-column", "before-provenance"])
def test_bench_gives_an_older_table_its_columns_and_drops_its_one_repetition_count(
    tmp_path, monkeypatch, gpu_column
):
    """A table written before the GPU column, or before rows carried their provenance, gets the columns
    it lacks on a rerun: the old rows' *made by* cell not recorded, and the header's claim of one
    repetition count for every row replaced by the line that points at each row's own."""
    out = tmp_path / "BENCHMARKS.md"
    header, row = (
        bench.WITHOUT_GPU,
        "| A | setting | 5.00 steps/s [5.00, 5.00] | 10.00 steps/s | 0.500 | >= 0.5 | yes |",
    )
    if gpu_column:
        header, row = bench.WITHOUT_PROVENANCE, row + " 0.900, yes (9 vs 10) |"
    separator = "|---" * header.count(" | ") + "|---|"
    out.write_text(f"{OLD_HEADER}{header}\n{separator}\n{row}\n\nNotes:\n- old.\n")
    monkeypatch.setattr(bench, "BENCHMARKS", {"B": lambda quick, repeats: _row("B", 6.0)})
    assert main(["bench", "--only", "B", "--repeats", "1", "--out", str(out)]) == 0
    lines = out.read_text().splitlines()
    at = lines.index(bench.TABLE_HEADER)
    assert lines[at + 1] == bench.SEPARATOR
    unknown = str(bench_measure.Provenance.unknown())
    assert lines[at + 2].endswith(
        f"| 0.500 | >= 0.5 | yes | {unknown} | {'0.900, yes (9 vs 10)' if gpu_column else '–'} |"
    )
    # B's repetitions are those its measurements hold (3, from _row), whatever --repeats asked.
    assert lines[at + 3].startswith("| B | ") and "| 0.600 | >= 0.5 | yes | " in lines[at + 3]
    assert lines[at + 3].endswith(" | – |") and _made("B", lines[at + 3])
    assert bench.FIGURES in lines and not any(line.startswith("Each figure: median of") for line in lines)


def test_bench_drops_the_recovered_provenance_paragraph_with_the_last_row_it_describes(tmp_path, monkeypatch):
    out = tmp_path / "BENCHMARKS.md"
    recovered = bench_measure.Provenance(
        "A", "3", "2026-11-24 03:49 UTC", f"a503a3c ({bench.RECOVERED})", "x"
    )
    rows = [dataclasses.replace(_row(name, 5.0), made=recovered) for name in ("A", "B")]
    lines = bench.render(rows, "dospcot-lab bench").splitlines()
    at = lines.index(bench.TABLE_HEADER)
    lines[at - 1 : at - 1] = ["", f"{bench.RECOVERED_NOTE} how rows A and B were made, from git."]
    out.write_text("\n".join(lines) + "\n")
    monkeypatch.setattr(bench, "BENCHMARKS", {"A": lambda quick, repeats: _row("A", 6.0)})
    assert main(["bench", "--only", "A", "--out", str(out)]) == 0
    assert bench.RECOVERED_NOTE in out.read_text()  # B is still a recovered row
    monkeypatch.setattr(bench, "BENCHMARKS", {"B": lambda quick, repeats: _row("B", 6.0)})
    assert main(["bench", "--only", "B", "--out", str(out)]) == 0
    assert bench.RECOVERED_NOTE not in out.read_text() and bench.RECOVERED not in out.read_text()


def test_bench_stamps_every_row_with_how_it_was_made(tmp_path, monkeypatch):
    """Each row a run measures carries its benchmark's name, its repetitions (counted from its
    measurements), the date, the commit and the CPU model; none is asserted by its timing."""
    out = tmp_path / "BENCHMARKS.md"
    one = bench_measure.Row(
        "One",
        "setting",
        bench_measure.Measurement.of([2.0], "s"),
        bench_measure.Measurement.of([4.0], "s"),
        False,
        1.0,
    )
    monkeypatch.setattr(
        bench,
        "BENCHMARKS",
        {"one_rep": lambda quick, repeats: one, "A": lambda quick, repeats: _row("A", 5.0)},
    )
    monkeypatch.setattr(bench_measure, "cpu_description", lambda: "Test CPU Model 9000, torch kernels AVX2")
    monkeypatch.setattr(bench, "short_commit", lambda: "abc1234+dirty")
    assert main(["bench", "--out", str(out)]) == 0
    text = out.read_text()
    rows = {line.split(" | ")[0]: line for line in text.splitlines() if line.startswith("| ")}
    made = {
        name: bench_measure.Provenance.parse(bench._cells(rows[f"| {name}"])[-2]) for name in ("One", "A")
    }
    assert (made["One"].bench, made["One"].repetitions) == ("one_rep", "1")
    assert (made["A"].bench, made["A"].repetitions) == ("A", "3")
    for prov in made.values():
        assert (prov.commit, prov.cpu) == ("abc1234+dirty", "Test CPU Model 9000, torch kernels AVX2")
        assert re.fullmatch(r"\d{4}-\d\d-\d\d \d\d:\d\d UTC", prov.date)
        assert bench_measure.Provenance.parse(str(prov)) == prov  # the cell reads back as written
    assert "median of 3 repetitions" not in text and bench.FIGURES in text
    assert "`one_rep`; 1 repetition; " in rows["| One"]
    # A provenance cell that a row written before them holds reads back as not recorded.
    unknown = bench_measure.Provenance.parse(str(bench_measure.Provenance.unknown()))
    assert set(dataclasses.astuple(unknown)) == {bench_measure.NOT_RECORDED}
    with pytest.raises(ValueError, match="not a made-by cell"):
        bench_measure.Provenance.parse("3 repetitions; yesterday")


def test_bench_note_of_a_row_stays_when_another_row_of_its_name_is_rerun(tmp_path, monkeypatch):
    """The ExpectedSarsaDQN rows share a name and differ in their setting: a GPU rerun of one keeps the
    line that says where the other's GPU figure came from."""
    out = tmp_path / "BENCHMARKS.md"
    wide = dataclasses.replace(_row("A", 5.0), setting="wide")
    out.write_text(bench.render([_row("A", 5.0), wide], "dospcot-lab bench"))
    monkeypatch.setattr(bench.torch.cuda, "is_available", lambda: True)
    monkeypatch.setattr(bench.torch.cuda, "get_device_name", lambda: "Test GPU")
    gpu = {"narrow": lambda quick, repeats: _row("A", 7.0), "wide": lambda quick, repeats: wide}
    monkeypatch.setattr(bench, "GPU_BENCHMARKS", gpu)
    assert main(["bench", "--device", "cuda", "--only", "wide", "--out", str(out)]) == 0
    assert main(["bench", "--device", "cuda", "--only", "narrow", "--out", str(out)]) == 0
    notes = [line for line in out.read_text().splitlines() if line.startswith("GPU column by")]
    assert [note.rsplit(": ", 1)[1] for note in notes] == ["wide.", "narrow."]
    cells = [line.rsplit(" | ", 1)[1] for line in out.read_text().splitlines() if line.startswith("| A | ")]
    assert cells == [
        "0.700, yes (7.00 steps/s vs 10.00 steps/s) |",
        "0.500, yes (5.00 steps/s vs 10.00 steps/s) |",
    ]


def test_two_only_runs_into_one_file_keep_each_others_rows(tmp_path, monkeypatch):
    """Two ``--only`` runs writing one file, each on its own core: a row lands into the file as it reads
    then, so the other run's row, landed meanwhile, stays, and so does its note."""
    out = tmp_path / "BENCHMARKS.md"
    out.write_text(bench.render([_row("A", 5.0), _row("B", 6.0)], "dospcot-lab bench"))

    def a_while_the_other_lands(quick: bool, repeats: int) -> bench_measure.Row:
        bench.run_benchmarks(out, False, 3, "dospcot-lab bench --only C", only=["C"])
        return _row("A", 20.0)

    rows = {"A": a_while_the_other_lands, "C": lambda quick, repeats: _row("C", 2.0)}
    monkeypatch.setattr(bench, "BENCHMARKS", rows)
    bench.run_benchmarks(out, False, 3, "dospcot-lab bench --only A", only=["A"])
    lines = out.read_text().splitlines()
    table = {line.split(" | ")[0]: line for line in lines if line.startswith("| ")}
    assert "| 2.000 |" in table["| A"] and "| 0.600 |" in table["| B"] and "| 0.200 |" in table["| C"]
    notes = [line.rsplit(": ", 1)[1] for line in lines if line.startswith("Rerun alone by")]
    assert sorted(notes) == ["A.", "C."]


def test_rows_of_one_name_from_two_benchmarks_sit_side_by_side(tmp_path, monkeypatch):
    """The cost rows share a name, one per task: a task's row, its setting new, does not take the row
    another task's benchmark wrote."""
    out = tmp_path / "BENCHMARKS.md"
    out.write_text(bench.render([_row("B", 6.0)], "dospcot-lab bench"))
    doorkey = dataclasses.replace(_row("Cost", 2.0), setting="doorkey")
    lavagap = dataclasses.replace(_row("Cost", 3.0), setting="lavagap")
    rows = {"cost_doorkey": lambda quick, repeats: doorkey, "cost_lavagap": lambda quick, repeats: lavagap}
    monkeypatch.setattr(bench, "BENCHMARKS", rows)
    bench.run_benchmarks(out, False, 3, "dospcot-lab bench --only cost_doorkey", only=["cost_doorkey"])
    bench.run_benchmarks(out, False, 3, "dospcot-lab bench --only cost_lavagap", only=["cost_lavagap"])
    costs = [line for line in out.read_text().splitlines() if line.startswith("| Cost | ")]
    assert [line.split(" | ")[1] for line in costs] == ["doorkey", "lavagap"]


def test_every_row_of_a_run_names_the_commit_its_source_had_as_the_run_started(tmp_path, monkeypatch):
    """The first row landing in a tracked BENCHMARKS.md leaves the checkout dirty; the rows after it
    were measured by the same source, so they name the same commit."""
    out = tmp_path / "BENCHMARKS.md"
    out.write_text(bench.render([_row("A", 5.0), _row("B", 6.0)], "dospcot-lab bench"))
    states = iter(["abc1234", "abc1234+dirty", "abc1234+dirty"])
    monkeypatch.setattr(bench, "short_commit", lambda: next(states))
    rows = {"A": lambda quick, repeats: _row("A", 7.0), "B": lambda quick, repeats: _row("B", 8.0)}
    monkeypatch.setattr(bench, "BENCHMARKS", rows)
    bench.run_benchmarks(out, False, 3, "dospcot-lab bench --only A --only B", only=["A", "B"])
    table = [line for line in out.read_text().splitlines() if line.startswith(("| A |", "| B |"))]
    assert [bench_measure.Provenance.parse(bench._cells(line)[-2]).commit for line in table] == [
        "abc1234",
        "abc1234",
    ]


def test_rows_of_one_name_rerun_together_with_new_settings_each_replace_their_own(tmp_path, monkeypatch):
    """Both cost rows rerun in one run, each with a new setting: each takes the row its own benchmark
    wrote, and the table holds no stale copy."""
    out = tmp_path / "BENCHMARKS.md"
    out.write_text(bench.render([_row("B", 6.0)], "dospcot-lab bench"))

    def cost_rows(suffix: str) -> dict:
        """cost_doorkey's and cost_lavagap's rows, their settings the task's name and ``suffix``."""
        rows = {
            task: dataclasses.replace(_row("Cost", 2.0), setting=task + suffix)
            for task in ("doorkey", "lavagap")
        }
        return {f"cost_{task}": (lambda quick, repeats, row=row: row) for task, row in rows.items()}

    for suffix in ("", ", longer"):
        monkeypatch.setattr(bench, "BENCHMARKS", cost_rows(suffix))
        bench.run_benchmarks(
            out, False, 3, "dospcot-lab bench --only both", only=["cost_doorkey", "cost_lavagap"]
        )
    costs_now = [
        line.split(" | ")[1] for line in out.read_text().splitlines() if line.startswith("| Cost | ")
    ]
    assert costs_now == ["doorkey, longer", "lavagap, longer"]


def test_a_target_of_a_third_is_written_as_the_ratio_is_rounded(tmp_path):
    row = dataclasses.replace(_row("A", 3.0), higher_is_better=False, target=1 / 3)
    line = next(line for line in bench.render([row], "cmd").splitlines() if line.startswith("| A"))
    assert "| 0.300 | <= 0.333 | yes |" in line and "0.3333" not in line
