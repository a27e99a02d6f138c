"""The evaluation server's HTTP app (Starlette): uploads, their status, each hidden suite's public leaderboard.

Routes (every error a JSON body ``{"error": code, "message": ..., "problems": [...]}`` with a 4xx status):

``GET /``, ``GET /suites/{suite}``
    HTML: the hidden suites, and a suite's public leaderboard: the leaderboard site's suite page, rendered live
    (:func:`colonbench.reports.live.live_page`) from the autoescaping Jinja2 templates the static site uses; this
    package's own pages (``templates/``) extend their ``page.html``.
``GET /api/v1/health``, ``GET /api/v1/suites``, ``GET /api/v1/suites/{suite}/leaderboard``
    JSON, no token: the suites (id, name, samples, noise levels, the published inputs' digest) and a suite's
    leaderboard of public, scored submissions.
``POST /api/v1/suites/{suite}/submissions?method=M&version=V&public=0|1``
    Token (``Authorization: Bearer``); the body is the predictions zip (``application/zip``). Checked whole
    before anything is stored (:mod:`colonbench.server.uploads`), then the team's limits; 202 with the
    submission's id, queued for a worker.
``GET /api/v1/submissions``, ``GET /api/v1/submissions/{id}``
    Token: the team's own submissions (another team's id is answered as an unknown one), with their status, the
    reason of a failure and, once scored, the summary row per noise level.

The truth is never served: no route reads a suite's folder, and of a result only :data:`SERVED` summary columns
are sent, never the per-sample rows (they hold each sample's true coverage) nor the suite's signature digest. A
listing reads neither the stored archives nor the rows.

Every upload is audited, accepted or refused, a team's every time; an unknown or missing token's refusals at most
:data:`ANONYMOUS_AUDITS` times a minute per client address (the next line audited says how many were left out),
so that anyone without a token cannot fill the log. An unknown suite id is audited as its ``repr``.
"""

from __future__ import annotations

import datetime as dt
import json
import secrets
import threading
import time
from pathlib import Path

from sqlalchemy import func, select, update
from sqlalchemy.orm import Session
from starlette.applications import Starlette
from starlette.concurrency import run_in_threadpool
from starlette.exceptions import HTTPException
from starlette.requests import Request
from starlette.responses import HTMLResponse, JSONResponse
from starlette.routing import Route

from colonbench.reports.live import live_page
from colonbench.reports.webpage import SORTER_SHA256, environment
from colonbench.server import accounts
from colonbench.server.db import SCORED, Result, Submission, Team, Token, engine, now
from colonbench.server.uploads import Limits, UploadError, canonical_zip, check

#: The summary columns a result is served with (per noise level); the rest stay in the database.
SERVED = ("noise_mm", "segments", "failed", "coverage_undefined", "coverage_mae", "coverage_median",
          "coverage_q95", "holes_precision_2mm_mean", "holes_recall_2mm_mean", "centerline_precision_2mm_mean",
          "centerline_recall_2mm_mean")
#: Every answer's headers: no script but the pages' table sorter (by its hash), no style from elsewhere, no framing.
HEADERS = {"X-Content-Type-Options": "nosniff", "Referrer-Policy": "no-referrer",
           "Content-Security-Policy": f"default-src 'none'; style-src 'unsafe-inline'; script-src '{SORTER_SHA256}'; "
                                      "frame-ancestors 'none'"}
#: Refused uploads of an unknown or missing token audited per client address and minute; the rest are counted.
ANONYMOUS_AUDITS = 10


def _error(status: int, code: str, message: str, problems=()) -> JSONResponse:
    return JSONResponse({"error": code, "message": message, "problems": list(problems)}, status, headers=HEADERS)


def _text(value, what: str, longest: int, empty: bool = False) -> str:
    """A text field of a request: printable, at most ``longest`` characters (stored as given, escaped when shown)."""
    value = "" if value is None else str(value)
    if (not value and not empty) or len(value) > longest or any(ord(c) < 32 or ord(c) == 127 for c in value):
        raise UploadError(400, "bad_field", f"{what}: {'1' if not empty else '0'} to {longest} printable characters")
    return value


def _flag(value) -> bool:
    if value in (None, "", "0", "false", "no"):
        return False
    if value in ("1", "true", "yes"):
        return True
    raise UploadError(400, "bad_field", "public: 0 or 1")


