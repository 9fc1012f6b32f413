"""The server of the rating page (``dospcot rate RUN_DIR``, docs/guide/rating.md): a Starlette app run
by uvicorn that shows a run's waiting reward queries one at a time and writes each answer to the
round's CSV as it is given.

It stays a local tool: it listens on 127.0.0.1 unless told otherwise; every request carries the random
token printed with the address, whatever the host; it serves only the files under the run's
``queries/`` folder; and an answer for a sample outside the round, or a reward that is not a finite
number a float32 holds, is refused with one line. A reward not seen in an earlier round is kept only
once the person confirms it, as in the CSV (:mod:`dospcot.raters.answer_files`).
"""

from __future__ import annotations

import argparse
import csv
import ipaddress
import secrets
import socket
import sys
import threading
from importlib.resources import files
from pathlib import Path
from typing import Any

from dospcot.raters.answer_files import (
    ROUND_FILE,
    RaterError,
    accept_values,
    confirmed,
    parse_reward,
    read_rows,
    rewards_seen,
    round_of,
    sample_number,
    show,
    write_rows,
)
from dospcot.run.run_folder import QUERIES_FILE, run_lock
from dospcot.run.run_session import QUERIES_FOLDER

ANSWERED_LOG = QUERIES_FILE
"""The run's log of the answers it read."""
FRAME_COLUMNS = {"frame": "before the step", "next_frame": "after the step"}


def waiting_round(run_dir: Path) -> Path:
    """The query file whose answers the run waits on: its newest round, if the run has not read it.

    :raises RaterError: no such file.
    """
    folder = run_dir / QUERIES_FOLDER
    if (run_dir / "config.toml").exists() and not (run_dir / "config.toml").is_file():
        raise RaterError(f"{run_dir / 'config.toml'} is not a file (a folder?): give a run folder")
    if not (run_dir / "config.toml").is_file():
        raise RaterError(f"{run_dir} is not a run folder (it has no config.toml)")
    paths = sorted(folder.glob("round_*.csv"), key=lambda p: (len(p.name), p.name))
    if not paths:
        raise RaterError(
            f"{run_dir}: no reward queries wait there (no {QUERIES_FOLDER}/round_<r>.csv): a run with "
            'training.rater = "file" and an active label strategy writes them'
        )
    path, log = paths[-1], run_dir / ANSWERED_LOG
    if log.is_file():
        with log.open(newline="") as handle:
            read = {row.get("round") for row in csv.DictReader(handle)}
        if str(round_of(path)) in read:
            raise RaterError(
                f"{run_dir}: the run read the answers of round {round_of(path)} already; nothing waits"
            )
    return path


