"""The scoring worker (``colonbench serve-worker``, or the workers ``colonbench serve`` starts): off the request
path, any number of them on one database.

A worker **claims** the oldest queued submission with one conditional update (``status`` from ``queued`` to
``scoring`` where it is still ``queued``): of several workers only one sees its update take, so none is scored
twice. While scoring it writes a heartbeat every few seconds. It scores the stored, checked predictions with the
code ``colonbench score`` runs (:func:`colonbench.benchmark.evaluate.evaluate` on a ``predictions:`` method, the
suite's data checked against its signature first), then writes the rows, their summary and ``scored`` in one
transaction; an exception leaves the submission ``failed`` with its reason and no result.

A submission left ``scoring`` by a worker that stopped (killed, its machine gone) is found by every worker when it
starts and between claims: its heartbeat older than ``stale_after`` seconds, or its worker a process of this
machine that no longer runs. It is queued again, or ``failed`` saying so once it was claimed ``max_attempts``
times: never left ``scoring``.
"""

from __future__ import annotations

import datetime as dt
import json
import logging
import os
import socket
import tempfile
import threading
import time
import uuid
from pathlib import Path

from sqlalchemy import select, update

from colonbench.server.db import FAILED, QUEUED, SCORED, SCORING, Result, Submission, engine, now, shown_url

log = logging.getLogger("colonbench.server.worker")


def worker_name() -> str:
    """This worker's name: ``host:pid:random``."""
    return f"{socket.gethostname()}:{os.getpid()}:{uuid.uuid4().hex[:8]}"


def _dead_here(worker: str) -> bool:
    """Whether ``worker`` names a process of this machine that no longer runs."""
    host, _, rest = worker.partition(":")
    pid = rest.partition(":")[0]
    if host != socket.gethostname() or not pid.isdigit():
        return False
    try:
        os.kill(int(pid), 0)
    except ProcessLookupError:
        return True
    except PermissionError:
        return False
    return False


def recover(eng, stale_after: float = 120.0, max_attempts: int = 2) -> list[tuple[str, str]]:
    """Queue again (or fail) every submission left ``scoring`` by a stopped worker; (public id, new status)."""
    from sqlalchemy.orm import Session

    cutoff = now() - dt.timedelta(seconds=stale_after)
    done = []
    with Session(eng) as s:
        rows = s.execute(select(Submission.id, Submission.public_id, Submission.worker, Submission.heartbeat_at,
                                Submission.attempts).where(Submission.status == SCORING)).all()
    for sid, pid, worker, beat, attempts in rows:
        if not ((beat is not None and beat < cutoff) or _dead_here(worker)):
            continue
        if attempts >= max_attempts:
            values = {"status": FAILED, "finished_at": now(),
                      "reason": f"its worker stopped while scoring it, {attempts} time(s); not tried again"}
        else:
            values = {"status": QUEUED, "reason": f"queued again: worker {worker} stopped while scoring it"}
        with eng.begin() as conn:
            taken = conn.execute(update(Submission).where(Submission.id == sid, Submission.status == SCORING,
                                                          Submission.worker == worker).values(**values)).rowcount
        if taken:
            log.warning("submission %s: %s", pid, values["reason"])
            done.append((pid, values["status"]))
    return done


def claim(eng, worker: str) -> int | None:
    """Claim the oldest queued submission for ``worker``: its row id, or None when none is queued."""
    for _ in range(20):
        with eng.connect() as conn:
            sid = conn.execute(select(Submission.id).where(Submission.status == QUEUED)
                               .order_by(Submission.id).limit(1)).scalar()
        if sid is None:
            return None
        with eng.begin() as conn:
            t = now()
            taken = conn.execute(update(Submission).where(Submission.id == sid, Submission.status == QUEUED)
                                 .values(status=SCORING, worker=worker, started_at=t, heartbeat_at=t,
                                         attempts=Submission.attempts + 1)).rowcount
        if taken == 1:
            return sid
    return None


class _Heartbeat(threading.Thread):
    def __init__(self, eng, sid: int, worker: str, every: float):
        super().__init__(daemon=True)
        self.eng, self.sid, self.worker, self.every, self.stop = eng, sid, worker, every, threading.Event()

    def run(self):
        while not self.stop.wait(self.every):
            try:
                with self.eng.begin() as conn:
                    conn.execute(update(Submission).where(Submission.id == self.sid, Submission.worker == self.worker,
                                                          Submission.status == SCORING).values(heartbeat_at=now()))
            except Exception as exc:  # noqa: BLE001  (a missed beat is retried; the scoring goes on)
                log.warning("heartbeat of submission %s: %s", self.sid, exc)


