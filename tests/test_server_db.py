"""The server's database: made only by its Alembic migrations (which match the models), tokens stored hashed,
URLs refused clearly and shown without their password, the admin command's actions audited with no control
character, anonymous refusals audited within a bound, listings that never read archives or per-sample rows."""

from __future__ import annotations

import pytest

from colonbench.cli import main
from colonbench.errors import InputError


def _diff(url: str) -> list:
    from alembic.autogenerate import compare_metadata
    from alembic.migration import MigrationContext

    from colonbench.server import db

    eng = db.engine(url)
    try:
        with eng.connect() as conn:
            return compare_metadata(MigrationContext.configure(conn), db.Base.metadata)
    finally:
        eng.dispose()


def test_the_migrations_make_the_models_schema_and_run_twice(tmp_path):
    from colonbench.server import db

    url = f"sqlite:///{tmp_path / 's.db'}"
    assert db.migrate(url) == "0001" and db.migrate(url) == "0001"
    assert _diff(url) == []


def test_tokens_are_stored_hashed_and_checked(tmp_path, capsys):
    from sqlalchemy import select
    from sqlalchemy.orm import Session

    from colonbench.server import accounts, db

    url = f"sqlite:///{tmp_path / 's.db'}"
    assert main(["serve-admin", "--db", url, "token", "create", "--team", "t1", "--label", "ci"]) == 0
    token = capsys.readouterr().out.strip().splitlines()[-1]
    assert token.startswith("cbt_") and len(token) == 68
    raw = (tmp_path / "s.db").read_bytes() + b"".join(p.read_bytes() for p in tmp_path.glob("s.db-*"))
    assert token.encode() not in raw and token[4:].encode() not in raw
    eng = db.engine(url)
    with Session(eng) as s:
        (row,) = s.scalars(select(db.Token)).all()
        assert row.token_hash == accounts.token_hash(token)
        assert accounts.authenticate(s, f"Bearer {token}").id == row.id
        for bad in (None, token, f"Bearer {token[:-1]}x", f"Basic {token}", "Bearer cbt_" + "g" * 64):
            assert accounts.authenticate(s, bad) is None
    eng.dispose()
    assert main(["serve-admin", "--db", url, "token", "revoke", "1"]) == 0
    assert main(["serve-admin", "--db", url, "team", "set", "t1", "--daily", "3"]) == 0
    capsys.readouterr()
    assert main(["serve-admin", "--db", url, "audit"]) == 0
    out = capsys.readouterr().out
    assert "token.create" in out and "token.revoke" in out and "team.limits" in out and token not in out


@pytest.mark.parametrize("url, says", [("mysql://x/y", "sqlite:///FILE"), ("sqlite:////nonexistent/dir/x.db",
                                                                           "cannot open the database")])
def test_bad_database_urls_are_refused_clearly(url, says, capsys):
    assert main(["serve-admin", "--db", url, "migrate"]) == 2
    err = capsys.readouterr().err
    assert says in err and "Traceback" not in err


def test_postgresql_urls_take_psycopg_3():
    from colonbench.server.db import normalize_url

    assert normalize_url("postgresql://u@h/db") == "postgresql+psycopg://u@h/db"
    with pytest.raises(InputError):
        normalize_url("oracle://x")


def test_a_submission_is_named_by_the_method_its_predictions_give(tmp_path):
    """colonbench submit without --method: the 'method' every prediction gives, else the folder's name."""
    import json

    from colonbench.server.client import method_of

    preds = tmp_path / "preds"
    preds.mkdir()
    for k in range(3):
        (preds / f"s{k}.json").write_text(json.dumps({"coverage": 0.5, "method": "my-method"}))
    assert method_of(preds) == "my-method"
    (preds / "s3.json").write_text(json.dumps({"coverage": 0.5, "method": "other"}))
    assert method_of(preds) == "preds"
    (preds / "s3.json").write_text(json.dumps({"coverage": 0.5}))
    assert method_of(preds) == "preds"


def _scored(url: str) -> str:
    """A team with one public, scored submission on a migrated database at ``url``: its public id."""
    from sqlalchemy.orm import Session

    from colonbench.server import accounts, db

    db.migrate(url)
    eng = db.engine(url)
    try:
        with Session(eng) as s, s.begin():
            _, tok = accounts.create_token(s, "t1")
            sub = db.Submission(public_id="p1", suite_id="s1", team_id=tok.team_id, token_id=tok.id, method="m",
                                public=True, status=db.SCORED, archive_sha256="0" * 64, archive=b"ARCHIVE" * 1000)
            s.add(sub)
            s.flush()
            s.add(db.Result(submission_id=sub.id, suite_id="s1", signature="cbs1-SIGNATURE", rows_json='["ROWS"]',
                            summary_json='[{"noise_mm": 0.0, "coverage_mae": 1.5}]'))
    finally:
        eng.dispose()
    return "p1"


