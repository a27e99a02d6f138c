"""``colonbench serve``, ``serve-worker``, ``serve-admin`` and ``submit``: the hidden-truth evaluation server, its
scoring workers, its accounts, and its client (docs/server.md).

``serve``, ``serve-worker`` and ``serve-admin`` need the ``server`` extra; without it they say what to install.
``submit`` needs only the standard library. The workers ``serve`` starts take the database URL from
:data:`DB_ENV` (the environment), never their argv, where any user of the machine would read a password in it.
"""

from __future__ import annotations

import argparse
import functools
import json
import os
import sys

DB_HELP = "the database URL: sqlite:///FILE (default sqlite:///server.db) or postgresql://USER@HOST[:PORT]/DB"
#: The environment variable ``serve-worker`` reads its database URL from when --db is not given.
DB_ENV = "COLONBENCH_DB"
#: The packages of the ``server`` extra (pyproject.toml) the server's commands import.
EXTRA = ("starlette", "uvicorn", "sqlalchemy", "alembic")
TOKEN_ON_COMMAND_LINE = ("--token: the token is read from $COLONBENCH_TOKEN or --token-file, never the command "
                         "line (where other users of the machine and the shell's history see it)")


def _needs_extra(func):
    """``func`` (a command) refused with what to install, where a package of the ``server`` extra is missing."""

    @functools.wraps(func)
    def run(args):
        from colonbench.errors import InputError

        def refuse(name):
            return InputError(f"colonbench {args.command} needs the server's packages ({name} is not installed): "
                              "pip install 'colonbench[server]'")

        for name in EXTRA:
            try:
                __import__(name)
            except ModuleNotFoundError:
                raise refuse(name) from None
        try:
            return func(args)
        except ModuleNotFoundError as exc:   # psycopg, for a postgresql:// URL
            if (exc.name or "").split(".")[0] in (*EXTRA, "psycopg"):
                raise refuse(exc.name) from None
            raise
    return run


class _NoToken(argparse.Action):
    """``submit --token``: refused without printing what followed it."""

    def __call__(self, parser, namespace, values, option_string=None):
        parser.error(TOKEN_ON_COMMAND_LINE)


def _suites(dirs) -> dict:
    from colonbench.server.hidden import served

    return served(dirs)


def _limits(args):
    from colonbench.server.uploads import Limits

    return Limits(max_bytes=int(args.max_upload_mb * 2 ** 20), max_files=args.max_files)


def cmd_serve(args):
    """Run the server on one address, with ``--workers`` scoring workers beside it."""
    import signal
    import subprocess

    import uvicorn

    from colonbench.server import db
    from colonbench.server.app import create_app

    suites = _suites(args.suites)
    revision = db.migrate(args.db)
    app = create_app(args.db, suites, _limits(args))
    procs = []
    env = {**os.environ, DB_ENV: args.db}   # the URL (and any password in it) not in the workers' argv
    for _ in range(args.workers):   # each stops when this process does (--parent), however it ends
        procs.append(subprocess.Popen([sys.executable, "-m", "colonbench.cli", "serve-worker", "--parent",
                                       str(os.getpid()), "--suites", *map(str, args.suites)], env=env))
    # uvicorn shuts down on SIGTERM and then raises it again: exit through the finally below, stopping the workers
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(0))
    print(f"colonbench serve: {len(suites)} hidden suite(s) ({', '.join(sorted(suites))}), database at schema "
          f"{revision}, {args.workers} scoring worker(s); http://{args.host}:{args.port}/", flush=True)
    try:
        uvicorn.run(app, host=args.host, port=args.port, log_level="warning" if args.quiet else "info",
                    proxy_headers=True, forwarded_allow_ips=args.forwarded_allow_ips)
    finally:
        for p in procs:
            p.send_signal(signal.SIGTERM)
        for p in procs:
            try:
                p.wait(timeout=30)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()
    return 0


def cmd_worker(args):
    """Score queued submissions until stopped (or, with --once, until none is queued)."""
    import signal
    import threading

    from colonbench.server import db, worker

    args.db = args.db or os.environ.get(DB_ENV) or db.DEFAULT_URL
    suites = _suites(args.suites)
    db.migrate(args.db)
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    n = worker.run(args.db, suites, once=args.once, poll=args.poll, stale_after=args.stale_after,
                   max_attempts=args.max_attempts, slow=args.slow, stop=stop, parent=args.parent)
    print(f"colonbench serve-worker: {n} submission(s) processed")
    return 0


