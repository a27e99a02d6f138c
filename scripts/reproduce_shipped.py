"""Check that this machine reproduces the shipped reference rows of a suite: evaluate the built-in methods and
compare, as another machine may differ (docs/benchmark.md, Results on another machine).

    python scripts/reproduce_shipped.py [--suite demo-v1] [--methods completion,unwrap,...] [--data DIR]
                                        [--out DIR] [--workers 2]

Prints the kernels the process ran (the BLAS's core type, PyTorch's CPU capability: set ``OPENBLAS_CORETYPE`` or
``ATEN_CPU_CAPABILITY`` to run others) and, per method, either that its rows reproduce or each differing cell
(row, column, ours, shipped, allowed). Exits 1 when a method differs beyond the bounds, 2 on bad input.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

from colonbench.benchmark import shipped, suites
from colonbench.benchmark.evaluate import evaluate
from colonbench.benchmark.registry import DEFAULT_METHODS
from colonbench.benchmark.runfolder import kernels
from colonbench.errors import InputError
from colonbench.reports.leaderboard import differing


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--suite", default="demo-v1", help="a segment suite with shipped rows (default: demo-v1)")
    ap.add_argument("--methods", default=",".join(DEFAULT_METHODS),
                    help="built-in methods, comma-separated (default: all of them)")
    ap.add_argument("--data", help="suite data folder (default: colonbench's cache; generated where missing)")
    ap.add_argument("--out", help="run folder to write (default: a temporary one, removed after)")
    ap.add_argument("--workers", type=int, default=2)
    args = ap.parse_args(argv)
    methods = [m.strip() for m in args.methods.split(",") if m.strip()]
    try:
        suite = suites.get(args.suite)
        root = Path(args.data) if args.data else suites.default_data_root()
        suites.ensure_data(suite, root, workers=args.workers, progress=False)
        with tempfile.TemporaryDirectory() as tmp:
            run = Path(args.out) if args.out else Path(tmp) / "run"
            t = time.perf_counter()
            evaluate(suites.data_dir(suite, root), methods, run, progress=False, workers=args.workers, examples=0)
            found = shipped.reproduction(run, suite, methods)
            # the kernels of this process: the evaluation's workers are its children and run the same
            try:
                import torch  # noqa: F401  (its CPU capability is told once it is loaded)
            except ImportError:
                pass
            where = ", ".join(f"{k} {v}" for k, v in kernels().items()) or "kernels unknown"
            print(f"{suite.id}: {len(methods)} methods evaluated in {time.perf_counter() - t:.0f} s ({where})")
            bad = 0
            for m, diff in found.items():
                if diff.empty:
                    print(f"  {m}: reproduces")
                    continue
                bad += 1
                rows = diff[["shard", "index", "noise_mm"]].drop_duplicates()
                print(f"  {m}: DIFFERS in {len(rows)} rows ({where}):")
                own = shipped.own_data(suite, m)
                if own:
                    print(f"    (its shipped rows were made on data {own['check']} of the published data, "
                          f"{differing(own)}: the rows of those samples differ on any machine whose data are not "
                          "the same as theirs)")
                print("    " + diff.to_string(index=False).replace("\n", "\n    "))
    except (InputError, ValueError) as e:   # ValueError: the run's rows hold other segments than the shipped
        print(f"error: {e}", file=sys.stderr)
        return 2
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