def test_the_leaderboard_and_a_teams_list_never_load_archives_or_rows(tmp_path):
    """Every anonymous leaderboard request would otherwise read every upload's zip and per-sample rows."""
    import re

    from sqlalchemy import event

    from colonbench.server.app import Server

    url = f"sqlite:///{tmp_path / 's.db'}"
    _scored(url)
    srv = Server(url, {})
    statements = []
    event.listen(srv.engine, "before_cursor_execute", lambda c, cur, sql, *a: statements.append(sql))
    try:
        (row,) = srv.leaderboard("s1")
        assert row["id"] == "p1" and row["coverage_mae"] == 1.5 and row["team"] == "t1"
        assert "signature" not in row     # a digest of the truth: never published
        from colonbench.server import accounts
        from sqlalchemy.orm import Session

        with Session(srv.engine) as s, s.begin():
            text, _ = accounts.create_token(s, "t1")
        statements.clear()
        (mine,) = srv.own(f"Bearer {text}")
        assert mine["id"] == "p1" and mine["summary"][0]["coverage_mae"] == 1.5
    finally:
        srv.engine.dispose()
    read = " ".join(statements)
    assert re.search(r"\barchive\b", read) is None and "rows_json" not in read and "signature" not in read


def test_audit_lines_keep_no_control_characters(tmp_path, capsys):
    """A control character in the audit log (an escape sequence) would act on the terminal of whoever reads it."""
    import sqlite3

    from sqlalchemy.orm import Session

    from colonbench.server import accounts, db

    url = f"sqlite:///{tmp_path / 's.db'}"
    db.migrate(url)
    eng = db.engine(url)
    with Session(eng) as s, s.begin():
        accounts.audit(s, "team \x1b[2J", "upload", "suite \x1b]0;owned\x07", "refused", {"m": "\x1b[31m"}, "\x1b")
    eng.dispose()
    con = sqlite3.connect(tmp_path / "s.db")    # a line an older colonbench wrote raw
    con.execute("insert into audit_log (at, actor, action, target, outcome, detail, remote) values "
                "('2026-01-01 00:00:00', 'x', 'upload', ?, 'refused', '{}', '')", ("suite \x1b[31mred\r\x9b",))
    con.commit()
    stored = con.execute("select actor, action, target, outcome, detail, remote from audit_log").fetchall()
    con.close()
    assert not any("\x1b" in v for v in stored[0])
    assert main(["serve-admin", "--db", url, "audit"]) == 0
    out = capsys.readouterr().out
    assert "\x1b" not in out and "\r" not in out and "\x9b" not in out and "\x07" not in out
    assert "\\x1b[31mred" in out


def test_anonymous_refusals_are_audited_within_a_bound(tmp_path):
    """An unknown token's uploads cannot fill the audit log; every refusal of a team's upload is a line."""
    from colonbench.server.app import ANONYMOUS_AUDITS, Server
    from colonbench.server.uploads import UploadError

    url = f"sqlite:///{tmp_path / 's.db'}"
    from colonbench.server import db

    db.migrate(url)
    srv = Server(url, {})
    err = UploadError(401, "bad_token", "a valid API token is needed")
    try:
        for _ in range(5 * ANONYMOUS_AUDITS):
            srv.refuse(None, "s1", err, "10.0.0.1")
        for _ in range(3):
            srv.refuse(None, "s1", err, "10.0.0.2")
        for _ in range(2 * ANONYMOUS_AUDITS):
            srv.refuse("team t1", "s1", UploadError(429, "daily_limit", "over"), "10.0.0.1")
        with srv.engine.connect() as conn:
            from sqlalchemy import text

            rows = conn.execute(text("select actor, remote from audit_log")).all()
    finally:
        srv.engine.dispose()
    assert sum(1 for a, r in rows if a == "unknown token" and r == "10.0.0.1") == ANONYMOUS_AUDITS
    assert sum(1 for a, r in rows if a == "unknown token" and r == "10.0.0.2") == 3
    assert sum(1 for a, _ in rows if a == "team t1") == 2 * ANONYMOUS_AUDITS


def test_a_password_in_the_database_url_is_never_shown(capsys):
    from colonbench.server import db

    url = "postgresql://cb:hunter2-s3cret@127.0.0.1:1/colonbench"
    assert "hunter2-s3cret" not in db.shown_url(url) and "127.0.0.1:1/colonbench" in db.shown_url(url)
    with pytest.raises(InputError) as refused:
        db.migrate(url)
    assert "hunter2-s3cret" not in str(refused.value) and "127.0.0.1" in str(refused.value)
    assert main(["serve-admin", "--db", url, "migrate"]) == 2
    assert "hunter2-s3cret" not in capsys.readouterr().err
