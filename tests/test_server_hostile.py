"""Hostile uploads to the real server: each refused with a 4xx JSON error naming the problem, nothing stored (no
submission row, no result), the refusal in the audit log; SQL metacharacters in every text field kept as text."""

from __future__ import annotations

import io
import json
import os
import zipfile

import pytest
from server_helpers import Server, prediction, sample_ids, zip_of

pytestmark = pytest.mark.slow
SQL = "x'); DROP TABLE submissions; -- \" OR 1=1 /*"


@pytest.fixture(scope="module")
def server(hidden_suite, tmp_path_factory):
    _, private, _, _ = hidden_suite
    # a 1 MiB upload cap and 500 entries, so the oversize and many-files cases stay small and quick
    srv = Server(private, tmp_path_factory.mktemp("hostile") / "server.db",
                 extra=["--max-upload-mb", "1", "--max-files", "500"])
    srv.tok = srv.token("mallory")
    yield srv
    srv.stop()


def _good(public) -> dict:
    return {f"{i}.json": prediction() for i in sample_ids(public)}


def _bomb() -> bytes:
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED, compresslevel=9) as zf:
        zf.writestr("bomb.json", b"0" * (20 * 2 ** 20))    # 20 MiB of one byte packs to about 20 KiB
    return buf.getvalue()


def _cases(public) -> dict:
    ids = sample_ids(public)
    good = _good(public)
    return {
        "dotdot": (zip_of({**good, "../evil.json": prediction()}), 400, "unsafe_entry", "outside the archive"),
        "absolute": (zip_of({**good, "/etc/evil.json": prediction()}), 400, "unsafe_entry", "absolute"),
        "symlink": (zip_of(good, symlinks=[("link.json", "/etc/passwd")]), 400, "unsafe_entry", "symbolic link"),
        "bomb": (_bomb(), 413, "zip_bomb", "times its packed size"),
        "oversize": (os.urandom(2 ** 20 + 10), 413, "too_large", "over 1048576 bytes"),
        "many_files": (zip_of({f"f{k}.json": b"{}" for k in range(10_000)}), 413, "too_many_files", "10000 entries"),
        "not_a_zip": (b"PK\x03\x04 not really a zip", 400, "not_a_zip", "not a readable zip"),
        "malformed_json": (zip_of({**good, f"{ids[0]}.json": b'{"coverage": 0.5,'}), 422, "bad_predictions",
                           "not valid JSON"),
        "not_the_contract": (zip_of({**good, f"{ids[1]}.json": b'{"coverage": 1.7}'}), 422, "bad_predictions",
                             "not a fraction"),
        "not_utf8": (zip_of({**good, f"{ids[1]}.json": b"\xff\xfe{}"}), 422, "bad_predictions", "not UTF-8"),
        "unknown_id": (zip_of({**good, "test_colon-99999-50mm_000_noise0.json": prediction()}), 422, "bad_names",
                       "not a sample id"),
        "missing_id": (zip_of({k: v for k, v in good.items() if not k.startswith(ids[0])}), 422,
                       "missing_samples", ids[0]),
        "duplicate": (zip_of({**good, f"sub/{ids[0]}.json": prediction()}), 422, "bad_names", "a second prediction"),
        "other_file": (zip_of({**good, "README.txt": b"hi"}), 422, "bad_names", "not a <sample_id>.json"),
        "empty": (zip_of({}), 422, "missing_samples", ids[0]),
    }


CASES = ["dotdot", "absolute", "symlink", "bomb", "oversize", "many_files", "not_a_zip", "malformed_json",
         "not_the_contract", "not_utf8", "unknown_id", "missing_id", "duplicate", "other_file", "empty"]


@pytest.mark.parametrize("case", CASES)
def test_a_hostile_upload_is_refused_and_nothing_is_stored(server, hidden_suite, case):
    sid, _, public, _ = hidden_suite
    data, status, code, says = _cases(public)[case]
    before = server.rows("select count(*) from submissions")
    results = server.rows("select count(*) from results")
    refused = server.rows("select count(*) from audit_log where outcome = 'refused'")[0][0]
    got, body = server.upload(sid, data, server.tok)
    assert (got, body["error"]) == (status, code), body
    assert says in json.dumps(body), body
    assert server.rows("select count(*) from submissions") == before
    assert server.rows("select count(*) from results") == results
    assert server.rows("select count(*) from audit_log where outcome = 'refused'")[0][0] == refused + 1


