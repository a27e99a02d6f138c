"""The scoring workers on a real database: killed mid-scoring and restarted, every submission ends scored or
failed; several at once never score one twice; a scoring that fails leaves its reason and no result."""

from __future__ import annotations

import sqlite3
import subprocess
import sys
import time

import pytest
from server_helpers import Server, prediction, sample_ids, zip_of

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def server(hidden_suite, tmp_path_factory):
    _, private, _, _ = hidden_suite
    srv = Server(private, tmp_path_factory.mktemp("workers") / "server.db", workers=0)
    srv.tok = srv.token("workers")
    srv.private = private
    yield srv
    srv.stop()


def _worker(server, *extra) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "colonbench.cli", "serve-worker", "--db", server.db, "--suites",
                             str(server.private), "--poll", "0.2", *extra], stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL)


def _upload(server, public, n: int) -> list[str]:
    ids = []
    for _ in range(n):
        status, made = server.upload(server.suite, zip_of({f"{i}.json": prediction() for i in sample_ids(public)}),
                                     server.tok)
        assert status == 202, made
        ids.append(made["id"])
    return ids


def _wait_scoring(server, attempt: int = 1, timeout: float = 60) -> str:
    """The submission a worker claimed for the ``attempt``-th time (held by its ``--slow``)."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        rows = server.rows(f"select public_id from submissions where status = 'scoring' and attempts = {attempt}")
        if rows:
            return rows[0][0]
        time.sleep(0.2)
    raise AssertionError("no submission was claimed")


def _kill(proc: subprocess.Popen) -> None:
    proc.kill()
    proc.wait(timeout=30)


def _finish(server, timeout: float = 180) -> None:
    done = subprocess.run([sys.executable, "-m", "colonbench.cli", "serve-worker", "--db", server.db, "--suites",
                           str(server.private), "--once"], capture_output=True, text=True, timeout=timeout)
    assert done.returncode == 0, done.stderr


def _write(server, sql: str, *args) -> None:
    con = sqlite3.connect(server.db_file, timeout=30)
    try:
        con.execute(sql, args)
        con.commit()
    finally:
        con.close()


def test_a_worker_killed_mid_scoring_leaves_nothing_stuck(server, hidden_suite):
    sid, _, public, _ = hidden_suite
    server.suite = sid
    ids = _upload(server, public, 3)
    slow = _worker(server, "--slow", "60")
    try:
        held = _wait_scoring(server)
    finally:
        _kill(slow)
    assert server.rows(f"select status from submissions where public_id = '{held}'") == [("scoring",)]
    _finish(server)
    final = {p: (s, a) for p, s, a in server.rows("select public_id, status, attempts from submissions")}
    assert all(final[i][0] == "scored" for i in ids), final
    assert final[held][1] == 2 and server.rows("select count(*) from results") == [(len(final),)]


def test_a_submission_whose_workers_keep_dying_is_failed_with_its_reason(server, hidden_suite):
    sid, _, public, _ = hidden_suite
    server.suite = sid
    (one,) = _upload(server, public, 1)
    for attempt in (1, 2):
        slow = _worker(server, "--slow", "60")
        try:
            assert _wait_scoring(server, attempt) == one
        finally:
            _kill(slow)
    _finish(server)
    ((status, reason, attempts),) = server.rows(f"select status, reason, attempts from submissions where "
                                                f"public_id = '{one}'")
    assert (status, attempts) == ("failed", 2) and "worker stopped while scoring it" in reason
    assert server.rows(f"select count(*) from results r join submissions s on s.id = r.submission_id "
                       f"where s.public_id = '{one}'") == [(0,)]
    got = server.json("GET", f"/api/v1/submissions/{one}", token=server.tok)[1]
    assert got["status"] == "failed" and got["reason"] == reason and got["summary"] is None


def test_a_stale_heartbeat_of_another_machine_is_queued_again(server, hidden_suite):
    sid, _, public, _ = hidden_suite
    server.suite = sid
    (one,) = _upload(server, public, 1)
    _write(server, "update submissions set status = 'scoring', worker = 'elsewhere:1:dead', attempts = 1, "
                   "heartbeat_at = '2000-01-01 00:00:00' where public_id = ?", one)
    _finish(server)
    assert server.rows(f"select status, attempts from submissions where public_id = '{one}'") == [("scored", 2)]


def test_several_workers_never_score_a_submission_twice(server, hidden_suite):
    sid, _, public, _ = hidden_suite
    server.suite = sid
    before = server.rows("select count(*) from results")[0][0]
    ids = _upload(server, public, 6)
    procs = [subprocess.Popen([sys.executable, "-m", "colonbench.cli", "serve-worker", "--db", server.db, "--suites",
                               str(server.private), "--once"], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
             for _ in range(3)]
    for p in procs:
        assert p.wait(timeout=300) == 0
    rows = {p: (s, a, w) for p, s, a, w in server.rows("select public_id, status, attempts, worker from submissions")}
    assert all(rows[i][:2] == ("scored", 1) for i in ids), rows
    assert server.rows("select count(*) from results")[0][0] == before + 6
    assert server.rows("select count(*) from (select submission_id from results group by submission_id "
                       "having count(*) > 1)") == [(0,)]


def test_a_scoring_that_fails_records_its_reason_and_no_result(server, hidden_suite):
    sid, _, public, _ = hidden_suite
    server.suite = sid
    (one,) = _upload(server, public, 1)
    _write(server, "update submissions set archive = ? where public_id = ?", b"not a zip", one)
    _finish(server)
    ((status, reason),) = server.rows(f"select status, reason from submissions where public_id = '{one}'")
    assert status == "failed" and "BadZipFile" in reason and "Traceback" not in reason
    assert server.rows(f"select count(*) from results r join submissions s on s.id = r.submission_id "
                       f"where s.public_id = '{one}'") == [(0,)]