def cmd_admin(args):
    """Teams, tokens, the audit log and the schema of the server's database."""
    from sqlalchemy import select
    from sqlalchemy.orm import Session

    from colonbench.errors import InputError
    from colonbench.server import accounts, db
    from colonbench.server.accounts import printable

    revision = db.migrate(args.db)
    if args.what == "migrate":
        print(f"the database is at schema {revision} (the newest)")
        return 0
    if args.what is None or (args.what == "token" and args.action is None):
        raise InputError("give an action: serve-admin token create|revoke|list, team set, audit, migrate")
    eng = db.engine(args.db)
    try:
        with Session(eng) as s, s.begin():
            if args.what == "token" and args.action == "create":
                text, row = accounts.create_token(s, args.team, args.label, args.expires_days)
                print(f"token {row.id} of team {args.team}"
                      + (f", expires {row.expires_at:%Y-%m-%d %H:%M} UTC" if row.expires_at else "")
                      + f" (shown once: give it to the team, who keep it in $COLONBENCH_TOKEN or a file):\n{text}")
            elif args.what == "token" and args.action == "revoke":
                row = accounts.revoke_token(s, args.id)
                print(f"token {row.id} revoked at {row.revoked_at:%Y-%m-%d %H:%M:%S} UTC")
            elif args.what == "token":
                for t in accounts.tokens(s):
                    state = "revoked" if t["revoked_at"] else "live"
                    print(f"{t['id']:5d}  {t['team']:<24} {state:<8} created {t['created_at'][:19]}"
                          + (f", expires {t['expires_at'][:19]}" if t["expires_at"] else "")
                          + (f"  {t['label']}" if t["label"] else ""))
            elif args.what == "team":
                team = accounts.set_team(s, args.team, args.daily, args.total)
                print(f"team {team.name}: {team.daily_limit if team.daily_limit is not None else 'no'} daily limit, "
                      f"{team.total_limit if team.total_limit is not None else 'no'} total limit")
            else:
                rows = s.scalars(select(db.Audit).order_by(db.Audit.id.desc()).limit(args.last)).all()
                for a in reversed(rows):     # escaped: a line written raw by an older colonbench is shown safe
                    print(f"{a.at:%Y-%m-%d %H:%M:%S}  {printable(a.actor):<24} {printable(a.action):<13} "
                          f"{printable(a.outcome):<9} {printable(a.target)}  {printable(a.detail)}")
                accounts.audit(s, "admin", "audit.read", detail={"last": args.last})
    finally:
        eng.dispose()
    return 0


def cmd_submit(args):
    """Upload a predictions folder to a server; print its status and, once scored, its summary row."""
    from colonbench.server.client import Client, method_of, read_token, zip_folder

    client = Client(args.server, read_token(args.token_file), timeout=args.http_timeout)
    data = zip_folder(args.predictions)
    method = args.method or method_of(args.predictions)
    made = client.submit(args.suite, data, method, args.version, args.public)
    print(f"submission {made['id']}: {made['status']} ({made['files']} predictions, {len(data)} bytes, "
          f"{'public' if made['public'] else 'private'}) on {made['suite']}", flush=True)
    if not args.wait:
        print(f"follow it: colonbench submit --server {args.server} --status {made['id']}")
        return 0
    return _report(client.wait(made["id"], timeout=args.timeout, poll=args.poll,
                               report=lambda s: print(f"submission {s['id']}: {s['status']}", flush=True)))


def _report(got: dict) -> int:
    if got["status"] == "failed":
        print(f"submission {got['id']} failed: {got['reason']}", file=sys.stderr)
        return 1
    if got["status"] != "scored":
        print(f"submission {got['id']} is still {got['status']}; ask again later with --status {got['id']}")
        return 3
    for r in got["summary"]:
        mae = "n/a" if r["coverage_mae"] is None else f"{r['coverage_mae']:.2f}"
        print(f"noise {r['noise_mm']:g} mm  {got['method']}: MAE {mae} percentage points over {r['segments']} segments"
              + (f", {r['failed']} failed" if r["failed"] else ""))
    print(json.dumps(got))
    return 0


def cmd_status(args):
    """The state of an earlier submission (``submit --status ID``); with --wait, once it is final."""
    from colonbench.server.client import Client, read_token

    client = Client(args.server, read_token(args.token_file), timeout=args.http_timeout)
    got = client.wait(args.status, timeout=args.timeout if args.wait else 0, poll=args.poll)
    print(f"submission {got['id']}: {got['status']}")
    return _report(got) if got["status"] in ("scored", "failed") else 0



def _submit(args):
    if args.status:
        return cmd_status(args)
    if not args.suite or not args.predictions:
        from colonbench.errors import InputError

        raise InputError("give --suite NAME and PRED_DIR (or --status ID)")
    return cmd_submit(args)


