"""The server's database: made only by its Alembic migrations (which match the models), tokens stored hashed,
URLs refused clearly, the admin command's actions audited; on PostgreSQL where its binaries are installed."""

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