def _summary(summary_json: str | None) -> list[dict] | None:
    if summary_json is None:
        return None
    return [{k: r.get(k) for k in SERVED} for r in json.loads(summary_json)]


class _Budget:
    """How many lines a client address may add to the audit log per window (anonymous refusals)."""

    def __init__(self, per_window: int, seconds: float = 60.0):
        self.per, self.seconds, self.lock, self.seen = per_window, seconds, threading.Lock(), {}

    def take(self, remote: str) -> tuple[bool, int]:
        """Whether a line of ``remote`` is written now, and how many of its lines were left out before it."""
        t = time.monotonic()
        with self.lock:
            if len(self.seen) > 4096:       # forget addresses whose window is over
                self.seen = {k: v for k, v in self.seen.items() if t - v[0] < self.seconds}
            start, used, dropped = self.seen.get(remote, (t, 0, 0))
            carried = 0
            if t - start >= self.seconds:
                start, used, carried, dropped = t, 0, dropped, 0
            if used >= self.per:
                self.seen[remote] = (start, used, dropped + 1)
                return False, 0
            self.seen[remote] = (start, used + 1, dropped)
            return True, carried


def _over_limits(s: Session, team: Team) -> UploadError | None:
    """The refusal of one more upload of ``team``, if it has used its total or today's (UTC) submissions."""
    if team.total_limit is None and team.daily_limit is None:
        return None
    day = now().replace(hour=0, minute=0, second=0, microsecond=0)
    total = s.scalar(select(func.count()).select_from(Submission).where(Submission.team_id == team.id))
    if team.total_limit is not None and total >= team.total_limit:
        return UploadError(429, "total_limit", f"team {team.name} has used all its {team.total_limit} submissions")
    today = s.scalar(select(func.count()).select_from(Submission).where(Submission.team_id == team.id,
                                                                       Submission.created_at >= day))
    if team.daily_limit is not None and today >= team.daily_limit:
        tomorrow = (day + dt.timedelta(days=1)).isoformat() + "Z"
        return UploadError(429, "daily_limit", f"team {team.name} has used its {team.daily_limit} submissions of "
                                               f"today (UTC); the next one from {tomorrow}")
    return None


def _submission(sub: Submission, summary_json: str | None) -> dict:
    return {"id": sub.public_id, "suite": sub.suite_id, "method": sub.method, "version": sub.version,
            "public": sub.public, "status": sub.status, "reason": sub.reason, "files": sub.files,
            "archive_sha256": sub.archive_sha256, "submitted_at": sub.created_at.isoformat() + "Z",
            "finished_at": sub.finished_at.isoformat() + "Z" if sub.finished_at else None,
            "summary": _summary(summary_json)}


