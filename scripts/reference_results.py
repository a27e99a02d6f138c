"""Make the shipped reference results: every built-in method on every suite, evaluated and published.

    python scripts/reference_results.py [--suites all] [--data DIR] [--workers 2] [--out runs/reference]
                                        [--methods completion]

Each suite's data is generated where missing (and checked against its
published hash), the built-in methods are evaluated into OUT/runs/<suite>/ by
colonbench benchmark (resumable: rerun to finish), and the finished run is
copied into benchmark/shipped_results/<suite>/ (colonbench.benchmark.shipped),
from where colonbench benchmark merges it. Prints the time per suite.
"""

from __future__ import annotations

import argparse
import time

from colonbench.benchmark import shipped, suites
from colonbench.benchmark.colon_evaluate import ALL_METHODS
from colonbench.benchmark.registry import DEFAULT_METHODS
from colonbench.pipeline import run_benchmark


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--suites", default="all")
    ap.add_argument("--data", help="suite data folder (default: colonbench's cache)")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--out", default="runs/reference")
    ap.add_argument("--methods", help="only these built-in methods (comma-separated): their shipped rows are replaced, "
                                      "the other methods' kept")
    args = ap.parse_args()
    only = [m.strip() for m in args.methods.split(",")] if args.methods else None
    for suite in suites.parse(args.suites):
        t = time.perf_counter()
        methods = only or list(ALL_METHODS if suite.task == "colon" else DEFAULT_METHODS)
        result = run_benchmark(methods, [suite], args.out, data=args.data, workers=args.workers, shipped=False,
                               figures=False, progress=False)
        where = shipped.publish(result["runs"][suite.id], suite, methods=only)
        sec = result["seconds"][suite.id]
        print(f"{suite.id}: {len(methods)} methods, data {sec['data_seconds']:.0f} s, evaluation "
              f"{sec['evaluate_seconds']:.0f} s with {args.workers} workers -> {where} "
              f"({time.perf_counter() - t:.0f} s in all)", flush=True)


if __name__ == "__main__":
    main()