class RoundAnswers:
    """A round's query file, read and written by one request at a time.

    :param path: ``<run>/queries/round_<r>.csv``.
    """

    def __init__(self, path: Path) -> None:
        self.path, self.folder, self.round = path, path.parent, round_of(path)
        self.run_dir = self.folder.parent
        self.seen = rewards_seen(self.folder, self.round)
        """The rewards of the earlier rounds' answers: the values that need no confirmation."""
        self.lock = threading.Lock()
        fields, rows, comma = self._rows()
        self.samples = [sample for sample, _ in rows]
        """The round's queries in the file's order; no other sample is answered."""
        if not self.samples:
            raise RaterError(
                f"{path} holds no query (the run writes a row for each): it was emptied since; restore "
                f"it, or delete it and resume the run to ask again: dospcot train --resume {self.run_dir}"
            )
        self.views = [f.removesuffix("_predicts") for f in fields if f.endswith("_predicts")]
        self.order: list[float] = _first_answered(self.folder, self.round)
        """Every known value in the order it became known (earlier rounds first): the page's number keys
        follow it, so a new value takes the next key and no key ever changes its value."""
        self._known([row for _, row in rows], comma)

    def _rows(self) -> tuple[list[str], list[tuple[int, dict[str, str]]], bool]:
        """The file's columns, its rows with their sample numbers, and whether it is ``;`` separated.

        :raises RaterError: a row without a sample number (the file was edited by hand).
        """
        fields, rows, comma = read_rows(self.path)
        numbered = []
        for line, row in rows:
            try:
                numbered.append((sample_number(row.get("sample") or ""), row))
            except ValueError:
                raise RaterError(
                    f"{self.path} line {line}: {row.get('sample')!r} in the sample column is not a sample "
                    "number; restore the number the run wrote"
                ) from None
        return fields, numbered, comma

    def _known(self, rows: list[dict[str, str]], comma: bool) -> list[float]:
        """The values a person may give at one keystroke: the earlier rounds', this round's confirmed and
        those confirmed on this page since it started (an answer changed since keeps its value's key), in
        the order they became known (:attr:`order`, which a value new here joins at its end)."""
        known = set(self.seen)
        for row in rows:
            try:
                value = parse_reward(row.get("reward") or "", comma)
            except ValueError:
                continue
            if value in known or confirmed(row):
                known.add(value)
        self.order += [value for value in sorted(known) if value not in self.order]
        return list(self.order)

    def state(self, token: str) -> dict[str, Any]:
        """The round as the page shows it."""
        with self.lock:
            _, rows, comma = self._rows()
        rows_ = [row for _, row in rows]
        queries = []
        for sample, row in rows:
            frames, text = [], None
            for column, caption in FRAME_COLUMNS.items():
                value = row.get(column) or ""
                if value.endswith(".png") and "\n" not in value:
                    frames.append({"caption": caption, "url": f"files/{value}?token={token}"})
                elif value:
                    text = value
            queries.append(
                {
                    "sample": sample,
                    "key": row.get("key", ""),
                    "frames": frames,
                    "text_frame": text,
                    "predictions": [
                        {
                            "view": v,
                            "predicts": row.get(f"{v}_predicts", ""),
                            "confidence": row.get(f"{v}_confidence", ""),
                        }
                        for v in self.views
                    ],
                    "reward": (row.get("reward") or "").strip(),
                }
            )
        known = self._known(rows_, comma)
        return {
            "round": self.round,
            "path": str(self.path),
            "run_dir": str(self.run_dir),
            "resume": f"dospcot train --resume {self.run_dir}",
            "seen": [{"value": v, "text": show(v)} for v in known],
            "queries": queries,
        }

    def answer(self, sample: Any, text: Any, confirm: bool) -> dict[str, Any]:
        """Write ``text`` as the reward of ``sample`` to the file at once (atomically).

        :raises RaterError: a sample outside the round, or a reward that is no finite number.
        :raises NewReward: a value not seen before, unless ``confirm``.
        """
        if isinstance(sample, str) and sample.strip().isdigit():
            sample = int(sample)
        if isinstance(sample, bool) or not isinstance(sample, int):  # 98.5 is no sample, nor is true
            raise RaterError(f"{sample!r} is not a sample number (a whole number from the round's file)")
        if sample not in self.samples:
            raise RaterError(
                f"sample {sample} is not one of round {self.round}'s {len(self.samples)} queries"
            )
        text = str(text).strip()
        try:
            value = parse_reward(text)
        except ValueError as err:
            why = str(err) if str(err).startswith("is ") else f"{text!r} is not a number"
            raise RaterError(
                f"the reward of sample {sample}: {why.removeprefix('is ')}; answer with a number"
            ) from None
        with self.lock:  # two tabs: one writes after the other, and the last answer stays
            fields, rows, comma = self._rows()
            rows_ = [row for _, row in rows]
            if sample not in [s for s, _ in rows]:
                raise RaterError(f"sample {sample} is no longer in {self.path}: restore its row")
            known = self._known(rows_, comma)
            if value not in known and confirm:
                self.order.append(value)  # the next free key, before the file's order could say otherwise
            if value not in known and not confirm:
                listed = ", ".join(show(v) for v in known) or "none yet"
                raise NewReward(f"{show(value)} is a new reward value (seen so far: {listed})")
            for row_sample, row in rows:
                if row_sample == sample:
                    row["reward"] = text
                # A new value is confirmed on every row that gives it, so it stays so when one row changes.
                try:
                    row_value = parse_reward(row.get("reward") or "", comma)
                except ValueError:
                    continue
                if row_value == value and value not in self.seen:
                    row["confirm_new"] = "yes"
            write_rows(self.path, list(dict.fromkeys([*fields, "confirm_new"])), rows_, comma)
        return {"sample": sample, "reward": text}