class Server:
    """The app's state: the database, the hidden suites it serves and their sample ids, the upload caps."""

    def __init__(self, url: str, suites: dict, limits: Limits = Limits()):
        from colonbench.server.hidden import sample_ids

        self.engine = engine(url)
        self.suites = suites
        self.ids = {sid: sample_ids(s) for sid, s in suites.items()}
        self.limits = limits
        self.templates = environment(Path(__file__).parent / "templates")   # autoescaping, over the site's
        self.anonymous = _Budget(ANONYMOUS_AUDITS)

    # ------------------------------------------------------------------------------------------ reads
    def suite_list(self) -> list[dict]:
        from colonbench.benchmark.local_suites import read_entry

        return [{"id": sid, "name": s.name, "samples": s.samples, "noise_mm": list(s.noise_mm),
                 "inputs_sha256": read_entry(Path(s.folder)).get("inputs_sha256")}
                for sid, s in sorted(self.suites.items())]

    def leaderboard(self, suite_id: str) -> list[dict]:
        """The public scored submissions of a suite, best first (by the mean coverage MAE over noise levels); only
        the columns shown are read (never the archive, the per-sample rows or the signature)."""
        with Session(self.engine) as s:
            found = s.execute(select(Submission.public_id, Submission.method, Submission.version,
                                     Submission.created_at, Team.name, Result.summary_json)
                              .join(Result, Result.submission_id == Submission.id)
                              .join(Team, Team.id == Submission.team_id)
                              .where(Submission.suite_id == suite_id, Submission.public.is_(True),
                                     Submission.status == SCORED)).all()
        rows = []
        for public_id, method, version, created_at, team, summary_json in found:
            summary = _summary(summary_json)
            maes = [r["coverage_mae"] for r in summary if r["coverage_mae"] is not None]
            rows.append({"id": public_id, "team": team, "method": method, "version": version,
                         "submitted_at": created_at.isoformat() + "Z",
                         "coverage_mae": sum(maes) / len(maes) if maes else None, "by_noise": summary})
        rows.sort(key=lambda r: (r["coverage_mae"] is None, r["coverage_mae"] or 0.0, r["submitted_at"]))
        for k, r in enumerate(rows, 1):
            r["rank"] = k
        return rows

    def own(self, token_header: str | None, public_id: str | None = None):
        """The submissions of the token's team (one, by its public id), or None for a token that is not live; the
        archives (deferred) and the per-sample rows are not read."""
        with Session(self.engine) as s:
            tok = accounts.authenticate(s, token_header)
            if tok is None:
                return None
            q = (select(Submission, Result.summary_json).outerjoin(Result, Result.submission_id == Submission.id)
                 .where(Submission.team_id == tok.team_id))
            if public_id is not None:
                q = q.where(Submission.public_id == public_id)
            return [_submission(sub, res) for sub, res in s.execute(q.order_by(Submission.id)).all()]

    # ------------------------------------------------------------------------------------------ upload
    def refuse(self, actor: str | None, suite_id: str, err: UploadError, remote: str) -> None:
        """Audit a refused upload: a team's (``actor``) always, an unknown token's (None) within
        :data:`ANONYMOUS_AUDITS` a minute per address; a suite id not served by its ``repr``."""
        detail = {"error": err.code, "message": err.message, "problems": err.problems[:5]}
        if actor is None:
            write, dropped = self.anonymous.take(remote)
            if not write:
                return
            if dropped:
                detail["left_out_before"] = dropped
        target = f"suite {suite_id}" if suite_id in self.suites else f"suite {suite_id!r}"
        with Session(self.engine) as s, s.begin():
            accounts.audit(s, actor or "unknown token", "upload", target[:200], "refused", detail, remote)

    def accept(self, tok_id: int, suite_id: str, method: str, version: str, public: bool, data: bytes,
               remote: str) -> dict:
        """Check an upload and, within the team's limits, store it queued (one transaction).

        The limits are counted first, without a lock (a team over them is refused before its upload is unpacked
        and checked), then again under the team's lock at the insert, which is what holds them under concurrent
        uploads."""
        with Session(self.engine) as s:
            over = _over_limits(s, s.get(Team, s.get(Token, tok_id).team_id))
        if over is not None:
            raise over
        predictions = check(data, self.ids[suite_id], self.limits)
        archive, digest = canonical_zip(predictions)
        with Session(self.engine) as s, s.begin():
            tok = s.get(Token, tok_id)
            # lock the team (its row in PostgreSQL, the database in SQLite) before counting: limits hold under
            # concurrent uploads
            s.execute(update(Team).where(Team.id == tok.team_id).values(name=Team.name))
            team = s.get(Team, tok.team_id)
            over = _over_limits(s, team)
            if over is not None:
                raise over
            sub = Submission(public_id=secrets.token_hex(12), suite_id=suite_id, team_id=team.id, token_id=tok.id,
                             method=method, version=version, public=public, files=len(predictions),
                             archive_sha256=digest, archive=archive, reason="", worker="", attempts=0)
            s.add(sub)
            s.flush()
            accounts.audit(s, f"team {team.name}", "upload", f"submission {sub.public_id}", "accepted",
                           {"suite": suite_id, "method": method, "version": version, "public": public,
                            "files": len(predictions), "sha256": digest}, remote)
            return _submission(sub, None)

    def token_of(self, header: str | None):
        with Session(self.engine) as s:
            tok = accounts.authenticate(s, header)
            return (tok.id, s.get(Team, tok.team_id).name) if tok else None


