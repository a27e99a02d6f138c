"""The evaluation server end to end: the real server (uvicorn on loopback, a SQLite file, a real worker), uploads
through the real client, the scored row, the JSON API and the page; accounts, limits and the truth never served."""

from __future__ import annotations

import csv
import gzip
import json
import time

import pytest
from server_fixtures import write_predictions
from server_helpers import Server, colonbench, one_utc_day, prediction, sample_ids, zip_of

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def server(hidden_suite, tmp_path_factory):
    _, private, _, _ = hidden_suite
    srv = Server(private, tmp_path_factory.mktemp("server") / "server.db")
    yield srv
    srv.stop()


def _all(public) -> bytes:
    return zip_of({f"{i}.json": prediction(0.6) for i in sample_ids(public)})


def test_the_client_uploads_and_reads_the_scored_row(server, hidden_suite, tmp_path):
    sid, private, public, _ = hidden_suite
    token = server.token("alpha")
    preds = write_predictions(tmp_path / "mine", sample_ids(public), coverage=0.5)
    (tmp_path / "token").write_text(token)
    t = time.monotonic()
    done = colonbench("submit", "--server", server.url, "--suite", sid, preds, "--public", "--wait", "--poll", "0.3",
                      "--version", "1.0", "--token-file", tmp_path / "token", timeout=180)
    assert done.returncode == 0, done.stderr
    assert "scored" in done.stdout and "MAE" in done.stdout
    got = json.loads(done.stdout.strip().splitlines()[-1])
    print(f"upload to scored row: {time.monotonic() - t:.1f} s")
    # the same rows colonbench score writes, stored in the database under the method's name
    assert colonbench("score", sid, preds, "--out", tmp_path / "run", "--data", private, "--quiet").returncode == 0
    mine = {r["sample_id"]: r for r in csv.DictReader(open(tmp_path / "run" / "results" / "mine.csv"))}
    (rows_json, summary_json, signature), = server.rows(
        "select r.rows_json, r.summary_json, r.signature from results r join submissions s on s.id = r.submission_id "
        f"where s.public_id = '{got['id']}'")
    stored = {r["sample_id"]: r for r in json.loads(rows_json)}
    assert set(stored) == set(mine) and len(stored) == 4
    for k, r in stored.items():
        assert r["method"] == "mine" and r["coverage_error"] == pytest.approx(float(mine[k]["coverage_error"]))
    assert got["summary"][0]["coverage_mae"] == pytest.approx(json.loads(summary_json)[0]["coverage_mae"])
    assert "true_coverage" not in done.stdout
    # the JSON API and the page
    status, board = server.json("GET", f"/api/v1/suites/{sid}/leaderboard")
    row = next(r for r in board["rows"] if r["id"] == got["id"])
    assert status == 200 and row["method"] == "mine" and row["version"] == "1.0" and row["team"] == "alpha"
    assert "signature" not in row       # a digest of the truth: never published
    status, page = server.get(f"/suites/{sid}")
    assert status == 200 and b"mine" in page and b"alpha" in page and signature.encode() not in page
    # the audit log has the token's creation and the upload
    lines = server.rows("select actor, action, outcome from audit_log")
    assert ("admin", "token.create", "ok") in lines and ("team alpha", "upload", "accepted") in lines


def test_status_without_waiting_and_private_submissions(server, hidden_suite, tmp_path):
    sid, _, public, _ = hidden_suite
    token = server.token("beta")
    preds = write_predictions(tmp_path / "secret-method", sample_ids(public))
    done = colonbench("submit", "--server", server.url, "--suite", sid, preds, env={"COLONBENCH_TOKEN": token})
    assert done.returncode == 0 and "private" in done.stdout
    pid = done.stdout.split()[1].rstrip(":")
    server.wait_final()
    done = colonbench("submit", "--server", server.url, "--status", pid, env={"COLONBENCH_TOKEN": token})
    assert done.returncode == 0 and "scored" in done.stdout
    board = server.json("GET", f"/api/v1/suites/{sid}/leaderboard")[1]
    assert pid not in {r["id"] for r in board["rows"]}
    assert b"secret-method" not in server.get(f"/suites/{sid}")[1]