def _first_answered(folder: Path, round_: int) -> list[float]:
    """The distinct rewards answered in the rounds before ``round_``, in the order they were first
    given (round by round, row by row)."""
    order: list[float] = []
    paths = [p for p in folder.glob("round_*.csv") if ROUND_FILE.fullmatch(p.name) and round_of(p) < round_]
    for path in sorted(paths, key=round_of):
        _, rows, comma = read_rows(path)
        for _, row in rows:
            try:
                value = parse_reward(row.get("reward") or "", comma)
            except ValueError:
                continue
            if value not in order:
                order.append(value)
    return order


class NewReward(RaterError):
    """A reward value not seen before, which the person has not confirmed."""


def make_app(answers: RoundAnswers, token: str, then_train: bool = False) -> Any:
    """The Starlette app of the page: ``/`` (the page), ``/api/round``, ``/api/answer``, ``/api/resume``
    and ``/files/<path under queries/>``; each refuses a request without ``token``."""
    from starlette.applications import Starlette
    from starlette.middleware import Middleware
    from starlette.middleware.base import BaseHTTPMiddleware
    from starlette.requests import Request
    from starlette.responses import FileResponse, HTMLResponse, JSONResponse, Response
    from starlette.routing import Route

    page = files("dospcot.rating").joinpath("page.html").read_text(encoding="utf-8")
    folder = answers.folder.resolve()

    async def require_token(request: Request, call_next: Any) -> Response:
        given = request.query_params.get("token") or request.headers.get("x-token") or ""
        if not secrets.compare_digest(given.encode(), token.encode()):
            return JSONResponse(
                {"error": "a missing or wrong token: open the address dospcot rate printed, token included"},
                status_code=403,
            )
        return await call_next(request)

    def error(err: Exception, status: int = 400) -> JSONResponse:
        return JSONResponse({"error": str(err), "confirm": isinstance(err, NewReward)}, status_code=status)

    async def index(request: Request) -> HTMLResponse:
        return HTMLResponse(page, headers={"Cache-Control": "no-store", "Referrer-Policy": "no-referrer"})

    async def state(request: Request) -> JSONResponse:
        try:
            return JSONResponse({**answers.state(token), "then_train": then_train})
        except RaterError as err:  # the file was edited by hand meanwhile
            return error(err)

    async def answer(request: Request) -> JSONResponse:
        try:
            body = await request.json()
        except ValueError:
            return error(RaterError("the request's body is not JSON"))
        if not isinstance(body, dict):
            return error(RaterError("the request's body is not a JSON object"))
        try:
            done = answers.answer(body.get("sample"), body.get("reward", ""), bool(body.get("confirm")))
        except NewReward as err:
            return error(err, 409)
        except RaterError as err:
            return error(err)
        return JSONResponse(done)

    async def resume(request: Request) -> JSONResponse:
        if not then_train:
            return error(
                RaterError(
                    f"the server resumes nothing without --then-train: {answers.state(token)['resume']}"
                )
            )
        open_ = [q["sample"] for q in answers.state(token)["queries"] if not q["reward"]]
        if open_:
            return error(RaterError(f"{len(open_)} queries have no answer yet (e.g. sample {open_[0]})"))
        request.app.state.resume = True
        request.app.state.server.should_exit = True
        return JSONResponse({"resuming": str(answers.run_dir)})

    async def serve_file(request: Request) -> Response:
        wanted = (folder / request.path_params["path"]).resolve()
        if not wanted.is_relative_to(folder) or not wanted.is_file():
            return JSONResponse(
                {"error": f"only the files under {answers.folder} are served"}, status_code=404
            )
        return FileResponse(wanted)

    routes = [
        Route("/", index),
        Route("/api/round", state),
        Route("/api/answer", answer, methods=["POST"]),
        Route("/api/resume", resume, methods=["POST"]),
        Route("/files/{path:path}", serve_file),
    ]
    app = Starlette(routes=routes, middleware=[Middleware(BaseHTTPMiddleware, dispatch=require_token)])
    app.state.resume = False
    return app


