"""The evaluation server's database: teams, their API tokens, submissions, results and the audit log.

SQLAlchemy 2 over any URL it takes: ``sqlite:///server.db`` (the default, a file beside where the server runs)
or ``postgresql+psycopg://user@host/db`` (psycopg 3; a plain ``postgresql://`` URL is read as that). The schema
is made and upgraded only by the Alembic migrations in :mod:`colonbench.server.migrations` (:func:`migrate`),
never by ``create_all``: a database made by an older colonbench is upgraded in place.

A submission moves ``queued`` -> ``scoring`` -> ``scored`` or ``failed``; only a worker that claimed it
(:func:`colonbench.server.worker.claim`) moves it on. Its predictions, checked before anything was stored
(:mod:`colonbench.server.uploads`), are kept as one canonical zip in ``archive``. Its results (the rows
``colonbench score`` writes, and their summary) are in ``results``; the rows hold each sample's truth, so the
server never serves them (:mod:`colonbench.server.app` serves the summary). Both ``archive`` and ``rows_json``
are deferred: a query loads them only where it names them (the worker, scoring), never for a listing.

A URL is shown (in messages and logs) only by :func:`shown_url`, its password hidden.
"""

from __future__ import annotations

import datetime as dt
from pathlib import Path

from sqlalchemy import (Boolean, DateTime, ForeignKey, Integer, LargeBinary, MetaData, String, Text, create_engine,
                        event)
from sqlalchemy.engine import Engine, make_url
from sqlalchemy.exc import ArgumentError
from sqlalchemy.orm import DeclarativeBase, Mapped, mapped_column

from colonbench.errors import InputError

#: Submission states.
QUEUED, SCORING, SCORED, FAILED = "queued", "scoring", "scored", "failed"
DEFAULT_URL = "sqlite:///server.db"


def now() -> dt.datetime:
    """The current time, UTC, without microseconds' surprises across databases (naive, as stored)."""
    return dt.datetime.now(dt.timezone.utc).replace(tzinfo=None)


class Base(DeclarativeBase):
    metadata = MetaData(naming_convention={"ix": "ix_%(column_0_label)s", "uq": "uq_%(table_name)s_%(column_0_name)s",
                                           "fk": "fk_%(table_name)s_%(column_0_name)s_%(referred_table_name)s",
                                           "pk": "pk_%(table_name)s"})


class Team(Base):
    """A team: who submits, with its limits (None: no limit)."""

    __tablename__ = "teams"
    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    name: Mapped[str] = mapped_column(String(100), unique=True)
    daily_limit: Mapped[int | None] = mapped_column(Integer, nullable=True)
    total_limit: Mapped[int | None] = mapped_column(Integer, nullable=True)
    created_at: Mapped[dt.datetime] = mapped_column(DateTime, default=now)


class Token(Base):
    """An API token of a team: only its sha256 is stored."""

    __tablename__ = "tokens"
    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    team_id: Mapped[int] = mapped_column(ForeignKey("teams.id"), index=True)
    token_hash: Mapped[str] = mapped_column(String(64), unique=True)
    label: Mapped[str] = mapped_column(String(200), default="")
    created_at: Mapped[dt.datetime] = mapped_column(DateTime, default=now)
    expires_at: Mapped[dt.datetime | None] = mapped_column(DateTime, nullable=True)
    revoked_at: Mapped[dt.datetime | None] = mapped_column(DateTime, nullable=True)


class Submission(Base):
    """One upload of predictions for a hidden suite, and where its scoring stands."""

    __tablename__ = "submissions"
    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    public_id: Mapped[str] = mapped_column(String(32), unique=True)
    suite_id: Mapped[str] = mapped_column(String(100), index=True)
    team_id: Mapped[int] = mapped_column(ForeignKey("teams.id"), index=True)
    token_id: Mapped[int] = mapped_column(ForeignKey("tokens.id"))
    method: Mapped[str] = mapped_column(String(100))
    version: Mapped[str] = mapped_column(String(100), default="")
    public: Mapped[bool] = mapped_column(Boolean, default=False)
    status: Mapped[str] = mapped_column(String(16), default=QUEUED, index=True)
    reason: Mapped[str] = mapped_column(Text, default="")
    created_at: Mapped[dt.datetime] = mapped_column(DateTime, default=now, index=True)
    started_at: Mapped[dt.datetime | None] = mapped_column(DateTime, nullable=True)
    heartbeat_at: Mapped[dt.datetime | None] = mapped_column(DateTime, nullable=True)
    finished_at: Mapped[dt.datetime | None] = mapped_column(DateTime, nullable=True)
    worker: Mapped[str] = mapped_column(String(200), default="")
    attempts: Mapped[int] = mapped_column(Integer, default=0)
    files: Mapped[int] = mapped_column(Integer, default=0)
    archive_sha256: Mapped[str] = mapped_column(String(64))
    archive: Mapped[bytes] = mapped_column(LargeBinary, deferred=True)


