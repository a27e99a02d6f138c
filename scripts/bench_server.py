"""A bounded load test of the evaluation server on loopback: CLIENTS teams upload SUBMISSIONS predictions zips in
all, at once, against a daily limit, while a reader loads the leaderboard page; then every accepted submission must
be scored exactly once, none lost, and no team over its limit.

    python scripts/bench_server.py [--clients 20] [--submissions 200] [--daily 8] [--workers 2] [--db URL]

It builds a tiny hidden suite (2 segments, 4 inputs) in a temporary folder, starts ``colonbench serve`` on a free
127.0.0.1 port over a SQLite file there (or ``--db``), and prints uploads per second, the p50 / p95 latency of an
upload and of the page, the time to score everything, and the checks. Exit 1 if a check fails.
"""

from __future__ import annotations

import argparse
import io
import json
import socket
import subprocess
import sys
import tempfile
import threading
import time
import urllib.error
import urllib.request
import zipfile
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[1]


def _call(url, data=None, token=None, timeout=120):
    req = urllib.request.Request(url, data=data, method="POST" if data is not None else "GET",
                                 headers={"Authorization": f"Bearer {token}"} if token else {})
    t = time.perf_counter()
    try:
        with urllib.request.urlopen(req, timeout=timeout) as r:
            body, status = r.read(), r.status
    except urllib.error.HTTPError as exc:
        body, status = exc.read(), exc.code
    return status, body, time.perf_counter() - t


def _pct(values, q):
    values = sorted(values)
    return values[min(len(values) - 1, int(round(q * (len(values) - 1))))] if values else float("nan")


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--clients", type=int, default=20)
    p.add_argument("--submissions", type=int, default=200)
    p.add_argument("--daily", type=int, default=8, help="each team's daily limit")
    p.add_argument("--workers", type=int, default=2)
    p.add_argument("--db", help="database URL (default: a SQLite file in the temporary folder)")
    p.add_argument("--timeout", type=float, default=1800, help="seconds to wait for the scoring")
    args = p.parse_args(argv)
    cb = [sys.executable, "-m", "colonbench.cli"]
    with tempfile.TemporaryDirectory(prefix="colonbench-bench-server-") as tmp:
        tmp = Path(tmp)
        m = yaml.safe_load((ROOT / "data_manifests" / "demo.yaml").read_text())
        m["name"], m["config"]["segments"]["lengths_mm"] = "tiny", [50.0, 60.0]
        m["splits"] = {"test": {**m["splits"]["test"], "colons": {"first": 3, "count": 1}, "segments_per_length": 1}}
        (tmp / "tiny.yaml").write_text(yaml.safe_dump(m))
        subprocess.run([*cb, "suites", "build", "hidden", "--from", tmp / "tiny.yaml", "--data", tmp / "private",
                        "--publish", tmp / "public", "--quiet"], check=True, capture_output=True)
        sid = json.loads((tmp / "public" / "suite.json").read_text())["suite"]["id"]
        ids = [line.split(",")[0] for line in (tmp / "public" / "index.csv").read_text().splitlines()[1:]]
        buf = io.BytesIO()
        with zipfile.ZipFile(buf, "w") as zf:
            for i in ids:
                zf.writestr(f"{i}.json", json.dumps({"coverage": 0.5, "holes": [], "centerline": []}))
        data = buf.getvalue()
        db = args.db or f"sqlite:///{tmp / 'server.db'}"
        tokens = []
        for k in range(args.clients):
            subprocess.run([*cb, "serve-admin", "--db", db, "team", "set", f"team{k}", "--daily", str(args.daily)],
                           check=True, capture_output=True)
            out = subprocess.run([*cb, "serve-admin", "--db", db, "token", "create", "--team", f"team{k}"],
                                 check=True, capture_output=True, text=True).stdout
            tokens.append(out.strip().splitlines()[-1])
        with socket.socket() as s:
            s.bind(("127.0.0.1", 0))
            port = s.getsockname()[1]
        base = f"http://127.0.0.1:{port}"
        server = subprocess.Popen([*cb, "serve", "--suites", tmp / "private", "--db", db, "--port", str(port),
                                   "--workers", str(args.workers), "--quiet"], stdout=subprocess.DEVNULL,
                                  stderr=open(tmp / "server.log", "w"))
        try:
            end = time.monotonic() + 60
            while time.monotonic() < end:
                try:
                    if _call(base + "/api/v1/health")[0] == 200:
                        break
                except OSError:
                    time.sleep(0.2)
            results, pages, stop = [], [], threading.Event()

            def client(k):
                for j in range(k, args.submissions, args.clients):
                    status, body, dt = _call(f"{base}/api/v1/suites/{sid}/submissions?method=m{k}&public=1", data,
                                             tokens[k])
                    results.append((k, status, json.loads(body), dt))

            def reader():
                while not stop.is_set():
                    pages.append(_call(f"{base}/suites/{sid}")[2])

            r = threading.Thread(target=reader)
            r.start()
            threads = [threading.Thread(target=client, args=(k,)) for k in range(args.clients)]
            t0 = time.perf_counter()
            for t in threads:
                t.start()
            for t in threads:
                t.join()
            upload_s = time.perf_counter() - t0
            accepted = {b["id"] for _, st, b, _ in results if st == 202}
            end = time.monotonic() + args.timeout
            while time.monotonic() < end:
                mine = [json.loads(_call(f"{base}/api/v1/submissions", token=t)[1])["submissions"] for t in tokens]
                states = {s["id"]: s["status"] for team in mine for s in team}
                if all(v in ("scored", "failed") for v in states.values()):
                    break
                time.sleep(1)
            scored_s = time.perf_counter() - t0
            stop.set()
            r.join()
        finally:
            server.terminate()
            server.wait(timeout=60)
        refused = [b.get("error") for _, st, b, _ in results if st != 202]
        per_team = {}
        for k, st, _, _ in results:
            per_team[k] = per_team.get(k, 0) + (st == 202)
        lat = [dt for *_, dt in results]
        print(f"{len(results)} uploads by {args.clients} clients in {upload_s:.1f} s "
              f"({len(results) / upload_s:.1f}/s); "
              f"upload latency p50 {_pct(lat, .5) * 1000:.0f} ms, p95 {_pct(lat, .95) * 1000:.0f} ms; "
              f"page p50 {_pct(pages, .5) * 1000:.0f} ms, p95 {_pct(pages, .95) * 1000:.0f} ms over {len(pages)} "
              f"loads; {len(accepted)} accepted, {len(refused)} refused, all scored or failed {scored_s:.0f} s after "
              f"the first upload with {args.workers} worker(s)")
        checks = {
            "no upload lost": set(states) == accepted,
            "every accepted submission scored": all(states[i] == "scored" for i in accepted),
            "no team over its daily limit": max(per_team.values()) <= args.daily,
            "every refusal is the daily limit": set(refused) <= {"daily_limit"},
            "the limit was reached": len(accepted) == min(args.submissions, args.clients * args.daily),
        }
        for name, ok in checks.items():
            print(f"{'ok  ' if ok else 'FAIL'} {name}")
        return 0 if all(checks.values()) else 1


if __name__ == "__main__":
    sys.exit(main())
