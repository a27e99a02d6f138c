"""Make the shipped reference results: every built-in method on every suite and track, evaluated and published.

    python scripts/reference_results.py [--suites all] [--tracks points,length] [--data DIR] [--workers 2]
                                        [--out runs/reference] [--methods completion]

Each suite's data is generated where missing (and checked against its
published signature; a whole run is published only where the data are
bit-identical to the published data, the rows of --methods also where they
are within tolerance of them), the built-in methods are evaluated by colonbench benchmark
into OUT/runs/<suite>/ (the points track) and OUT@length/runs/<suite>/ (the
known-length track; resumable: rerun to finish), and each finished run is
copied into benchmark/shipped_results/<suite>/ or <suite>@length/
(colonbench.benchmark.shipped), from where colonbench benchmark merges it into
the tables of its track. The whole-colon suite has no known-length track and is
skipped there. Prints the time per suite and track.
"""

from __future__ import annotations

import argparse
import time

from colonbench.benchmark import shipped, suites, tracks
from colonbench.benchmark.colon_evaluate import ALL_METHODS
from colonbench.benchmark.registry import DEFAULT_METHODS
from colonbench.pipeline import run_benchmark


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--suites", default="all")
    ap.add_argument("--tracks", default=",".join(tracks.TRACKS), help="comma-separated (default: points,length)")
    ap.add_argument("--data", help="suite data folder (default: colonbench's cache)")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--out", default="runs/reference")
    ap.add_argument("--methods", help="only these built-in methods (comma-separated): their shipped rows are replaced, "
                                      "the other methods' kept")
    args = ap.parse_args()
    only = [m.strip() for m in args.methods.split(",")] if args.methods else None
    chosen = [tracks.check(t) for t in args.tracks.split(",") if t.strip()]
    for track in chosen:
        out = args.out if track == tracks.DEFAULT else f"{args.out}@{track}"
        for suite in suites.parse(args.suites):
            if suite.task == "colon" and track != tracks.DEFAULT:
                print(f"{suite.id}: skipped on the {tracks.label(track)}, which it does not have", flush=True)
                continue
            t = time.perf_counter()
            methods = only or list(ALL_METHODS if suite.task == "colon" else DEFAULT_METHODS)
            result = run_benchmark(methods, [suite], out, data=args.data, workers=args.workers, shipped=False,
                                   submitted=False, figures=False, progress=False, track=track)
            where = shipped.publish(result["runs"][suite.id], suite, methods=only, track=track)
            sec = result["seconds"][suite.id]
            print(f"{suite.id} ({tracks.label(track)}): {len(methods)} methods, data {sec['data_seconds']:.0f} s, "
                  f"evaluation {sec['evaluate_seconds']:.0f} s with {args.workers} workers -> {where} "
                  f"({time.perf_counter() - t:.0f} s in all)", flush=True)


if __name__ == "__main__":
    main()