class Result(Base):
    """The scored result of a submission: its rows (as ``colonbench score`` writes them) and their summary."""

    __tablename__ = "results"
    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    submission_id: Mapped[int] = mapped_column(ForeignKey("submissions.id"), unique=True)
    suite_id: Mapped[str] = mapped_column(String(100), index=True)
    signature: Mapped[str] = mapped_column(String(100))
    rows_json: Mapped[str] = mapped_column(Text, deferred=True)
    summary_json: Mapped[str] = mapped_column(Text)
    scored_at: Mapped[dt.datetime] = mapped_column(DateTime, default=now)


class Audit(Base):
    """One line of the audit log: every upload (accepted or refused) and every admin action."""

    __tablename__ = "audit_log"
    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    at: Mapped[dt.datetime] = mapped_column(DateTime, default=now, index=True)
    actor: Mapped[str] = mapped_column(String(200))
    action: Mapped[str] = mapped_column(String(50))
    target: Mapped[str] = mapped_column(String(200), default="")
    outcome: Mapped[str] = mapped_column(String(20), default="ok")
    detail: Mapped[str] = mapped_column(Text, default="")
    remote: Mapped[str] = mapped_column(String(100), default="")


def normalize_url(url: str) -> str:
    """A database URL as SQLAlchemy takes it: ``postgresql://`` read as psycopg 3's ``postgresql+psycopg://``.

    Raises
    ------
    InputError
        Not a SQLite or PostgreSQL URL.
    """
    url = str(url)
    if url.startswith(("postgresql://", "postgres://")):
        url = "postgresql+psycopg://" + url.split("://", 1)[1]
    if not url.startswith(("sqlite://", "postgresql+psycopg://")):
        raise InputError(f"--db {url.split('://')[0]}://...: colonbench serve takes sqlite:///FILE or "
                         "postgresql://USER@HOST[:PORT]/DB")
    return url


def shown_url(url: str) -> str:
    """A database URL as it may be shown in a message or a log: its password replaced by ``***``.

    Parameters
    ----------
    url : str
        Any URL ``--db`` takes.

    Returns
    -------
    str
        The URL without its password (only its scheme where it cannot be parsed).
    """
    try:
        return make_url(str(url)).render_as_string(hide_password=True)
    except (ArgumentError, ValueError):
        return str(url).split("://", 1)[0] + "://..."


def engine(url: str = DEFAULT_URL) -> Engine:
    """An engine for ``url``: SQLite with foreign keys on, a busy timeout and write-ahead logging (readers and one
    writer at once across processes)."""
    url = normalize_url(url)
    if url.startswith("sqlite"):
        eng = create_engine(url, connect_args={"timeout": 30})

        @event.listens_for(eng, "connect")
        def _pragmas(conn, _):
            cur = conn.cursor()
            cur.execute("PRAGMA foreign_keys=ON")
            cur.execute("PRAGMA journal_mode=WAL")
            cur.execute("PRAGMA busy_timeout=30000")
            cur.close()
        return eng
    return create_engine(url, pool_pre_ping=True)


def migrate(url: str = DEFAULT_URL) -> str:
    """Make or upgrade the database at ``url`` to the newest schema (Alembic ``upgrade head``); its revision.

    Raises
    ------
    InputError
        The database cannot be reached or opened.
    """
    from alembic import command
    from alembic.config import Config
    from alembic.runtime.migration import MigrationContext
    from sqlalchemy.exc import OperationalError

    cfg = Config()
    cfg.set_main_option("script_location", str(Path(__file__).parent / "migrations"))
    eng = engine(url)
    try:
        with eng.begin() as conn:
            cfg.attributes["connection"] = conn
            command.upgrade(cfg, "head")
        with eng.connect() as conn:
            return MigrationContext.configure(conn).get_current_revision()
    except OperationalError as exc:
        reason = str(exc.orig).splitlines()[0] if str(exc.orig) else type(exc.orig).__name__
        raise InputError(f"cannot open the database {shown_url(url)}: {reason}") from None
    finally:
        eng.dispose()