def add_parsers(sub) -> None:
    """Add ``serve``, ``serve-worker``, ``serve-admin`` and ``submit`` to the ``colonbench`` subparsers."""
    p = sub.add_parser("serve", help="run the hidden-truth evaluation server (HTTP, with its scoring workers)",
                       description="Serve hidden suites: take predictions zips from teams with API tokens, score "
                                   "them in worker processes, and show each suite's public leaderboard "
                                   "(docs/server.md).")
    p.add_argument("--suites", nargs="+", required=True, metavar="DIR",
                   help="private folders of hidden suites (colonbench suites build hidden --data DIR)")
    p.add_argument("--db", default="sqlite:///server.db", help=DB_HELP)
    p.add_argument("--host", default="127.0.0.1", help="address to listen on (default 127.0.0.1)")
    p.add_argument("--port", type=int, default=8000, help="port (default 8000)")
    p.add_argument("--workers", type=int, default=1, help="scoring worker processes started beside it (default 1; "
                                                          "0: run colonbench serve-worker separately)")
    p.add_argument("--max-upload-mb", type=float, default=64.0, help="largest upload, MiB (default 64)")
    p.add_argument("--max-files", type=int, default=5000, help="most entries in an upload (default 5000)")
    p.add_argument("--forwarded-allow-ips", default="127.0.0.1",
                   help="proxies whose X-Forwarded-For is trusted (default 127.0.0.1)")
    p.add_argument("--quiet", action="store_true", help="log warnings only")
    p.set_defaults(func=_needs_extra(cmd_serve))

    p = sub.add_parser("serve-worker", help="score the server's queued submissions (any number, on one database)")
    p.add_argument("--suites", nargs="+", required=True, metavar="DIR", help="private folders of hidden suites")
    p.add_argument("--db", help=f"{DB_HELP}; default ${DB_ENV} where it is set")
    p.add_argument("--once", action="store_true", help="stop when no submission is queued")
    p.add_argument("--poll", type=float, default=1.0, help="seconds between looks at the queue (default 1)")
    p.add_argument("--stale-after", type=float, default=120.0,
                   help="a submission whose worker's heartbeat is older than this many seconds is queued again "
                        "(default 120)")
    p.add_argument("--max-attempts", type=int, default=2, help="claims of one submission before it is failed "
                                                               "(default 2)")
    p.add_argument("--slow", type=float, default=0.0, help=argparse.SUPPRESS)   # tests: seconds held per scoring
    p.add_argument("--parent", type=int, help=argparse.SUPPRESS)   # colonbench serve's pid: stop when it is gone
    p.set_defaults(func=_needs_extra(cmd_worker))

    p = sub.add_parser("serve-admin", help="the server's teams, API tokens, audit log and schema")
    p.add_argument("--db", default="sqlite:///server.db", help=DB_HELP)
    p.set_defaults(func=_needs_extra(cmd_admin), what=None, action=None)
    what = p.add_subparsers(dest="what", metavar="WHAT")
    t = what.add_parser("token", help="create, revoke or list API tokens")
    t.set_defaults(action=None)
    acts = t.add_subparsers(dest="action", metavar="ACTION")
    c = acts.add_parser("create", help="a new token of a team (the team is made where missing); printed once")
    c.add_argument("--team", required=True)
    c.add_argument("--label", default="", help="what the token is for")
    c.add_argument("--expires-days", type=float, help="refused after this many days (default: never)")
    r = acts.add_parser("revoke", help="revoke a token by its id (token list)")
    r.add_argument("id", type=int)
    acts.add_parser("list", help="every token: id, team, state (never the token)")
    tm = what.add_parser("team", help="set a team's submission limits (made where missing)")
    tm.add_argument("action", choices=["set"])
    tm.add_argument("team")
    tm.add_argument("--daily", type=int, help="submissions per UTC day (default: no limit)")
    tm.add_argument("--total", type=int, help="submissions in all (default: no limit)")
    a = what.add_parser("audit", help="the audit log's last lines")
    a.add_argument("--last", type=int, default=50)
    what.add_parser("migrate", help="make or upgrade the database to the newest schema")

    p = sub.add_parser("submit", help="upload predictions to an evaluation server and follow their scoring",
                       description="Zip PRED_DIR/<sample_id>.json and upload it to a colonbench server for a hidden "
                                   "suite; the token comes from $COLONBENCH_TOKEN or --token-file, never the "
                                   "command line (docs/server.md).")
    p.add_argument("predictions", nargs="?", metavar="PRED_DIR", help="folder of <sample_id>.json predictions")
    p.add_argument("--server", required=True, help="the server's address, http(s)://HOST[:PORT]")
    p.add_argument("--suite", help="the hidden suite's id")
    p.add_argument("--method", help="the method's name on the leaderboard (default: the 'method' every prediction "
                                     "gives, else the folder's name)")
    p.add_argument("--version", default="", help="the method's version")
    p.add_argument("--public", action="store_true", help="show it on the public leaderboard once scored")
    p.add_argument("--token-file", help="a file holding the API token (default: $COLONBENCH_TOKEN)")
    p.add_argument("--token", nargs="?", action=_NoToken, help=argparse.SUPPRESS)   # refused, never echoed
    p.add_argument("--wait", action="store_true", help="poll until it is scored or failed")
    p.add_argument("--status", metavar="ID", help="the state of an earlier submission, in place of an upload")
    p.add_argument("--timeout", type=float, default=600.0, help="--wait: give up after this many seconds (600)")
    p.add_argument("--poll", type=float, default=2.0, help="--wait: seconds between polls (default 2)")
    p.add_argument("--http-timeout", type=float, default=120.0, help=argparse.SUPPRESS)
    p.set_defaults(func=_submit)
