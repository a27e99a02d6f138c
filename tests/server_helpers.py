"""The real evaluation server in tests: uvicorn on a free loopback port in a subprocess, a real SQLite file, real
worker processes; every wait bounded, every process stopped by the test that started it."""

from __future__ import annotations

import contextlib
import datetime as dt
import io
import json
import os
import signal
import socket
import sqlite3
import subprocess
import sys
import time
import urllib.error
import urllib.request
import zipfile
from pathlib import Path

from colonbench.cli import main


def free_port() -> int:
    """A port free on 127.0.0.1 now."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def colonbench(*args, env=None, timeout: float = 120) -> subprocess.CompletedProcess:
    """``colonbench ARGS`` in a subprocess, its output captured."""
    return subprocess.run([sys.executable, "-m", "colonbench.cli", *map(str, args)], capture_output=True, text=True,
                          timeout=timeout, env={**os.environ, **(env or {})})


class Server:
    """``colonbench serve`` on a free loopback port over a SQLite file, stopped by :meth:`stop`."""

    def __init__(self, suites: Path, db_file: Path, workers: int = 1, extra=(), url: str | None = None):
        self.db = url or f"sqlite:///{db_file}"
        self.db_file = db_file     # with a url: where the log goes
        self.port = free_port()
        self.url = f"http://127.0.0.1:{self.port}"
        self.log = open(db_file.with_suffix(".log"), "w")
        try:
            self.proc = subprocess.Popen([sys.executable, "-m", "colonbench.cli", "serve", "--suites", str(suites),
                                          "--db", self.db, "--port", str(self.port), "--workers", str(workers),
                                          *extra], stdout=self.log, stderr=subprocess.STDOUT)
        except BaseException:
            self.log.close()
            raise
        try:
            self._wait_up(60)
        except BaseException:
            self.stop()     # stops the process where it runs and closes its log
            raise

    def _wait_up(self, timeout: float) -> None:
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            if self.proc.poll() is not None:
                raise RuntimeError(f"the server stopped: {self.db_file.with_suffix('.log').read_text()[-2000:]}")
            with contextlib.suppress(OSError):
                if self.get("/api/v1/health")[0] == 200:
                    return
            time.sleep(0.2)
        raise RuntimeError(f"the server did not answer within {timeout:g} s")

    def request(self, method: str, path: str, body: bytes | None = None, token: str | None = None,
                headers=None) -> tuple[int, bytes]:
        h = dict(headers or {})
        if token:
            h["Authorization"] = f"Bearer {token}"
        req = urllib.request.Request(self.url + path, data=body, method=method, headers=h)
        try:
            with urllib.request.urlopen(req, timeout=60) as r:
                return r.status, r.read()
        except urllib.error.HTTPError as exc:
            return exc.code, exc.read()

    def get(self, path: str, token: str | None = None) -> tuple[int, bytes]:
        return self.request("GET", path, token=token)

    def json(self, method: str, path: str, **kw) -> tuple[int, dict]:
        status, raw = self.request(method, path, **kw)
        return status, json.loads(raw)

    def upload(self, suite: str, data: bytes, token: str, method: str = "m", version: str = "",
               public: bool = True) -> tuple[int, dict]:
        from urllib.parse import quote, urlencode

        q = urlencode({"method": method, "version": version, "public": int(public)})
        return self.json("POST", f"/api/v1/suites/{quote(suite, safe='')}/submissions?{q}", body=data, token=token,
                         headers={"Content-Type": "application/zip"})

    def token(self, team: str, *extra) -> str:
        """A new token of ``team`` through ``colonbench serve-admin`` (in this process)."""
        out = io.StringIO()
        with contextlib.redirect_stdout(out):
            assert main(["serve-admin", "--db", self.db, "token", "create", "--team", team, *map(str, extra)]) == 0
        return out.getvalue().strip().splitlines()[-1]

    def admin(self, *args) -> str:
        out = io.StringIO()
        with contextlib.redirect_stdout(out):
            assert main(["serve-admin", "--db", self.db, *map(str, args)]) == 0
        return out.getvalue()

    def rows(self, sql: str) -> list[tuple]:
        """Rows of a query on the server's database (read only on SQLite)."""
        if self.db.startswith("sqlite"):
            con = sqlite3.connect(f"file:{self.db_file}?mode=ro", uri=True, timeout=30)
            try:
                return con.execute(sql).fetchall()
            finally:
                con.close()
        from sqlalchemy import text

        from colonbench.server.db import engine

        eng = engine(self.db)
        try:
            with eng.connect() as conn:
                return [tuple(r) for r in conn.execute(text(sql)).all()]
        finally:
            eng.dispose()

    def wait_final(self, timeout: float = 120) -> list[tuple]:
        """Wait until no submission is queued or scoring; every (public id, status, reason)."""
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            rows = self.rows("select public_id, status, reason from submissions")
            if all(r[1] in ("scored", "failed") for r in rows):
                return rows
            time.sleep(0.3)
        raise AssertionError(f"submissions not final after {timeout} s: {rows}")

    def stop(self) -> None:
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
            try:
                self.proc.wait(timeout=30)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        self.log.close()


def one_utc_day(attempt):
    """``attempt(k)`` run again (k = 1) if a UTC midnight fell inside its first run (k = 0), which a daily limit
    counts from: its result on one day."""
    for k in range(2):
        day = dt.datetime.now(dt.timezone.utc).date()
        got = attempt(k)
        if dt.datetime.now(dt.timezone.utc).date() == day:
            return got
    raise AssertionError("two UTC midnights in two runs of a test")


def zip_of(files: dict, symlinks=()) -> bytes:
    """A zip of ``name -> bytes`` (and ``name -> target`` symbolic links)."""
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as zf:
        for name, data in files.items():
            zf.writestr(name, data)
        for name, target in symlinks:
            info = zipfile.ZipInfo(name)
            info.create_system = 3
            info.external_attr = (0o120777 << 16)
            zf.writestr(info, target)
    return buf.getvalue()


def prediction(coverage: float = 0.5) -> bytes:
    return json.dumps({"coverage": coverage, "holes": [[0.0, 0.0, 1.0]],
                       "centerline": [[0.0, 0.0, 0.0], [0.0, 0.0, 1.0]]}).encode()


def sample_ids(public: Path) -> list[str]:
    import csv

    with open(public / "index.csv") as f:
        return sorted(r["sample_id"] for r in csv.DictReader(f))