def test_a_lying_content_length_is_refused(server, hidden_suite):
    sid, _, public, _ = hidden_suite
    before = server.rows("select count(*) from submissions")
    status, raw = server.request("POST", f"/api/v1/suites/{sid}/submissions?method=m", body=zip_of(_good(public)),
                                 token=server.tok, headers={"Content-Length": str(2 ** 30)})
    assert status in (400, 413)
    assert server.rows("select count(*) from submissions") == before


@pytest.mark.parametrize("with_token", [True, False])
def test_escape_codes_in_the_path_never_reach_the_audit_log_raw(server, hidden_suite, with_token):
    """The suite id of a refused upload is audited (before the token or the suite is checked): escaped, so that
    reading the log (serve-admin audit) cannot drive the reader's terminal."""
    _, _, public, _ = hidden_suite
    status, _ = server.request("POST", "/api/v1/suites/%1b%5b2J%1b%5d0%3bowned%07x/submissions?method=m",
                               body=zip_of(_good(public)), token=server.tok if with_token else None)
    assert status == (404 if with_token else 401)
    for row in server.rows("select actor, action, target, outcome, detail, remote from audit_log"):
        assert not any(ord(c) < 32 or 127 <= ord(c) < 160 for v in row for c in str(v)), row
    assert any("\\x1b[2J" in t for (t,) in server.rows("select target from audit_log"))
    shown = server.admin("audit", "--last", "100000")
    assert "\x1b" not in shown and "\x07" not in shown and "\\x1b[2J" in shown


def test_sql_metacharacters_are_text_in_every_field(server, hidden_suite):
    sid, _, public, _ = hidden_suite
    before = server.rows("select count(*) from submissions")[0][0]
    status, made = server.upload(sid, zip_of(_good(public)), server.tok, method=SQL, version=SQL, public=True)
    assert status == 202, made
    assert (made["method"], made["version"]) == (SQL, SQL)
    assert server.rows(f"select count(*) from submissions where method = '{SQL.replace(chr(39), chr(39) * 2)}'") \
        == [(1,)]       # this test's upload alone has this method
    assert server.rows("select name from sqlite_master where name = 'submissions'") == [("submissions",)]
    # the suite, the submission id and the token in the path and header
    for path in [f"/api/v1/suites/{SQL}/leaderboard", f"/api/v1/submissions/{SQL}", f"/suites/{SQL}",
                 "/api/v1/submissions/1' OR '1'='1"]:
        from urllib.parse import quote

        status, raw = server.request("GET", quote(path, safe="/"), token=server.tok)
        assert status == 404, (path, raw)
    assert server.upload(SQL, zip_of(_good(public)), server.tok)[0] == 404     # no route takes its '/'
    status, body = server.upload(SQL.replace("/", ""), zip_of(_good(public)), server.tok)
    assert status == 404 and body["error"] == "unknown_suite"
    assert server.upload(sid, zip_of(_good(public)), "cbt_' OR '1'='1")[0] == 401
    # a team name with them is refused by the admin command with a message; a token label keeps them as text
    from colonbench.cli import main

    assert main(["serve-admin", "--db", server.db, "token", "create", "--team", SQL]) == 2
    server.token("labelled", "--label", SQL)
    assert SQL in server.admin("token", "list")
    server.wait_final()
    assert server.rows("select count(*) from submissions") == [(before + 1,)]


@pytest.mark.parametrize("query, says", [("method=", "method"), ("method=" + "m" * 101, "method"),
                                         ("method=a%0Ab", "method"), ("method=m&version=" + "v" * 101, "version"),
                                         ("method=m&public=maybe", "public")])
def test_bad_fields_are_refused(server, hidden_suite, query, says):
    sid, _, public, _ = hidden_suite
    before = server.rows("select count(*) from submissions")
    status, raw = server.request("POST", f"/api/v1/suites/{sid}/submissions?{query}", body=zip_of(_good(public)),
                                 token=server.tok)
    body = json.loads(raw)
    assert status == 400 and body["error"] == "bad_field" and says in body["message"]
    assert server.rows("select count(*) from submissions") == before