async def _body(request: Request, cap: int) -> bytes:
    """The request body, read no further than ``cap`` bytes."""
    length = request.headers.get("content-length")
    if length is not None and (not length.isdigit() or int(length) > cap):
        raise UploadError(413, "too_large", f"the upload is over {cap} bytes")
    chunks, size = [], 0
    async for chunk in request.stream():
        size += len(chunk)
        if size > cap:
            raise UploadError(413, "too_large", f"the upload is over {cap} bytes")
        chunks.append(chunk)
    return b"".join(chunks)


def create_app(url: str, suites: dict, limits: Limits = Limits()) -> Starlette:
    """The ASGI app serving ``suites`` (id -> hidden suite) on the database at ``url`` (migrated already)."""
    srv = Server(url, suites, limits)

    def page(name: str, status: int = 200, **context) -> HTMLResponse:
        return HTMLResponse(srv.templates.get_template(name).render(root="/", **context), status, headers=HEADERS)

    async def index(request):
        return page("index.html", suites=srv.suite_list())

    async def suite_page(request):
        sid = request.path_params["suite"]
        if sid not in srv.suites:
            return page("missing.html", 404, what=sid)
        rows = await run_in_threadpool(srv.leaderboard, sid)
        suite = next(s for s in srv.suite_list() if s["id"] == sid)
        return HTMLResponse(await run_in_threadpool(live_page, suite, rows, "/"), headers=HEADERS)

    async def health(request):
        return JSONResponse({"ok": True, "suites": sorted(srv.suites)}, headers=HEADERS)

    async def suites_api(request):
        return JSONResponse({"suites": srv.suite_list()}, headers=HEADERS)

    async def leaderboard_api(request):
        sid = request.path_params["suite"]
        if sid not in srv.suites:
            return _error(404, "unknown_suite", "no such hidden suite on this server")
        return JSONResponse({"suite": sid, "rows": await run_in_threadpool(srv.leaderboard, sid)}, headers=HEADERS)

    async def submit(request):
        sid = request.path_params["suite"]
        remote = request.client.host if request.client else ""
        who = await run_in_threadpool(srv.token_of, request.headers.get("authorization"))
        actor = f"team {who[1]}" if who else None
        try:
            if who is None:
                raise UploadError(401, "bad_token", "a valid API token is needed (Authorization: Bearer cbt_...)")
            if sid not in srv.suites:
                raise UploadError(404, "unknown_suite", "no such hidden suite on this server")
            q = request.query_params
            method = _text(q.get("method"), "method", 100)
            version = _text(q.get("version"), "version", 100, empty=True)
            public = _flag(q.get("public"))
            data = await _body(request, srv.limits.max_bytes)
            made = await run_in_threadpool(srv.accept, who[0], sid, method, version, public, data, remote)
        except UploadError as err:
            await run_in_threadpool(srv.refuse, actor, sid, err, remote)
            return JSONResponse(err.body(), err.status, headers=HEADERS)
        return JSONResponse(made, 202, headers=HEADERS)

    async def my_submissions(request):
        found = await run_in_threadpool(srv.own, request.headers.get("authorization"))
        if found is None:
            return _error(401, "bad_token", "a valid API token is needed (Authorization: Bearer cbt_...)")
        return JSONResponse({"submissions": found}, headers=HEADERS)

    async def my_submission(request):
        found = await run_in_threadpool(srv.own, request.headers.get("authorization"), request.path_params["id"])
        if found is None:
            return _error(401, "bad_token", "a valid API token is needed (Authorization: Bearer cbt_...)")
        if not found:
            return _error(404, "unknown_submission", "no submission of your team has this id")
        return JSONResponse(found[0], headers=HEADERS)

    async def http_error(request, exc: HTTPException):
        return _error(exc.status_code, "http", str(exc.detail))

    async def server_error(request, exc: Exception):
        return _error(500, "internal", "the server failed on this request; it is logged")

    routes = [Route("/", index), Route("/suites/{suite}", suite_page),
              Route("/api/v1/health", health), Route("/api/v1/suites", suites_api),
              Route("/api/v1/suites/{suite}/leaderboard", leaderboard_api),
              Route("/api/v1/suites/{suite}/submissions", submit, methods=["POST"]),
              Route("/api/v1/submissions", my_submissions), Route("/api/v1/submissions/{id}", my_submission)]
    app = Starlette(routes=routes, exception_handlers={HTTPException: http_error, Exception: server_error})
    app.state.server = srv
    return app
