"""The rating page (``dospcot rate RUN_DIR``): bad requests against a real server, and Chromium answering
whole runs by keys and clicks, which must end byte-identical to the simulated runs."""

from __future__ import annotations

import csv
import json
import os
import re
import shutil
import signal
import socket
import subprocess
import sys
import threading
import urllib.error
import urllib.request
from contextlib import contextmanager
from pathlib import Path

import pytest
from small_runs import PINNED

from dospcot.cli import main
from dospcot.raters.answer_files import read_answers, read_rows

uvicorn = pytest.importorskip(
    "uvicorn", reason="the rate extra (pip install 'dospcot[rate]') is not installed"
)
from dospcot.rating.server import RoundAnswers, make_app  # noqa: E402

CHROMIUM = Path("/usr/bin/chromium")
CHROMIUM_ARGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
]
TOKEN = "t0ken-for-tests"
ROUND_2 = [
    {"sample": 5, "key": "state 1, action 0 (up)", "reward": "", "frame": "round_2/5_frame.png"},
    {"sample": 9, "key": "state 2, action 1 (right)", "reward": "", "frame": "..A\n.G."},
    {"sample": 12, "key": "state 3, action 2 (down)", "reward": "", "frame": ""},
]
PNG = b"\x89PNG\r\n\x1a\n fake image bytes"


def _fake_run(tmp_path: Path) -> Path:
    """A run folder waiting on round 2's three queries; round 1 answered -1 and 0."""
    run_dir = tmp_path / "run"
    (run_dir / "queries" / "round_2").mkdir(parents=True)
    (run_dir / "config.toml").write_text('name = "secret"\n')
    (run_dir / "queries" / "round_1.csv").write_text("sample,key,reward\n1,k,-1\n2,k,0\n")
    (run_dir / "queries" / "round_2" / "5_frame.png").write_bytes(PNG)
    _write(run_dir / "queries" / "round_2.csv", ROUND_2)
    return run_dir


