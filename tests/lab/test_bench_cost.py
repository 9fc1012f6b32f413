"""The cost rows of ``dospcot-lab bench`` (lab/bench_cost.py): how a run is launched and read, and how the
rows compare the runs."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from dospcot_lab import bench_cost

ROOT = Path(__file__).resolve().parents[2]

FAKE_MAIN = """
import json, os, sys
if "fail" in sys.argv:
    sys.exit("the fake release failed on purpose")
blob = bytearray(64 * 1024 * 1024)  # 64 MiB resident, so that the peak memory shows it
blob[:: 4096] = b"x" * len(blob[:: 4096])
with open(os.environ["FAKE_OUT"], "w") as handle:
    json.dump({"argv": sys.argv[1:], "cwd": os.getcwd(), "file": __file__}, handle)
"""


@pytest.fixture
def fake_release(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """A release whose ``python -m dospcot`` records its arguments and working folder in FAKE_OUT."""
    site = tmp_path / "site"
    (site / "dospcot").mkdir(parents=True)
    (site / "dospcot" / "__init__.py").write_text("")
    (site / "dospcot" / "__main__.py").write_text(FAKE_MAIN)
    monkeypatch.setattr(bench_cost, "release_site", lambda commit: site)
    monkeypatch.setenv("FAKE_OUT", str(tmp_path / "called.json"))
    bench_cost.trained.cache_clear()
    yield tmp_path
    bench_cost.trained.cache_clear()


def test_a_release_runs_from_its_own_install_with_the_seed_and_length(fake_release: Path) -> None:
    cpu, peak = bench_cost.trained("grid16-dospcot", 3, "fake", True)
    called = json.loads((fake_release / "called.json").read_text())
    assert called["file"].startswith(str(fake_release / "site"))
    assert called["argv"][:2] == ["train", "grid16-dospcot"]
    assert called["argv"][-4:] == ["--set", "seed=3", "--set", "training.rounds=2"]
    assert not Path(called["cwd"]).is_relative_to(ROOT)  # no checkout shadows the install
    assert cpu > 0 and peak >= 64  # MiB: the fake's buffer


def test_a_failed_run_says_why(fake_release: Path) -> None:
    with pytest.raises(RuntimeError, match="failed on purpose"):
        bench_cost.trained("fail", 0, "fake", True)


def test_a_commit_the_checkout_lacks_is_a_clear_error(tmp_path: Path, monkeypatch) -> None:
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    with pytest.raises(RuntimeError, match="0000000"):
        bench_cost.release_site("0000000")


def test_rows_compare_cpu_and_memory_of_the_same_seeds(monkeypatch) -> None:
    """Hand figures: DOSPCoT 30 / 50 / 40 CPU-s against its agents alone, self-training on the image
    view 10 / 20 / 20 plus on the egocentric map 15 / 25 / 20 (sums 25 / 45 / 40; median ratio 40 / 40 =
    1.0 <= 1.15); the last release 100 / 90 / 80 (40 / 90, under the 0.5 LavaGap target); peak memory 600
    MiB against 1,500 (0.4: not 3x less)."""
    cpu = {
        ("minigrid-lavagap-dospcot", ()): [30.0, 50.0, 40.0],
        ("minigrid-lavagap-self-training", ("image",)): [10.0, 20.0, 20.0],
        ("minigrid-lavagap-self-training", ("ego",)): [15.0, 25.0, 20.0],
    }
    old = [100.0, 90.0, 80.0]

    def trained(
        preset: str, seed: int, release: str | None, quick: bool, views: tuple[str, ...] = ()
    ) -> tuple[float, float]:
        assert not quick
        return (old[seed], 1500.0) if release else (cpu[preset, views][seed], 600.0)

    monkeypatch.setattr(bench_cost, "trained", trained)
    cost = bench_cost.bench_cost("lavagap", False, 3)
    assert (cost.ours.median, cost.peer.median, cost.ratio, cost.met) == (40.0, 40.0, 1.0, True)
    assert cost.target == 1.15
    assert "seeds 0-2" in cost.setting and "full length" in cost.setting and "`ego`" in cost.setting
    release = bench_cost.bench_release("lavagap", False, 3)
    assert release.ratio == pytest.approx(40 / 90) and release.target == 0.5 and release.met
    memory = bench_cost.bench_release("lavagap", False, 3, memory=True)
    assert memory.ratio == pytest.approx(0.4) and not memory.met


def test_a_run_on_other_views_names_them_in_a_toml_list(fake_release: Path) -> None:
    bench_cost.trained("minigrid-lavagap-self-training", 0, "fake", True, ("ego",))
    called = json.loads((fake_release / "called.json").read_text())
    assert called["argv"][-2:] == ["--set", 'views=["ego"]']
