"""What reaches the terminal: progress bars only on one, log lines elsewhere; the library's logging; verb usage."""

import functools
import http.server
import io
import logging
import re
import subprocess
import sys
import threading
from pathlib import Path

import pytest

from colonbench import progress
from colonbench.cli import main

CLI = [sys.executable, "-m", "colonbench.cli"]
SMOKE = Path(__file__).resolve().parents[1] / "data_manifests" / "smoke.yaml"


class _Clock:
    def __init__(self):
        self.t = 0.0

    def __call__(self):
        return self.t


class _Terminal(io.StringIO):
    def isatty(self):
        return True


def _percentages(records) -> list[int]:
    return [int(m.group(1)) for r in records if (m := re.search(r"\((\d+) %", r.getMessage()))]


def test_off_a_terminal_a_bar_logs_a_line_now_and_then(monkeypatch, caplog):
    clock = _Clock()
    monkeypatch.setattr(progress.time, "monotonic", clock)
    caplog.set_level(logging.INFO, logger="colonbench")
    with progress.bar(total=100, desc="work", unit="item") as b:   # 100 items in 1 s: the last line only
        for _ in range(100):
            clock.t += 0.01
            b.update()
    assert [r.getMessage() for r in caplog.records] == ["work: 100/100 item (100 %, 1 s)"]
    caplog.clear()
    b = progress.bar(total=100, desc="slow", unit="item")     # 100 items in 200 s: a line each tenth
    for _ in range(100):
        clock.t += 2
        b.update()
    b.close()
    assert _percentages(caplog.records) == list(range(10, 101, 10))
    caplog.clear()
    b = progress.bar(total=10000, desc="long", unit="item")    # 10000 items in 10000 s: a line a minute at most
    for _ in range(10000):
        clock.t += 1
        b.update()
    b.close()
    assert 150 <= len(caplog.records) <= 170 and _percentages(caplog.records) == sorted(_percentages(caplog.records))
    caplog.clear()
    assert list(progress.bar(["a", "b"], desc="each", unit="seg")) == ["a", "b"]    # iterated: the last line at its end
    assert [r.getMessage() for r in caplog.records] == ["each: 2/2 seg (100 %, 0 s)"]
    caplog.clear()
    for item in progress.bar(range(5), desc="quiet", enabled=False):   # --quiet: no line at all
        clock.t += 100
    assert not caplog.records


def test_on_a_terminal_a_bar_is_tqdm_and_off_one_nothing_is_drawn(monkeypatch, capsys):
    monkeypatch.setattr(sys, "stderr", _Terminal())
    assert progress.on_terminal()
    b = progress.bar(total=4, desc="draw", unit="item")
    b.update(3)
    b.update(5)            # past the total: stops at it
    assert b.n == 4
    b.close()
    assert "draw: 100%" in sys.stderr.getvalue()
    monkeypatch.setattr(sys, "stderr", io.StringIO())
    assert not progress.on_terminal()
    b = progress.bar(total=4, desc="draw")
    b.update(4)
    b.close()
    assert sys.stderr.getvalue() == ""    # a Python user who configured no logging sees nothing


@pytest.fixture
def http_file(tmp_path, monkeypatch):
    """A 300 kB file served over HTTP on this machine: (path, URL)."""
    (tmp_path / "www").mkdir()
    path = tmp_path / "www" / "blob.bin"
    path.write_bytes(bytes(range(256)) * 1200)
    monkeypatch.setenv("NO_PROXY", "127.0.0.1,localhost")

    class Quiet(http.server.SimpleHTTPRequestHandler):
        def log_message(self, *args):
            pass

    handler = functools.partial(Quiet, directory=str(path.parent))
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), handler)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    yield path, f"http://127.0.0.1:{server.server_address[1]}/{path.name}"
    server.shutdown()


def test_a_download_shows_one_bar_that_only_goes_forwards(http_file, tmp_path, monkeypatch, caplog):
    """pooch resets its bar before showing it full (0 -> 59 -> 0 -> 100 %); the suite fetch's bar does not."""
    import hashlib

    import pooch

    from colonbench.benchmark.archive import _download_bar

    path, url = http_file
    digest = hashlib.sha256(path.read_bytes()).hexdigest()
    monkeypatch.setattr(pooch.get_logger(), "disabled", True)     # no "Downloading data from ..."
    monkeypatch.setattr(sys, "stderr", _Terminal())
    pooch.retrieve(url, known_hash=f"sha256:{digest}", fname="a.bin", path=tmp_path / "a",
                   progressbar=_download_bar(url, True))
    drawn = [int(p) for p in re.findall(r"download:\s+(\d+)%", sys.stderr.getvalue())]
    assert drawn[-1] == 100 and drawn == sorted(drawn) and drawn.count(0) <= 1, drawn
    monkeypatch.setattr(progress.time, "monotonic", _Clock())
    monkeypatch.setattr(sys, "stderr", io.StringIO())
    caplog.set_level(logging.INFO, logger="colonbench")
    pooch.retrieve(url, known_hash=f"sha256:{digest}", fname="b.bin", path=tmp_path / "b",
                   progressbar=_download_bar(url, True))
    assert [r.getMessage() for r in caplog.records] == ["download: 0.3/0.3 MiB (100 %, 0 s)"]
    assert sys.stderr.getvalue() == ""


