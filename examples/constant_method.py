"""A coverage estimator outside colonbench: it answers 0.8 for every segment (no holes, no centerline).

The command contract of `colonbench estimate`, which any program can keep:
    python constant_method.py FILE.ply ... --out-dir DIR   ->   DIR/<file stem>.json
Benchmark it: colonbench benchmark --methods "exec:python examples/constant_method.py" --out runs/mine
"""
import json
import sys
from pathlib import Path

args = sys.argv[1:]
out = Path(args[args.index("--out-dir") + 1])
out.mkdir(parents=True, exist_ok=True)
for f in (a for a in args if a.endswith(".ply")):
    (out / f"{Path(f).stem}.json").write_text(json.dumps({"coverage": 0.8, "holes": [], "centerline": []}))
