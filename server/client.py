"""The evaluation server's client (``colonbench submit``): zip a predictions folder, upload it, follow it.

The token is read from the environment (``COLONBENCH_TOKEN``) or a file, never from the command line (where other
users of the machine and the shell's history would see it). It is sent to the server named and nowhere else: a
redirect is refused (naming where it pointed), not followed with the token; sending it over plain ``http://`` to
a host that is not this machine is warned of. Only the standard library is used, so a participant needs nothing
beyond colonbench itself.
"""

from __future__ import annotations

import io
import ipaddress
import json
import logging
import os
import time
import urllib.error
import urllib.parse
import urllib.request
import zipfile
from pathlib import Path

from colonbench.errors import InputError

ENV = "COLONBENCH_TOKEN"
FINAL = ("scored", "failed")
log = logging.getLogger("colonbench.server.client")


class _NoRedirects(urllib.request.HTTPRedirectHandler):
    """Redirects are answered as the error they are (the request, and its token, goes nowhere else)."""

    def redirect_request(self, req, fp, code, msg, headers, newurl):
        return None


def _loopback(host: str) -> bool:
    """Whether ``host`` (a URL's host name) is this machine."""
    if host.lower() in ("localhost", "localhost.") or host.lower().endswith(".localhost"):
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def read_token(token_file=None) -> str:
    """The API token: from ``token_file`` if given, else ``$COLONBENCH_TOKEN``.

    Raises
    ------
    InputError
        Neither gives one.
    """
    if token_file:
        try:
            token = Path(token_file).read_text().strip()
        except OSError as exc:
            raise InputError(f"{token_file}: cannot read the token ({exc.strerror})") from None
        if not token:
            raise InputError(f"{token_file}: empty; it should hold the token colonbench serve-admin printed")
        return token
    token = os.environ.get(ENV, "").strip()
    if not token:
        raise InputError(f"no API token: set {ENV} or pass --token-file FILE (never the token itself)")
    return token


def zip_folder(folder) -> bytes:
    """The ``<sample_id>.json`` files of a folder as one zip (flat; other files left out).

    Raises
    ------
    InputError
        No such folder, or no ``.json`` file in it.
    """
    folder = Path(folder)
    if not folder.is_dir():
        raise InputError(f"{folder}: no such folder of predictions")
    files = sorted(p for p in folder.glob("*.json") if p.is_file() and not p.is_symlink())
    if not files:
        raise InputError(f"{folder}: no <sample_id>.json predictions in it (docs/formats.md)")
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as zf:
        for p in files:
            zf.write(p, p.name)
    return buf.getvalue()


def method_of(folder) -> str:
    """The method a folder of predictions names: the ``method`` its ``<sample_id>.json`` files all give (the score
    contract's field), else the folder's name.

    Returns
    -------
    str
        The name shown on the leaderboard when ``colonbench submit`` is given no ``--method``.
    """
    folder = Path(folder)
    names = set()
    for p in sorted(folder.glob("*.json")):
        try:
            got = json.loads(p.read_text()).get("method")
        except (OSError, ValueError, AttributeError):   # the server names what is wrong with such a file
            return folder.resolve().name
        names.add(got if isinstance(got, str) and got.strip() else None)
    return names.pop() if len(names) == 1 and None not in names else folder.resolve().name


class Client:
    """Calls to one server with one token."""

    def __init__(self, server: str, token: str | None = None, timeout: float = 60.0):
        parts = urllib.parse.urlsplit(server)
        if parts.scheme not in ("http", "https") or not parts.netloc:
            raise InputError(f"--server {server}: an http:// or https:// address")
        self.base, self.token, self.timeout = server.rstrip("/"), token, timeout
        self.opener = urllib.request.build_opener(_NoRedirects)
        if token and parts.scheme == "http" and not _loopback(parts.hostname or ""):
            log.warning("warning: the API token is sent over plain http to %s, where anyone on the way can read it; "
                        "use https:// (a TLS-terminating proxy in front of the server, docs/server.md)", parts.netloc)

    def call(self, method: str, path: str, body: bytes | None = None, query: dict | None = None) -> tuple[int, dict]:
        """One request; the status and JSON body (an error's body too).

        Raises
        ------
        InputError
            The server cannot be reached, answers with a redirect (never followed), or its answer is not JSON.
        """
        url = self.base + path + ("?" + urllib.parse.urlencode(query) if query else "")
        headers = {"Accept": "application/json"}
        if self.token:
            headers["Authorization"] = f"Bearer {self.token}"
        if body is not None:
            headers["Content-Type"] = "application/zip"
        req = urllib.request.Request(url, data=body, headers=headers, method=method)
        try:
            with self.opener.open(req, timeout=self.timeout) as resp:
                status, raw = resp.status, resp.read()
        except urllib.error.HTTPError as exc:
            status, raw = exc.code, exc.read()
            if 300 <= status < 400:
                raise InputError(f"{self.base} answered {status}, a redirect to {exc.headers.get('Location')!r}, "
                                 "which is not followed (the token goes to the --server named only): give "
                                 "--server the address it points to") from None
        except (urllib.error.URLError, OSError) as exc:
            raise InputError(f"cannot reach {self.base}: {getattr(exc, 'reason', exc)}") from None
        try:
            return status, json.loads(raw)
        except ValueError:
            raise InputError(f"{self.base} answered {status} without JSON: is it a colonbench server?") from None

    def checked(self, method: str, path: str, **kw) -> dict:
        """:meth:`call`, an error answer raised as its message and problems."""
        status, body = self.call(method, path, **kw)
        if status >= 400:
            problems = body.get("problems") or []
            more = "".join(f"\n  {p}" for p in problems)
            raise InputError(f"the server refused ({status} {body.get('error')}): {body.get('message')}{more}")
        return body

    def submit(self, suite: str, data: bytes, method: str, version: str = "", public: bool = False) -> dict:
        """Upload a predictions zip; the queued submission."""
        return self.checked("POST", f"/api/v1/suites/{urllib.parse.quote(suite, safe='')}/submissions", body=data,
                            query={"method": method, "version": version, "public": int(bool(public))})

    def status(self, submission: str) -> dict:
        """A submission of the token's team."""
        return self.checked("GET", f"/api/v1/submissions/{urllib.parse.quote(submission, safe='')}")

    def wait(self, submission: str, timeout: float = 600.0, poll: float = 2.0, report=None) -> dict:
        """Poll a submission until it is scored or failed, or ``timeout`` seconds pass (then its last state)."""
        end = time.monotonic() + timeout
        last = None
        while True:
            got = self.status(submission)
            if report is not None and got["status"] != last:
                report(got)
            last = got["status"]
            if got["status"] in FINAL or time.monotonic() >= end:
                return got
            time.sleep(min(poll, max(0.0, end - time.monotonic())))