def test_the_token_is_never_taken_on_the_command_line(server, hidden_suite, tmp_path):
    sid, _, public, _ = hidden_suite
    done = colonbench("submit", "--server", server.url, "--suite", sid, tmp_path, env={"COLONBENCH_TOKEN": ""})
    assert done.returncode == 2 and "COLONBENCH_TOKEN" in done.stderr and "Traceback" not in done.stderr
    secret = "cbt_" + "7e57" * 16
    for given in (["--token", secret], [f"--token={secret}"]):
        done = colonbench("submit", "--server", server.url, "--suite", sid, tmp_path, *given)
        assert done.returncode == 2 and "never the command line" in done.stderr
        assert secret not in done.stdout + done.stderr


def test_wrong_revoked_and_expired_tokens_are_refused(server, hidden_suite):
    sid, _, public, _ = hidden_suite
    before = server.rows("select count(*) from submissions")
    for bad in ("cbt_" + "0" * 64, "nonsense", ""):
        status, body = server.upload(sid, _all(public), bad)
        assert status == 401 and body["error"] == "bad_token"
    token = server.token("gamma")
    (tid,) = [line.split()[0] for line in server.admin("token", "list").splitlines() if "gamma" in line]
    server.admin("token", "revoke", tid)
    assert server.upload(sid, _all(public), token)[0] == 401
    short = server.token("delta", "--expires-days", 1 / 86400)   # one second
    time.sleep(1.5)
    assert server.upload(sid, _all(public), short)[0] == 401
    assert server.json("GET", "/api/v1/submissions", token=short)[0] == 401
    assert server.rows("select count(*) from submissions") == before
    assert ("unknown token", "upload", "refused") in server.rows("select actor, action, outcome from audit_log")


def test_another_teams_submission_is_not_found(server, hidden_suite):
    sid, _, public, _ = hidden_suite
    a, b = server.token("team-a"), server.token("team-b")
    status, made = server.upload(sid, _all(public), a, public=False)
    assert status == 202, made
    assert server.json("GET", f"/api/v1/submissions/{made['id']}", token=a)[0] == 200
    status, body = server.json("GET", f"/api/v1/submissions/{made['id']}", token=b)
    assert status == 404 and body["error"] == "unknown_submission"
    assert made["id"] not in {s["id"] for s in server.json("GET", "/api/v1/submissions", token=b)[1]["submissions"]}
    server.wait_final()


def test_daily_and_total_limits_hold(server, hidden_suite):
    sid, _, public, _ = hidden_suite

    def daily(k):
        server.admin("team", "set", f"limited{k}", "--daily", 2)
        token = server.token(f"limited{k}")
        statuses = [server.upload(sid, _all(public), token)[0] for _ in range(3)]
        # over its limit, an upload is refused before the server unpacks and checks it
        return statuses, server.upload(sid, b"not even a zip", token)

    statuses, (status, body) = one_utc_day(daily)
    assert statuses == [202, 202, 429] and (status, body["error"]) == (429, "daily_limit")
    server.admin("team", "set", "capped", "--total", 1)
    token = server.token("capped")
    assert server.upload(sid, _all(public), token)[0] == 202
    status, body = server.upload(sid, _all(public), token)
    assert status == 429 and body["error"] == "total_limit"
    status, body = server.upload(sid, b"not even a zip", token)
    assert status == 429 and body["error"] == "total_limit"
    counts = dict(server.rows("select t.name, count(*) from submissions s join teams t on t.id = s.team_id "
                              "group by t.name"))
    assert counts[next(t for t in ("limited1", "limited0") if t in counts)] == 2 and counts["capped"] == 1
    server.wait_final()


