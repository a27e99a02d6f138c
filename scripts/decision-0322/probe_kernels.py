"""Decision 0322's probe: demo-v1 evaluated under several BLAS / ATen kernels, rows compared exactly and by the bounds.

    python probe_kernels.py OUT [METHODS]
"""
import json, os, subprocess, sys
from pathlib import Path
import pandas as pd

out = Path(sys.argv[1]); methods = sys.argv[2] if len(sys.argv) > 2 else "unwrap,unwrap-pca,unwrap-gt,completion,thresholding"
kernels = {"haswell": {"OPENBLAS_CORETYPE": "Haswell"}, "sandybridge": {"OPENBLAS_CORETYPE": "Sandybridge"},
           "nehalem": {"OPENBLAS_CORETYPE": "Nehalem"}, "skylakex": {"OPENBLAS_CORETYPE": "SkylakeX"},
           "aten-default": {"OPENBLAS_CORETYPE": "Haswell", "ATEN_CPU_CAPABILITY": "default"}}
code = """
import sys
from colonbench.benchmark import suites
from colonbench.benchmark.evaluate import evaluate
evaluate(suites.data_dir(suites.get('demo-v1'), suites.default_data_root()), sys.argv[2].split(','), sys.argv[1],
         progress=False, workers=2, examples=0)
"""
for name, env in kernels.items():
    run = out / name
    if not (run / "results").is_dir():
        subprocess.run([sys.executable, "-c", code, str(run), methods], check=True, env={**os.environ, **env})
from colonbench.benchmark import shipped
key = ["shard", "index", "noise_mm"]
for m in methods.split(","):
    ref = pd.read_csv(out / "haswell" / "results" / f"{m}.csv").set_index(key).sort_index()
    for name in kernels:
        if name == "haswell":
            continue
        a = pd.read_csv(out / name / "results" / f"{m}.csv").set_index(key).sort_index()
        num = [c for c in a.columns if a[c].dtype.kind == "f"]
        exact = int(((a[num] - ref[num]).abs().fillna(0) > 0).any(axis=1).sum())
        cov = float((a["coverage"] - ref["coverage"]).abs().max())
        diff = shipped.differences(a.reset_index(), ref.reset_index(), counted=m not in shipped.EXACT)
        print(f"{m:12s} {name:12s} rows differing at all: {exact:2d}/{len(a)}  max |coverage diff| {cov:.1e}  "
              f"beyond the bounds: {len(diff)} cells", flush=True)
