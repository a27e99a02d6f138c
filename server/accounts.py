"""Teams, their API tokens and the audit log (``colonbench serve-admin``).

A token is 32 random bytes from :mod:`secrets`, shown once as ``cbt_<64 hex>`` when it is created; the database
keeps only its sha256, so a copy of the database gives no usable token. A request's token is hashed and looked up;
the stored and computed hashes are compared with :func:`hmac.compare_digest`. A token may expire
(``--expires-days``) and may be revoked; a revoked or expired token is refused as an unknown one is. Rotating a
team's token is creating a new one and revoking the old.

Every admin action and every upload (accepted or refused) is written to the audit log (:func:`audit`), every
field :func:`printable` (no control character, which would act on the terminal of whoever reads the log).
"""

from __future__ import annotations

import datetime as dt
import hashlib
import hmac
import json
import secrets

from sqlalchemy import select
from sqlalchemy.orm import Session

from colonbench.errors import InputError
from colonbench.server.db import Audit, Team, Token, now

PREFIX = "cbt_"
#: Team names: letters, digits and ``-_.``, at most 100 characters.
NAME_CHARS = set("abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789-_.")


def token_hash(token: str) -> str:
    """The sha256 hex of a token's text, as stored."""
    return hashlib.sha256(token.encode("utf-8", "replace")).hexdigest()


def printable(text) -> str:
    """``text`` with every character that is not printable (control characters: an escape sequence, a carriage
    return, a bell; line and paragraph separators) written as its Python escape (``\\x1b``).

    Parameters
    ----------
    text : object
        Anything; its ``str``.

    Returns
    -------
    str
        Safe to write to a terminal: what it shows is what was stored.
    """
    return "".join(c if c.isprintable() else c.encode("unicode_escape").decode("ascii") for c in str(text))


def audit(session: Session, actor: str, action: str, target: str = "", outcome: str = "ok", detail=None,
          remote: str = "") -> None:
    """Add one line to the audit log (committed with the session), every field :func:`printable`."""
    session.add(Audit(actor=printable(actor)[:200], action=printable(action)[:50], target=printable(target)[:200],
                      outcome=printable(outcome)[:20],
                      detail=printable(json.dumps(detail if detail is not None else {}, sort_keys=True))[:20000],
                      remote=printable(remote)[:100]))


def _check_name(name: str) -> str:
    if not name or len(name) > 100 or not set(name) <= NAME_CHARS:
        raise InputError(f"team name {name!r}: 1 to 100 letters, digits, '-', '_' or '.'")
    return name


def _limit(value, what: str):
    if value is None:
        return None
    if int(value) < 0:
        raise InputError(f"{what} must be >= 0")
    return int(value)


def set_team(session: Session, name: str, daily: int | None = None, total: int | None = None,
             actor: str = "admin") -> Team:
    """Create a team, or set its limits (None: no limit; a team made without limits has none)."""
    name = _check_name(name)
    team = session.scalar(select(Team).where(Team.name == name))
    created = team is None
    if created:
        team = Team(name=name)
        session.add(team)
    team.daily_limit = _limit(daily, "--daily")
    team.total_limit = _limit(total, "--total")
    session.flush()
    audit(session, actor, "team.create" if created else "team.limits", name,
          detail={"daily_limit": team.daily_limit, "total_limit": team.total_limit})
    return team


def create_token(session: Session, team_name: str, label: str = "", expires_days: float | None = None,
                 actor: str = "admin") -> tuple[str, Token]:
    """A new token of a team (the team made where missing, without limits): its text (shown once) and row."""
    team = session.scalar(select(Team).where(Team.name == _check_name(team_name)))
    if team is None:
        team = set_team(session, team_name, actor=actor)
    if expires_days is not None and expires_days <= 0:
        raise InputError("--expires-days must be > 0")
    text = PREFIX + secrets.token_bytes(32).hex()
    row = Token(team_id=team.id, token_hash=token_hash(text), label=str(label)[:200],
                expires_at=now() + dt.timedelta(days=expires_days) if expires_days else None)
    session.add(row)
    session.flush()
    audit(session, actor, "token.create", f"team {team.name}", detail={"token_id": row.id, "label": row.label,
                                                                      "expires_at": str(row.expires_at or "")})
    return text, row


def revoke_token(session: Session, token_id: int, actor: str = "admin") -> Token:
    """Revoke a token by its id (``serve-admin token list``)."""
    row = session.get(Token, int(token_id))
    if row is None:
        raise InputError(f"no token {token_id}")
    row.revoked_at = row.revoked_at or now()
    audit(session, actor, "token.revoke", f"token {row.id}")
    return row


def authenticate(session: Session, header: str | None) -> Token | None:
    """The live token an ``Authorization: Bearer <token>`` header names, or None (missing, malformed, unknown,
    revoked or expired)."""
    if not header or not header.startswith("Bearer "):
        return None
    text = header[len("Bearer "):].strip()
    if not text.startswith(PREFIX) or len(text) != len(PREFIX) + 64:
        return None
    digest = token_hash(text)
    row = session.scalar(select(Token).where(Token.token_hash == digest))
    if row is None or not hmac.compare_digest(row.token_hash, digest):
        return None
    if row.revoked_at is not None or (row.expires_at is not None and row.expires_at <= now()):
        return None
    return row


def tokens(session: Session) -> list[dict]:
    """Every token: id, team, label, created, expires, revoked (never the token)."""
    out = []
    for tok, team in session.execute(select(Token, Team).join(Team, Team.id == Token.team_id).order_by(Token.id)):
        out.append({"id": tok.id, "team": team.name, "label": tok.label, "created_at": str(tok.created_at),
                    "expires_at": str(tok.expires_at or ""), "revoked_at": str(tok.revoked_at or "")})
    return out
