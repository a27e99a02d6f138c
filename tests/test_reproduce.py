"""The shipped reference rows reproduce on this machine and under other CPU kernels (decisions 0321, 0322)."""

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from colonbench.benchmark import shipped, suites
from colonbench.errors import InputError


#: Kernels the shipped demo rows must reproduce under: the machine's own, and others that change the last bits as
#: another CPU does (OpenBLAS's core type for numpy's and scipy's BLAS / LAPACK, PyTorch's CPU capability).
KERNELS = {"default": {}, "sandybridge": {"OPENBLAS_CORETYPE": "Sandybridge"},
           "nehalem+aten-default": {"OPENBLAS_CORETYPE": "Nehalem", "ATEN_CPU_CAPABILITY": "default"}}


@pytest.mark.parametrize("kernel", list(KERNELS))
def test_shipped_demo_results_reproduce(demo_data, tmp_path, kernel):
    """The safety net of every refactoring, and of another machine: every built-in method gives the shipped demo-v1
    rows (as another machine may differ: coverages to 1e-6, threshold metrics by a few of their points) under the
    machine's kernels and under others; a failure names the method, its rows and the kernel."""
    env = {**os.environ, **KERNELS[kernel]}
    asked = KERNELS[kernel].get("OPENBLAS_CORETYPE")
    if asked:   # a CPU (or BLAS build) without that kernel runs its own: nothing to check there
        probe = "from colonbench.benchmark.runfolder import kernels; print(kernels().get('blas_core'))"
        ran = subprocess.run([sys.executable, "-c", probe], env=env, capture_output=True, text=True).stdout.strip()
        if ran != asked:
            pytest.skip(f"OPENBLAS_CORETYPE={asked} runs {ran} here")
    script = Path(__file__).resolve().parents[1] / "scripts" / "reproduce_shipped.py"
    proc = subprocess.run([sys.executable, str(script), "--suite", "demo-v1", "--data", str(demo_data),
                           "--out", str(tmp_path / "run")], env=env, capture_output=True, text=True)
    assert proc.returncode == 0, f"kernel {kernel} ({KERNELS[kernel] or 'as the machine runs'}):\n" \
                                 f"{proc.stdout}{proc.stderr[-3000:]}"
    out = proc.stdout
    assert all(f"  {m}: reproduces" in out for m in run_methods(tmp_path / "run")), out
    if asked:
        assert f"blas_core {asked}" in out, out


def run_methods(run) -> list:
    return list(json.loads((Path(run) / "run.json").read_text())["methods"])


def test_a_run_off_its_shipped_rows_is_named_by_method_row_and_column(tmp_path):
    """shipped.reproduction, which the reproduction check prints: a hole recall moved by more points than may flip
    in one row of unwrap-pca (an exact method) is that method's one differing cell; the others reproduce."""
    suite = suites.get("demo-v1")
    rows = shipped.load(suite)[1]
    (tmp_path / "results").mkdir()
    mine = {m: rows[rows["method"] == m].drop(columns=["sample_id"]).reset_index(drop=True)
            for m in ("unwrap-pca", "constant")}
    moved = mine["unwrap-pca"]
    moved.loc[3, "holes_recall_1mm"] += 10.0 / moved.loc[3, "holes_true_n"]
    for m, frame in mine.items():
        frame.to_csv(tmp_path / "results" / f"{m}.csv", index=False)
    found = shipped.reproduction(tmp_path, suite, ["unwrap-pca", "constant"])
    assert found["constant"].empty
    diff = found["unwrap-pca"]
    assert list(diff["column"]) == ["holes_recall_1mm"]
    assert (diff.iloc[0]["shard"], diff.iloc[0]["index"]) == (moved.loc[3, "shard"], moved.loc[3, "index"])
    with pytest.raises(InputError, match="no shipped rows of nothing-such"):
        shipped.reproduction(tmp_path, suite, ["nothing-such"])
