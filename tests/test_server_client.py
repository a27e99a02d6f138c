"""The evaluation server's client and commands without a server: the token never taken from (or echoed off) the
command line, redirects refused, a warning before a token goes over plain http, a clear word where the server's
packages are not installed."""

from __future__ import annotations

import http.server
import logging
import sys
import threading

import pytest

from colonbench.cli import main
from colonbench.errors import InputError

SECRET = "cbt_" + "5ec2e7" * 10 + "abcd"


@pytest.mark.parametrize("argv", [["--token", SECRET], [f"--token={SECRET}"], ["--token"]])
def test_a_token_on_the_command_line_is_refused_without_echoing_it(argv, capsys):
    with pytest.raises(SystemExit) as stop:
        main(["submit", "--server", "http://127.0.0.1:1", "--suite", "x", "preds", *argv])
    err = capsys.readouterr().err
    assert stop.value.code == 2 and SECRET not in err
    assert "never the command line" in err and "COLONBENCH_TOKEN" in err


def test_options_are_never_taken_by_their_abbreviation(tmp_path, capsys):
    """argparse's prefix matching would read --token-f FILE (or --token SECRET) as --token-file."""
    (tmp_path / "t").write_text(SECRET)
    with pytest.raises(SystemExit) as stop:
        main(["submit", "--server", "http://127.0.0.1:1", "--suite", "x", "preds", "--token-f", str(tmp_path / "t")])
    assert stop.value.code == 2 and "unrecognized arguments: --token-f" in capsys.readouterr().err


class _Redirecting(http.server.BaseHTTPRequestHandler):
    seen: list = []

    def do_GET(self):   # noqa: N802  (http.server's name)
        self.seen.append((self.path, self.headers.get("Authorization")))
        if self.path.startswith("/elsewhere"):
            self.send_response(200)
            self.send_header("Content-Type", "application/json")
            self.end_headers()
            self.wfile.write(b'{"ok": true}')
            return
        self.send_response(302)
        self.send_header("Location", f"http://127.0.0.1:{self.server.server_port}/elsewhere")
        self.end_headers()

    def log_message(self, *args):
        pass


def test_a_redirect_is_refused_and_the_token_not_sent_on(capsys):
    from colonbench.server.client import Client

    httpd = http.server.HTTPServer(("127.0.0.1", 0), _Redirecting)
    thread = threading.Thread(target=httpd.serve_forever, daemon=True)
    thread.start()
    try:
        _Redirecting.seen = []
        client = Client(f"http://127.0.0.1:{httpd.server_port}", SECRET, timeout=10)
        with pytest.raises(InputError, match="redirect") as refused:
            client.call("GET", "/api/v1/health")
        assert "/elsewhere" in str(refused.value) and SECRET not in str(refused.value)
        assert [p for p, _ in _Redirecting.seen] == ["/api/v1/health"]
    finally:
        httpd.shutdown()
        httpd.server_close()
        thread.join(timeout=10)


@pytest.mark.parametrize("server, warned", [("http://example.org", True), ("http://10.1.2.3:8000", True),
                                            ("http://127.0.0.1:8000", False), ("http://localhost:8000", False),
                                            ("http://[::1]:8000", False), ("https://example.org", False)])
def test_a_token_over_plain_http_to_another_host_is_warned_of(server, warned, caplog):
    from colonbench.server.client import Client

    with caplog.at_level(logging.WARNING, logger="colonbench"):
        Client(server, SECRET)
    said = " ".join(r.getMessage() for r in caplog.records)
    assert ("plain http" in said) is warned and SECRET not in said
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger="colonbench"):
        Client(server, None)
    assert not caplog.records


@pytest.mark.parametrize("missing, argv", [
    ("uvicorn", ["serve", "--suites", "nowhere"]),
    ("sqlalchemy", ["serve-admin", "--db", "sqlite:///x.db", "migrate"]),
    ("sqlalchemy", ["serve-worker", "--suites", "nowhere"]),
])
def test_without_the_server_extra_the_commands_say_what_to_install(missing, argv, monkeypatch, capsys, tmp_path):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setitem(sys.modules, missing, None)     # ``import missing`` raises ModuleNotFoundError
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "pip install 'colonbench[server]'" in err and "Traceback" not in err
    assert not (tmp_path / "x.db").exists()
