"""Start-up of ``colonbench estimate``: the time before the first segment is estimated, by stage.

    python scripts/bench_startup.py [--repeat 3]

Runs each measurement in a fresh interpreter (imports are what start-up is made of) on a partial segment made
here (a 60 mm tube of radius 15 mm with a window cut out, 2 points/mm^2), and prints per stage the median over
the repeats: the interpreter alone, importing the command line and building its parser, loading the method
(PyTorch, the network, the shipped weights), reading the file, the first estimate; then the wall time of the
real command ``colonbench estimate FILE --out-dir DIR``.
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

PROBE = """
import json, sys, time
t0 = time.perf_counter()
from colonbench.cli import build_parser
build_parser().parse_args(["estimate", sys.argv[1], "--out-dir", sys.argv[2]])
t1 = time.perf_counter()
from colonbench.benchmark.registry import load_method
method = load_method("completion")
t2 = time.perf_counter()
from colonbench.pointio import read_surface
points, _ = read_surface(sys.argv[1])
t3 = time.perf_counter()
method.estimate(points)
t4 = time.perf_counter()
print(json.dumps({"cli": t1 - t0, "method": t2 - t1, "read": t3 - t2, "estimate": t4 - t3,
                  "monai_imported": "monai" in sys.modules}))
"""


def tube_segment(path: Path) -> Path:
    """A 60 mm tube of radius 15 mm, 2 points/mm^2, with a 20 x 30 mm window cut out, as .npy (mm)."""
    rng = np.random.default_rng(0)
    n = int(2.0 * 2 * np.pi * 15.0 * 60.0)
    a, z = rng.uniform(0, 2 * np.pi, n), rng.uniform(0, 60, n)
    keep = ~((a < 20 / 15.0) & (z > 15) & (z < 45))
    np.save(path, np.c_[15 * np.cos(a), 15 * np.sin(a), z][keep])
    return path


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        cloud = tube_segment(Path(tmp) / "segment.npy")
        runs, interp, wall = [], [], []
        for _ in range(args.repeat):
            t = time.perf_counter()
            subprocess.run([sys.executable, "-c", "pass"], check=True)
            interp.append(time.perf_counter() - t)
            out = subprocess.run([sys.executable, "-c", PROBE, str(cloud), tmp], check=True, capture_output=True,
                                 text=True).stdout
            runs.append(json.loads(out.strip().splitlines()[-1]))
            t = time.perf_counter()
            subprocess.run([str(Path(sys.executable).with_name("colonbench")), "estimate", str(cloud), "--out-dir",
                            tmp], check=True, capture_output=True)
            wall.append(time.perf_counter() - t)
    med = {k: statistics.median(r[k] for r in runs) for k in ("cli", "method", "read", "estimate")}
    startup = statistics.median(interp) + med["cli"] + med["method"] + med["read"]
    print(f"interpreter {statistics.median(interp):.2f} s, command line and parser {med['cli']:.2f} s, method "
          f"(PyTorch, network, weights) {med['method']:.2f} s, read {med['read']:.3f} s: start-up {startup:.2f} s "
          f"before the first segment; first estimate {med['estimate']:.2f} s; colonbench estimate on one file "
          f"{statistics.median(wall):.2f} s in all (median of {args.repeat}); MONAI imported: "
          f"{any(r['monai_imported'] for r in runs)}")


if __name__ == "__main__":
    main()