def test_concurrent_uploads_of_one_team_keep_its_limit(server, hidden_suite):
    from concurrent.futures import ThreadPoolExecutor

    sid, _, public, _ = hidden_suite
    data = _all(public)

    def race(k):
        server.admin("team", "set", f"racing{k}", "--daily", 3)
        token = server.token(f"racing{k}")
        with ThreadPoolExecutor(8) as pool:
            statuses = sorted(pool.map(lambda _: server.upload(sid, data, token)[0], range(8)))
        return k, statuses

    k, statuses = one_utc_day(race)
    assert statuses == [202] * 3 + [429] * 5
    assert server.rows("select count(*) from submissions s join teams t on t.id = s.team_id "
                       f"where t.name = 'racing{k}'") == [(3,)]
    server.wait_final()


def test_a_method_name_with_html_is_escaped_on_the_page(server, hidden_suite):
    sid, _, public, _ = hidden_suite
    token = server.token("html")
    name = '<script>alert("x")</script><img src=x onerror=alert(1)>'
    assert server.upload(sid, _all(public), token, method=name, version="<b>v</b>")[0] == 202
    server.wait_final()
    page = server.get(f"/suites/{sid}")[1].decode()
    assert "<script>alert" not in page and "<img" not in page and "<b>v" not in page
    assert page.count("<script>") == 1                  # the page's own table sorter, as on the static site
    assert "&lt;script&gt;alert(&#34;x&#34;)&lt;/script&gt;" in page and "&lt;b&gt;v&lt;/b&gt;" in page
    board = server.json("GET", f"/api/v1/suites/{sid}/leaderboard")[1]
    assert name in {r["method"] for r in board["rows"]}     # kept as given, escaped where shown


def test_no_route_serves_the_truth(server, hidden_suite):
    sid, private, public, seed = hidden_suite
    token = server.token("walker")
    status, made = server.upload(sid, _all(public), token, public=True)
    assert status == 202
    server.wait_final()
    signature = json.loads(gzip.decompress((private / sid / "signature.json.gz").read_bytes()))
    truths = {f"{s['coverage']:.6f}"[:8] for s in signature["samples"]}
    (rows_json,) = server.rows("select rows_json from results")[0]
    truths |= {repr(r["true_coverage"])[:10] for r in json.loads(rows_json)}
    built = json.loads((private / sid / "built-suite.json").read_text())
    truths |= {built["signature"], built["sha256"].removeprefix("cb1-")}     # digests of the truth
    routes = ["/", f"/suites/{sid}", "/api/v1/health", "/api/v1/suites", f"/api/v1/suites/{sid}/leaderboard",
              "/api/v1/submissions", f"/api/v1/submissions/{made['id']}", f"/suites/{sid}/signature.json.gz",
              f"/{sid}/manifest.yaml", "/static/../../etc/passwd", f"/api/v1/suites/{sid}/truth"]
    for route in routes:
        for tok in (None, token):
            for method in ("GET", "POST"):
                status, body = server.request(method, route, token=tok)
                text = body.decode("utf-8", "replace")
                assert status < 500, (route, status)
                for bad in ["true_coverage", "hole_points", "partial_points", ".h5", "signature.json", "manifest.yaml",
                            str(seed), "noise_seed", "rows_json", *truths]:
                    assert bad not in text, (method, route, bool(tok), bad)


@pytest.mark.parametrize("how", ["SIGTERM", "SIGKILL"])
def test_the_servers_workers_stop_with_it(hidden_suite, tmp_path, how):
    psutil = pytest.importorskip("psutil")

    _, private, _, _ = hidden_suite
    srv = Server(private, tmp_path / "s.db", workers=2)
    workers = psutil.Process(srv.proc.pid).children()
    assert len(workers) == 2
    # the database URL (which may hold a password) reaches them by the environment, not in their argv
    assert all(srv.db not in " ".join(p.cmdline()) for p in workers)
    if how == "SIGKILL":
        srv.proc.kill()
        srv.proc.wait(timeout=30)
    srv.stop()
    gone, alive = psutil.wait_procs(workers, timeout=30)
    for p in alive:     # a failure: stop them anyway, then say so
        p.kill()
    assert not alive, f"workers left running after the server's {how}"