def test_a_command_writing_into_a_log_file_leaves_lines_not_redraws(tmp_path):
    log = tmp_path / "log.txt"
    with open(log, "w") as err:
        r = subprocess.run([*CLI, "generate", str(SMOKE), "--out", str(tmp_path / "data")], stdout=subprocess.PIPE,
                           stderr=err, text=True)
    assert r.returncode == 0 and "dataset.lock.json" in r.stdout
    text = log.read_text()
    assert "\r" not in text and text.splitlines() == [l for l in text.splitlines() if l.startswith("generate: 3/3")]
    assert len(text.splitlines()) == 1
    with open(log, "w") as err:
        r = subprocess.run([*CLI, "generate", str(SMOKE), "--out", str(tmp_path / "quiet"), "--quiet"],
                           stdout=subprocess.PIPE, stderr=err, text=True)
    assert r.returncode == 0 and log.read_text() == ""


def test_the_command_line_shows_the_library_log_for_its_run_only(capsys):
    from colonbench.cli import _log_to_stderr

    logger = logging.getLogger("colonbench.benchmark")
    for level, said in ((logging.INFO, "told at info\na warning\n"), (logging.WARNING, "a warning\n")):  # --quiet
        handler = _log_to_stderr(level)
        try:
            logger.info("told at info")
            logger.warning("a warning")
        finally:
            handler.close()
        assert capsys.readouterr().err == said
    assert not logging.getLogger("colonbench").handlers and logging.getLogger("colonbench").level == logging.NOTSET
    logger.info("after the command")      # a Python user who configured no logging sees nothing
    assert capsys.readouterr().err == ""
    assert main(["suites"]) == 0 and not logging.getLogger("colonbench").handlers


@pytest.mark.parametrize("argv, usage, wrong, close", [
    (["estimate", "--lenght-mm", "60", "x.ply"], "usage: colonbench estimate", "--lenght-mm", "--length-mm"),
    (["suites", "fetch", "demo-v1", "--url", "u", "--sha256", "0", "--quit"], "usage: colonbench suites fetch",
     "--quit", "--quiet"),
    (["benchmark", "--out", "x", "--suits", "demo"], "usage: colonbench benchmark", "--suits demo", "--suites"),
])
def test_a_mistyped_option_shows_the_verbs_usage_and_the_closest_option(argv, usage, wrong, close, capsys):
    with pytest.raises(SystemExit) as exit_:
        main(argv)
    err = capsys.readouterr().err
    assert exit_.value.code == 2
    assert err.startswith(usage), err
    assert f"error: unrecognized arguments: {wrong} (did you mean {close}?)" in err
    with pytest.raises(SystemExit):
        main(["estimate", "--out-dir", "x"])      # other errors as before, with the verb's usage
    err = capsys.readouterr().err
    assert err.startswith("usage: colonbench estimate") and "required: files" in err


def test_a_mistyped_verb_gets_the_closest_verb(capsys):
    with pytest.raises(SystemExit) as exit_:
        main(["benchmrk", "--out", "x"])
    err = capsys.readouterr().err
    assert exit_.value.code == 2 and err.startswith("usage: colonbench")
    assert "invalid choice: 'benchmrk' (did you mean benchmark?)" in err


@pytest.mark.parametrize("argv, said", [
    (["--methods", "python my.py"], "unknown method 'python my.py'; a program's command line is given as exec:PROGRAM "
                                    "ARGS: did you mean exec:python my.py?"),
    (["--methods", "thresholdng"], "unknown method 'thresholdng' (did you mean thresholding?)"),
    (["--methods", "constant", "--suites", "demo-v2"], "unknown suite 'demo-v2' (did you mean demo-v1?)"),
    (["--methods", "constant", "--suites", "dmeo-v1"], "unknown suite 'dmeo-v1' (did you mean demo-v1?)"),
])
def test_an_unknown_method_or_suite_is_refused_with_the_closest_and_no_folder_made(argv, said, demo_data, tmp_path,
                                                                                   capsys):
    out = tmp_path / "bench"
    assert main(["benchmark", *argv, "--out", str(out), "--data", str(demo_data), "--quiet", "--no-figures"]) == 2
    err = capsys.readouterr().err
    assert said in err and "Traceback" not in err, err
    assert not out.exists()