def _listen(host: str, port: int) -> socket.socket:
    """A socket bound to ``host``:``port`` (0: a free port)."""
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    sock = socket.socket(family, socket.SOCK_STREAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    try:
        sock.bind((host, port))
        sock.listen(128)  # a request sent as soon as the address is printed waits, not refused
    except OSError as err:
        sock.close()
        raise RaterError(
            f"cannot listen on {host}:{port} ({err.strerror}); give another --port or --host"
        ) from None
    return sock


def rate(args: argparse.Namespace) -> bool:
    """``dospcot rate``: serve the run's waiting queries until Ctrl-C, or until the page asks to resume
    (``--then-train``); with ``--accept``, confirm new reward values in the CSV instead.

    :return: whether the page asked to resume the run.
    :raises RaterError: one line: no waiting queries, a port in use, the rate extra missing.
    """
    path = waiting_round(args.run_dir)
    if args.accept:
        count = accept_values(path, args.accept)
        print(f"{path}: confirmed {', '.join(show(v) for v in args.accept)} as new rewards on {count} rows")
        return False
    try:
        import uvicorn  # noqa: F401 - the rate extra, checked before anything is served
    except ImportError:
        raise RaterError("dospcot rate needs the rate extra: pip install 'dospcot[rate]'") from None
    answers = RoundAnswers(path)
    # One server per run: two would both write the round's file, each over the other's answers.
    with run_lock(answers.folder, "rated", RaterError):
        return _serve(args, answers, path)


def _serve(args: argparse.Namespace, answers: RoundAnswers, path: Path) -> bool:
    """Serve ``answers`` until Ctrl-C or until the page asks to resume; return whether it asked."""
    import uvicorn

    # The next round (--then-train) is served at the same address: the open page goes on with it.
    token = getattr(args, "token", None) or secrets.token_urlsafe(24)
    if not _is_local(args.host):
        print(
            f"dospcot rate: warning: --host {args.host} serves the page to other machines too; the token in "
            "its address is all that keeps them out (use 127.0.0.1 unless a rater works elsewhere)",
            file=sys.stderr,
        )
    sock = _listen(args.host, args.port)
    app = make_app(answers, token, args.then_train)
    server = uvicorn.Server(uvicorn.Config(app, log_level="warning", access_log=False, lifespan="off"))
    app.state.server = server
    host, port = sock.getsockname()[:2]
    args.token, args.port = token, port
    shown = f"[{host}]" if ":" in host else host
    left = sum(1 for q in answers.state(token)["queries"] if not q["reward"])
    print(
        f"{args.run_dir}: {len(answers.samples)} reward queries of round {answers.round} ({left} unanswered) "
        f"on http://{shown}:{port}/?token={token} ; each answer goes to {path} as it is given; Ctrl-C stops",
        flush=True,
    )
    server.run(sockets=[sock])
    return bool(app.state.resume)


def _is_local(host: str) -> bool:
    """Whether ``host`` is this machine's loopback address, which no other machine reaches."""
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:
        return False
