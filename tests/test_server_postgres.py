"""The evaluation server on PostgreSQL (psycopg 3): a throwaway cluster on loopback, the real server and workers,
an upload through the real client scored and on the leaderboard, a hostile upload refused with nothing stored,
concurrent uploads of one team within its limit, workers claiming concurrently without scoring one submission
twice, a killed worker's submission finished."""

from __future__ import annotations

import json
import subprocess
import sys
import time

import pytest
from pg_cluster import postgres_url  # noqa: F401  (a fixture)
from server_fixtures import write_predictions
from server_helpers import Server, colonbench, one_utc_day, prediction, sample_ids, zip_of

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def server(hidden_suite, postgres_url, tmp_path_factory):
    _, private, _, _ = hidden_suite
    srv = Server(private, tmp_path_factory.mktemp("pg") / "server.db", workers=1, url=postgres_url)
    srv.private = private
    yield srv
    srv.stop()


def test_the_migrations_match_the_models_on_postgresql(server):
    from test_server_db import _diff

    assert server.rows("select version_num from alembic_version") == [("0001",)]
    assert _diff(server.db) == []


def test_an_upload_is_scored_and_listed(server, hidden_suite, tmp_path):
    sid, _, public, _ = hidden_suite
    token = server.token("pg-team")
    preds = write_predictions(tmp_path / "pg-method", sample_ids(public))
    done = colonbench("submit", "--server", server.url, "--suite", sid, preds, "--public", "--wait", "--poll", "0.3",
                      env={"COLONBENCH_TOKEN": token}, timeout=180)
    assert done.returncode == 0, done.stderr
    got = json.loads(done.stdout.strip().splitlines()[-1])
    assert got["status"] == "scored" and got["summary"][0]["segments"] == 2
    rows = server.json("GET", f"/api/v1/suites/{sid}/leaderboard")[1]["rows"]
    assert got["id"] in {r["id"] for r in rows}
    ((stored,),) = server.rows(f"select r.rows_json from results r join submissions s on s.id = r.submission_id "
                               f"where s.public_id = '{got['id']}'")
    assert len(json.loads(stored)) == 4


def test_a_hostile_upload_stores_nothing(server, hidden_suite):
    sid, _, public, _ = hidden_suite
    token = server.token("pg-mallory")
    before = server.rows("select count(*) from submissions")
    good = {f"{i}.json": prediction() for i in sample_ids(public)}
    status, body = server.upload(sid, zip_of({**good, "../x.json": prediction()}), token,
                                 method="x'); DROP TABLE submissions; --")
    assert status == 400 and body["error"] == "unsafe_entry"
    assert server.rows("select count(*) from submissions") == before


def test_workers_claim_once_and_a_killed_one_leaves_nothing_stuck(server, hidden_suite):
    sid, _, public, _ = hidden_suite
    token = server.token("pg-load")
    data = zip_of({f"{i}.json": prediction() for i in sample_ids(public)})
    base = ["serve-worker", "--db", server.db, "--suites", str(server.private)]
    slow = subprocess.Popen([sys.executable, "-m", "colonbench.cli", *base, "--slow", "60", "--poll", "0.2"],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        ids = [server.upload(sid, data, token)[1]["id"] for _ in range(5)]
        end = time.monotonic() + 60
        while time.monotonic() < end and not server.rows(
                "select 1 from submissions where status = 'scoring' and worker like '%:" + str(slow.pid) + ":%'"):
            time.sleep(0.2)
    finally:
        slow.kill()
        slow.wait(timeout=30)
    procs = [subprocess.Popen([sys.executable, "-m", "colonbench.cli", *base, "--once"], stdout=subprocess.DEVNULL,
                              stderr=subprocess.DEVNULL) for _ in range(2)]
    for p in procs:
        assert p.wait(timeout=300) == 0
    final = server.wait_final()
    assert {p: s for p, s, _ in final if p in ids} == {i: "scored" for i in ids}
    assert server.rows("select count(*) from (select submission_id from results group by submission_id "
                       "having count(*) > 1) t") == [(0,)]


def test_concurrent_uploads_of_one_team_keep_its_limit(server, hidden_suite):
    from concurrent.futures import ThreadPoolExecutor

    sid, _, public, _ = hidden_suite
    data = zip_of({f"{i}.json": prediction() for i in sample_ids(public)})

    def race(k):
        server.admin("team", "set", f"pg-racing{k}", "--daily", 3)
        token = server.token(f"pg-racing{k}")
        with ThreadPoolExecutor(8) as pool:
            return sorted(pool.map(lambda _: server.upload(sid, data, token)[0], range(8)))

    assert one_utc_day(race) == [202] * 3 + [429] * 5
    server.wait_final()