def score_rows(suite, archive: bytes, method: str) -> tuple[list[dict], list[dict], str]:
    """Score a stored predictions archive on a hidden suite as ``colonbench score`` does.

    Returns
    -------
    rows : list of dict
        The per-sample rows of the run folder's results (the method named ``method``).
    summary : list of dict
        :func:`colonbench.benchmark.summary.summarize` of them, one row per noise level.
    signature : str
        The suite's signature digest the data were checked against.
    """
    from colonbench.benchmark.evaluate import evaluate, load_results
    from colonbench.benchmark.summary import summarize
    from colonbench.server.uploads import unpack_canonical

    with tempfile.TemporaryDirectory(prefix="colonbench-score-") as tmp:
        preds = Path(tmp) / "predictions"
        unpack_canonical(archive, preds)
        run = evaluate(suite.folder, [f"submission=predictions:{preds}"], Path(tmp) / "run", noise=suite.noise_mm,
                       split=suite.split, limit=suite.limit, noise_seed=suite.noise_seed, progress=False)
        meta, results = load_results(run)
    if (meta.get("suite") or {}).get("id") != suite.id:
        raise RuntimeError(f"the data scored are not suite {suite.id}")
    results = results.assign(method=method)
    summary = summarize(results).assign(method=method)
    return (json.loads(results.to_json(orient="records")), json.loads(summary.to_json(orient="records")),
            suite.signature)


def process(eng, sid: int, suites: dict, worker: str, beat: float = 5.0, slow: float = 0.0) -> str:
    """Score one claimed submission and record the outcome; ``scored`` or ``failed``."""
    from sqlalchemy.orm import Session

    from colonbench.benchmark.exchange import one_line

    with Session(eng) as s:
        sub = s.get(Submission, sid)
        suite_id, method, archive = sub.suite_id, sub.method, sub.archive
    heart = _Heartbeat(eng, sid, worker, beat)
    heart.start()
    try:
        if slow:
            time.sleep(slow)
        if suite_id not in suites:
            raise RuntimeError(f"suite {suite_id} is not served by this worker")
        rows, summary, signature = score_rows(suites[suite_id], archive, method)
        outcome, reason = SCORED, ""
    except Exception as exc:  # noqa: BLE001  (any failure of a scoring is the submission's reason, never a crash)
        log.exception("submission %s failed", sid)
        outcome, reason = FAILED, one_line(f"{type(exc).__name__}: {exc}", 1000)
    finally:
        heart.stop.set()
        heart.join()
    with Session(eng) as s, s.begin():
        taken = s.execute(update(Submission).where(Submission.id == sid, Submission.worker == worker,
                                                   Submission.status == SCORING)
                          .values(status=outcome, reason=reason, finished_at=now())).rowcount
        if taken and outcome == SCORED:
            s.add(Result(submission_id=sid, suite_id=suite_id, signature=signature, rows_json=json.dumps(rows),
                         summary_json=json.dumps(summary)))
    return outcome if taken else "lost"


def run(url: str, suites: dict, once: bool = False, poll: float = 1.0, stale_after: float = 120.0,
        max_attempts: int = 2, slow: float = 0.0, stop: threading.Event | None = None,
        parent: int | None = None) -> int:
    """Claim and score submissions until stopped (``once``: until none is queued; ``parent``: until the process of
    that id, the ``colonbench serve`` that started this worker, is no longer its parent); how many were
    processed."""
    eng = engine(url)
    worker = worker_name()
    log.info("worker %s on %s, suites %s", worker, shown_url(url), ", ".join(sorted(suites)))
    done = 0
    stop = stop or threading.Event()
    try:
        while not stop.is_set():
            if parent is not None and os.getppid() != parent:
                log.warning("worker %s: its server (process %s) stopped; stopping", worker, parent)
                break
            recover(eng, stale_after, max_attempts)
            sid = claim(eng, worker)
            if sid is None:
                if once:
                    break
                stop.wait(poll)
                continue
            outcome = process(eng, sid, suites, worker, slow=slow)
            log.info("submission %s: %s", sid, outcome)
            done += 1
    finally:
        eng.dispose()
    return done