def _write(path: Path, rows: list[dict]) -> None:
    with path.open("w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)


def _rewards(path: Path) -> dict[int, str]:
    _, rows, _ = read_rows(path)
    return {int(row["sample"]): row["reward"] for _, row in rows}


@contextmanager
def _serve(path: Path, then_train: bool = False):
    """The page's app for the query file ``path``, served from a thread; yields its address."""
    sock = socket.socket()
    sock.bind(("127.0.0.1", 0))
    app = make_app(RoundAnswers(path), TOKEN, then_train)
    server = uvicorn.Server(uvicorn.Config(app, log_level="warning", access_log=False, lifespan="off"))
    app.state.server = server
    thread = threading.Thread(target=server.run, kwargs={"sockets": [sock]}, daemon=True)
    thread.start()
    while not server.started:
        threading.Event().wait(0.01)
    try:
        yield f"http://127.0.0.1:{sock.getsockname()[1]}"
    finally:
        server.should_exit = True
        thread.join()


def _request(url: str, body: dict | None = None, token: str | None = TOKEN, raw: bytes | None = None):
    """(status, parsed JSON or bytes) of a GET, or a POST of ``body``, with the token in a header."""
    data = raw if raw is not None else (None if body is None else json.dumps(body).encode())
    request = urllib.request.Request(url, data=data, method="GET" if data is None else "POST")
    if token is not None:
        request.add_header("X-Token", token)
    try:
        with urllib.request.urlopen(request) as response:
            status, content = response.status, response.read()
    except urllib.error.HTTPError as err:
        status, content = err.code, err.read()
    try:
        return status, json.loads(content)
    except ValueError:
        return status, content


# --- Bad requests ----------------------------------------------------------------------------------


def test_every_request_needs_the_token(tmp_path):
    run_dir = _fake_run(tmp_path)
    before = (run_dir / "queries" / "round_2.csv").read_bytes()
    with _serve(run_dir / "queries" / "round_2.csv") as url:
        for path in ("/", "/api/round", "/files/round_2/5_frame.png"):
            for token in (None, "", "wrong", TOKEN + "x"):
                status, body = _request(url + path, token=token)
                assert status == 403 and "missing or wrong token" in body["error"]
        status, body = _request(url + "/api/answer", {"sample": 5, "reward": "-1"}, token="wrong")
        assert status == 403
        assert (run_dir / "queries" / "round_2.csv").read_bytes() == before
        # The token as a query parameter (the page's address, its images) or as a header.
        status, page = _request(f"{url}/?token={TOKEN}", token=None)
        assert status == 200 and b"dospcot rate" in page
        status, body = _request(url + "/api/round")
        assert status == 200 and [q["sample"] for q in body["queries"]] == [5, 9, 12]
        assert [s["value"] for s in body["seen"]] == [-1.0, 0.0]
        assert body["queries"][1]["text_frame"] == "..A\n.G."


def test_only_files_under_the_queries_folder_are_served(tmp_path):
    run_dir = _fake_run(tmp_path)
    (run_dir / "queries" / "round_2" / "link.png").symlink_to(run_dir / "config.toml")
    with _serve(run_dir / "queries" / "round_2.csv") as url:
        assert _request(url + "/files/round_2/5_frame.png") == (200, PNG)
        for path in (
            "/files/../config.toml",
            "/files/%2e%2e/config.toml",
            "/files/round_2/..%2f..%2fconfig.toml",
            "/files//etc/passwd",
            "/files/%2fetc%2fpasswd",
            "/files/round_2/link.png",
            "/files/round_2/none.png",
        ):
            status, body = _request(url + path)
            assert status == 404, path
            assert (
                body == {"error": f"only the files under {run_dir / 'queries'} are served"}
                or path == "/files/../config.toml"
            )


def test_answers_outside_the_round_or_not_finite_numbers_are_refused(tmp_path):
    run_dir = _fake_run(tmp_path)
    path = run_dir / "queries" / "round_2.csv"
    before = path.read_bytes()
    with _serve(path) as url:
        for body, message in (
            ({"sample": 999, "reward": "-1"}, "sample 999 is not one of round 2's 3 queries"),
            ({"sample": "five", "reward": "-1"}, "'five' is not a sample number"),
            (
                {"sample": 5, "reward": "abc"},
                "the reward of sample 5: 'abc' is not a number; answer with a number",
            ),
            ({"sample": 5, "reward": ""}, "the reward of sample 5: '' is not a number"),
            ({"sample": 5, "reward": "inf"}, "the reward of sample 5: inf, not finite"),
            ({"sample": 5, "reward": "nan"}, "the reward of sample 5: nan, not finite"),
            ({"sample": 5, "reward": "-1e300"}, "beyond the +-3.4e38 a float32 reward holds"),
        ):
            status, answer = _request(url + "/api/answer", body)
            assert status == 400 and message in answer["error"] and "\n" not in answer["error"], body
        assert _request(url + "/api/answer", raw=b"{not json")[0] == 400
        assert path.read_bytes() == before


def test_a_new_reward_value_is_kept_only_once_confirmed(tmp_path):
    run_dir = _fake_run(tmp_path)
    path = run_dir / "queries" / "round_2.csv"
    with _serve(path) as url:
        status, body = _request(url + "/api/answer", {"sample": 5, "reward": "42"})
        assert status == 409 and body["confirm"]
        assert body["error"] == "42 is a new reward value (seen so far: -1, 0)"
        assert _rewards(path)[5] == ""
        assert _request(url + "/api/answer", {"sample": 5, "reward": "42", "confirm": True})[0] == 200
        assert _request(url + "/api/answer", {"sample": 9, "reward": "42"})[0] == 200  # confirmed already
        assert _request(url + "/api/answer", {"sample": 12, "reward": "-1"})[0] == 200
        _, state = _request(url + "/api/round")
        assert [s["value"] for s in state["seen"]] == [-1.0, 0.0, 42.0]
    assert read_answers(path, [5, 9, 12], [-1.0, 0.0]).tolist() == [42.0, 42.0, -1.0]


def test_a_file_edited_by_hand_while_served_is_one_line_not_a_crash(tmp_path):
    run_dir = _fake_run(tmp_path)
    path = run_dir / "queries" / "round_2.csv"
    with _serve(path) as url:
        _write(path, [ROUND_2[0], ROUND_2[2]])  # sample 9's row deleted
        status, body = _request(url + "/api/answer", {"sample": 9, "reward": "0"})
        assert (status, body["error"]) == (400, f"sample 9 is no longer in {path}: restore its row")
        _write(path, [{**ROUND_2[0], "sample": "five"}])
        status, body = _request(url + "/api/round")
        assert status == 400 and "line 2: 'five' in the sample column is not a sample number" in body["error"]


def test_two_tabs_answering_the_same_query_the_last_answer_wins(tmp_path):
    run_dir = _fake_run(tmp_path)
    path = run_dir / "queries" / "round_2.csv"
    torn = []

    def read_while_written(stop: threading.Event) -> None:
        while not stop.is_set():
            _, rows, _ = read_rows(path)
            if [int(row["sample"]) for _, row in rows] != [5, 9, 12]:
                torn.append(rows)

    with _serve(path) as url:

        def tab(value: str) -> None:
            for _ in range(15):
                assert _request(url + "/api/answer", {"sample": 9, "reward": value})[0] == 200

        stop = threading.Event()
        reader = threading.Thread(target=read_while_written, args=(stop,))
        tabs = [threading.Thread(target=tab, args=(v,)) for v in ("-1", "0")]
        for thread in (reader, *tabs):
            thread.start()
        for thread in tabs:
            thread.join()
        stop.set()
        reader.join()
        assert _request(url + "/api/answer", {"sample": 9, "reward": "0"})[0] == 200
        assert _request(url + "/api/answer", {"sample": 9, "reward": "-1"})[0] == 200  # the second tab, last
    assert not torn
    assert _rewards(path) == {5: "", 9: "-1", 12: ""}
    assert not list(path.parent.glob("*.tmp"))


def _start_rate(run_dir: Path, *options: str) -> tuple[subprocess.Popen, str]:
    """``dospcot rate RUN_DIR`` in a process of its own, and the address it printed."""
    command = [sys.executable, "-m", "dospcot.cli", "rate", str(run_dir), *options]
    process = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    line = process.stdout.readline()
    match = re.search(r"http://127\.0\.0\.1:\d+/\?token=\S+", line)
    assert match, (line, process.stderr.read() if process.poll() is not None else "")
    return process, match.group(0)


def test_the_server_killed_mid_round_loses_no_answer(tmp_path):
    run_dir = _fake_run(tmp_path)
    path = run_dir / "queries" / "round_2.csv"
    process, address = _start_rate(run_dir)
    base, token = address.split("/?token=")
    try:
        assert _request(base + "/api/answer", {"sample": 5, "reward": "-1"}, token=token)[0] == 200
        assert _request(base + "/api/answer", {"sample": 12, "reward": "0"}, token=token)[0] == 200
    finally:
        process.send_signal(signal.SIGKILL)
        process.wait()
    assert _rewards(path) == {5: "-1", 9: "", 12: "0"}
    process, again = _start_rate(run_dir)
    try:
        base, new_token = again.split("/?token=")
        assert new_token != token and _request(base + "/api/round", token=token)[0] == 403
        _, state = _request(base + "/api/round", token=new_token)
        assert [q["reward"] for q in state["queries"]] == ["-1", "", "0"]
        assert _request(base + "/api/answer", {"sample": 9, "reward": "0"}, token=new_token)[0] == 200
    finally:
        process.send_signal(signal.SIGINT)
        process.wait()
    assert read_answers(path, [5, 9, 12], [-1.0, 0.0]).tolist() == [-1.0, 0.0, 0.0]


def test_rate_without_waiting_queries_or_with_a_taken_port_is_one_line(tmp_path, capsys):
    run_dir = _fake_run(tmp_path)
    for argv, message in (
        (["rate", str(tmp_path / "none")], "is not a run folder (it has no config.toml)"),
        (["rate", str(run_dir), "--accept=7"], "--accept=7: no row of"),
    ):
        assert main(argv) == 2
        err = capsys.readouterr().err
        assert message in err and err.count("\n") == 1, err
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        assert main(["rate", str(run_dir), "--port", str(taken.getsockname()[1])]) == 2
        assert "cannot listen on 127.0.0.1:" in capsys.readouterr().err
    (run_dir / "queries.csv").write_text("round,sample,strategy,answer\n2,5,random,-1.0\n")
    assert main(["rate", str(run_dir)]) == 2
    assert "the run read the answers of round 2 already" in capsys.readouterr().err
    shutil.rmtree(run_dir / "queries")
    assert main(["rate", str(run_dir)]) == 2
    assert "no reward queries wait there" in capsys.readouterr().err


# --- Whole runs answered in Chromium ----------------------------------------------------------------


def _browser():
    """A Chromium driven by Playwright, or a skip (outside CI) where Debian's Chromium is absent."""
    if not CHROMIUM.exists():
        if os.environ.get("CI"):
            pytest.fail("CI needs /usr/bin/chromium: `make test` installs it with apt-get")
        pytest.skip("no /usr/bin/chromium (apt-get install chromium) for the browser test")
    sync_api = pytest.importorskip("playwright.sync_api")
    return sync_api.sync_playwright(), dict(executable_path=str(CHROMIUM), args=CHROMIUM_ARGS)


def _train(*argv: str) -> int:
    return main([*argv, "--no-progress"])


def _shown(page) -> int:
    return int(page.get_attribute("#query", "data-sample"))


def _skip_back_and_list(page, samples: list[int]) -> None:
    """Skip (arrow key), back (button), the progress, and the list view, whose rows open their query."""
    first = _shown(page)
    assert page.text_content("#progress") == f"{samples.index(first) + 1} of {len(samples)} · 0 answered"
    page.keyboard.press("ArrowRight")
    assert _shown(page) == samples[(samples.index(first) + 1) % len(samples)]
    page.click("#back")
    assert _shown(page) == first
    page.keyboard.press("l")
    assert page.is_hidden("#query") and page.locator("#rows tr").count() == len(samples)
    page.click(f"#rows tr >> nth={len(samples) - 1}")
    assert page.is_visible("#query") and _shown(page) == samples[-1]


def _answer_in_the_page(page, address: str, hidden: dict[int, float], screenshot: Path | None = None) -> None:
    """Answer every query of the page at ``address`` with its hidden reward: a number key where the
    value is one of the buttons (a click past the ninth), else typed, and confirmed where it is new."""
    page.goto(address)
    page.wait_for_selector("#query:not([hidden]), #done:not([hidden])")
    samples = [q["sample"] for q in page.evaluate("round.queries")]
    total = len(samples)
    _skip_back_and_list(page, samples)
    for step in range(total):
        page.wait_for_selector("#query:not([hidden])")
        sample = int(page.get_attribute("#query", "data-sample"))
        if screenshot is not None and step == 1:
            page.screenshot(path=str(screenshot), full_page=True)
        values = [
            float(v) for v in page.eval_on_selector_all("button.value", "bs => bs.map(b => b.dataset.value)")
        ]
        wanted = hidden[sample]
        progress = page.text_content("#progress")
        if wanted in values and values.index(wanted) < 9:
            page.keyboard.press(str(values.index(wanted) + 1))
        elif wanted in values:
            page.click(f"button.value >> nth={values.index(wanted)}")
        else:
            page.fill("#other", repr(wanted))
            page.keyboard.press("Enter")
            page.wait_for_selector("#message.confirm")
            page.keyboard.press("Enter")
        page.wait_for_function("p => document.getElementById('progress').textContent !== p", arg=progress)
    page.wait_for_selector("#done:not([hidden])")
    assert f"All {total} queries" in page.text_content("#done")


def _hidden(simulated: Path) -> dict[int, float]:
    """Every answer the simulated run's rater gave: the hidden rewards of the queried samples."""
    with (simulated / "queries.csv").open() as handle:
        return {int(row["sample"]): float(row["answer"]) for row in csv.DictReader(handle)}


def _same_files(run_dir: Path, simulated: Path) -> None:
    for name in ("metrics.csv", "summary.json", "queries.csv", "reward_classes.json"):
        assert (run_dir / name).read_bytes() == (simulated / name).read_bytes(), name


def _answered_in_chromium(
    tmp_path: Path, preset: str, sets: list[str], then_train: bool, screenshot: Path | None = None
) -> None:
    """Train ``preset`` simulated and with the file rater; answer each round's queries in Chromium and
    resume (the last round through ``dospcot rate --then-train`` where ``then_train``); check the two
    runs' files are equal. ``screenshot``: the page of the last round's second query."""
    options = [a for s in sets for a in ("--set", s)]
    assert _train("train", preset, *options, "--runs-dir", str(tmp_path / "simulated")) == 0
    (simulated,) = (tmp_path / "simulated" / preset).iterdir()
    hidden = _hidden(simulated)
    file_sets = [*options, "--set", 'training.rater="file"']
    assert _train("train", preset, *file_sets, "--runs-dir", str(tmp_path / "file")) == 0
    (run_dir,) = (tmp_path / "file" / preset).iterdir()
    playwright, launch = _browser()
    with playwright as p:
        browser = p.chromium.launch(**launch)
        page = browser.new_page(viewport={"width": 1000, "height": 820})
        for round_ in (1, 2):
            if round_ == 2 and then_train:
                process, address = _start_rate(run_dir, "--then-train", "--no-progress")
                try:
                    _answer_in_the_page(page, address, hidden, screenshot)
                    page.keyboard.press("Enter")  # the done screen's "Resume training"
                    out, err = process.communicate(timeout=600)
                finally:
                    process.kill()
                assert process.returncode == 0, err
                assert f"{run_dir}: " in out
                continue
            with _serve(run_dir / "queries" / f"round_{round_}.csv") as url:
                _answer_in_the_page(
                    page, f"{url}/?token={TOKEN}", hidden, screenshot if round_ == 2 else None
                )
            assert _train("train", "--resume", str(run_dir)) == 0
        browser.close()
    assert not (run_dir / "checkpoint.pkl").exists()  # the run finished
    _same_files(run_dir, simulated)


TINY_SETS = [
    *PINNED,
    "training.steps_per_round=150",
    "training.label_fraction=0.2",
    'training.label_strategy="disagreement"',
]
MINIGRID_SETS = [
    # A person's answers cannot pause round 1's collection, so a file-rated run buys round 1's labels at
    # its end whatever the version; the simulated twin must buy them there too to train the same run.
    'training.first_labels="round_end"',
    "training.rounds=2",
    "training.steps_per_round=200",
    "dqn.learning_starts=50",
    "gym.eval_episodes=1",
    'training.label_strategy="disagreement"',
]


def test_a_tiny_run_answered_in_chromium_equals_the_simulated_run(tmp_path):
    _answered_in_chromium(tmp_path, "tiny", TINY_SETS, then_train=True)


@pytest.mark.slow
def test_a_minigrid_run_answered_in_chromium_equals_the_simulated_run(tmp_path):
    pytest.importorskip("minigrid")
    screenshot = tmp_path / "rating-page.png"
    _answered_in_chromium(tmp_path, "minigrid-doorkey-dospcot", MINIGRID_SETS, False, screenshot)
    assert screenshot.read_bytes().startswith(b"\x89PNG")
    if os.environ.get("DOSPCOT_WRITE_SCREENSHOT"):  # the guide's picture: docs/guide/rating.md
        shutil.copy(screenshot, Path(__file__).parents[1] / "docs" / "guide" / "rating-page.png")


# --- One server per run, whole sample numbers, keys that keep their values -----------------------------


def test_a_fractional_or_boolean_sample_is_refused_and_nothing_is_written(tmp_path):
    path = _fake_run(tmp_path) / "queries" / "round_2.csv"
    before = path.read_bytes()
    with _serve(path) as url:
        for sample in (5.5, True, "5.0", None, [5]):
            status, body = _request(f"{url}/api/answer", {"sample": sample, "reward": "-1"})
            assert status == 400 and "is not a sample number" in body["error"], sample
        assert _request(f"{url}/api/answer", {"sample": "5", "reward": "-1"})[0] == 200
    assert path.read_bytes() != before and _rewards(path)[5] == "-1"


def test_a_new_value_takes_the_next_key_and_no_key_changes_its_value(tmp_path):
    path = _fake_run(tmp_path) / "queries" / "round_2.csv"
    with _serve(path) as url:
        _, state = _request(f"{url}/api/round")
        assert [s["value"] for s in state["seen"]] == [-1.0, 0.0]  # round 1's, as first answered
        for value in ("-100", "7"):  # below and above the known ones
            assert _request(f"{url}/api/answer", {"sample": 5, "reward": value, "confirm": True})[0] == 200
            _, state = _request(f"{url}/api/round")
        # -100 is no longer given, and keeps its key: 7 takes the next one, and -100 needs no confirming.
        assert [s["value"] for s in state["seen"]] == [-1.0, 0.0, -100.0, 7.0]
        assert _request(f"{url}/api/answer", {"sample": 9, "reward": "-100"})[0] == 200
        assert _request(f"{url}/api/answer", {"sample": 12, "reward": "-7", "confirm": True})[0] == 200
        _, state = _request(f"{url}/api/round")
        assert [s["value"] for s in state["seen"]] == [-1.0, 0.0, -100.0, 7.0, -7.0]


def test_a_second_server_on_the_same_run_is_refused_and_an_empty_answer_file_is_named(tmp_path, capsys):
    run_dir = _fake_run(tmp_path)
    lock = run_dir / "queries" / ".lock"
    lock.write_text(str(os.getpid()))  # a live dospcot process serves it
    assert main(["rate", str(run_dir)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"{run_dir / 'queries'} is being rated by process {os.getpid()}" in err
    lock.unlink()
    (run_dir / "queries" / "round_2.csv").write_text("")
    assert main(["rate", str(run_dir)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "holds no query (the run writes a row for each)" in err


def test_a_host_other_machines_reach_is_warned_of(tmp_path, monkeypatch, capsys):
    from dospcot.rating import server

    monkeypatch.setattr(
        server, "_listen", lambda host, port: (_ for _ in ()).throw(server.RaterError("stop"))
    )
    run_dir = _fake_run(tmp_path)
    for host, warned in (("0.0.0.0", True), ("127.0.0.1", False), ("::1", False), ("localhost", False)):
        assert main(["rate", str(run_dir), "--host", host]) == 2
        err = capsys.readouterr().err
        assert ("warning: --host 0.0.0.0 serves the page to other machines" in err) == warned, host
    assert not (run_dir / "queries" / ".lock").exists()  # let go when the server did not start


def test_then_train_serves_the_next_rounds_queries_instead_of_exiting(tmp_path, monkeypatch, capsys):
    from dospcot import rating
    from dospcot.raters.file_rater import QueriesPending
    from dospcot.rating import server

    served, trained = [], []

    def rate(args):
        served.append((args.port, getattr(args, "token", None)))
        args.port, args.token = 8765, "kept"  # what the first server listened on, as _serve keeps it
        return True

    monkeypatch.setattr(server, "rate", rate)

    def train(args, command):
        trained.append(args.resume)
        if len(trained) == 1:  # round 2 asks in turn
            raise QueriesPending(3, args.resume / "queries" / "round_3.csv")
        return 0

    argv = ["rate", str(tmp_path), "--then-train"]
    from dospcot.cli.parser import build_parser

    args = build_parser().parse_args(argv)
    assert rating.rate_command(args, "dospcot rate", train) == 0
    # The next round is served at the first one's address: the open page goes on with it.
    assert served == [(0, None), (8765, "kept")] and trained == [tmp_path, tmp_path]
    assert "stopped for 3 new reward queries" in capsys.readouterr().out


def test_the_next_round_is_served_at_the_first_rounds_address(tmp_path, monkeypatch, capsys):
    from dospcot.cli.parser import build_parser
    from dospcot.rating import server

    monkeypatch.setattr(uvicorn.Server, "run", lambda self, sockets: sockets[0].close())
    args = build_parser().parse_args(["rate", str(_fake_run(tmp_path))])
    server.rate(args)
    first = capsys.readouterr().out
    assert args.port and f":{args.port}/?token={args.token} " in first
    server.rate(args)
    assert capsys.readouterr().out == first
