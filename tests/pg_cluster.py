"""A throwaway PostgreSQL cluster for tests: initdb in a temporary folder (as the ``postgres`` user when the tests
run as root, which initdb refuses), started on a free loopback port, stopped and removed after. Skipped, saying
why, where PostgreSQL's binaries are not installed (scripts/system-deps.sh installs Debian's ``postgresql``)."""

from __future__ import annotations

import glob
import os
import shutil
import subprocess
import tempfile
import time
from pathlib import Path

import pytest


def _bin() -> Path | None:
    found = shutil.which("pg_ctl")
    if found:
        return Path(found).resolve().parent
    versions = sorted(glob.glob("/usr/lib/postgresql/*/bin/pg_ctl"), key=lambda p: int(Path(p).parts[-3]))
    return Path(versions[-1]).parent if versions else None


@pytest.fixture(scope="module")
def postgres_url():
    """``postgresql://postgres@127.0.0.1:PORT/postgres`` of a cluster started for the module's tests."""
    from server_helpers import free_port

    bindir = _bin()
    if bindir is None or not (bindir / "initdb").exists():
        pytest.skip("PostgreSQL is not installed (no pg_ctl, initdb): scripts/system-deps.sh installs it")
    as_user = []
    if os.geteuid() == 0:
        try:
            import pwd

            pwd.getpwnam("postgres")
        except KeyError:
            pytest.skip("running as root and there is no postgres user to run initdb as")
        runuser = shutil.which("runuser")
        if runuser is None:
            pytest.skip("running as root without runuser to run initdb as the postgres user")
        as_user = [runuser, "-u", "postgres", "--"]
    base = Path(tempfile.mkdtemp(prefix="colonbench-pg-"))
    data = base / "data"
    if as_user:
        shutil.chown(base, "postgres")
    port = free_port()

    def run(*args, timeout=120):
        return subprocess.run([*as_user, *map(str, args)], capture_output=True, text=True, timeout=timeout)

    done = run(bindir / "initdb", "-D", data, "-A", "trust", "-U", "postgres", "--no-sync", "-E", "UTF8")
    if done.returncode != 0:
        shutil.rmtree(base, ignore_errors=True)
        pytest.skip(f"initdb failed: {done.stderr.strip()[-300:]}")
    done = run(bindir / "pg_ctl", "-D", data, "-l", base / "log", "-w", "-t", "60", "-o",
               f"-h 127.0.0.1 -p {port} -k {base} -F", "start")
    try:
        if done.returncode != 0:
            pytest.fail(f"the PostgreSQL cluster did not start: {(base / 'log').read_text()[-1000:]}")
        yield f"postgresql://postgres@127.0.0.1:{port}/postgres"
    finally:
        run(bindir / "pg_ctl", "-D", data, "-m", "immediate", "-w", "-t", "60", "stop")
        time.sleep(0.2)
        shutil.rmtree(base, ignore_errors=True)
