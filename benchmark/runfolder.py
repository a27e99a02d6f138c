"""Run folders: their record (``run.json``), their CSV and JSON files, written atomically, and who may extend them.

A run folder is made by ``colonbench evaluate`` (segments or whole colons),
``colonbench benchmark`` (one per suite) or ``colonbench score``. Its
``run.json`` says what was evaluated (data identity, suite and hash, track, noise,
metric settings, methods with their versions, package versions, sessions); a
rerun with the same settings finishes it or adds methods, and anything else is
refused (:class:`RunMismatch`).
"""

from __future__ import annotations

import json
import os
import platform
import sys
from pathlib import Path

import numpy as np
import pandas as pd

from colonbench._version import __version__
from colonbench.benchmark import tracks
from colonbench.errors import InputError

RUN_FILE = "run.json"
RUN_FORMAT = "colonbench-run"
RUN_FORMAT_VERSION = 1


class RunMismatch(InputError):
    """The run folder holds a run with other data, settings or method versions."""


def write_csv(path: Path, rows, columns: list[str] | None = None) -> Path:
    """Rows (a DataFrame, or dicts with ``columns``) as CSV, atomically."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    df = rows if isinstance(rows, pd.DataFrame) else pd.DataFrame(rows, columns=columns)
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    df.to_csv(tmp, index=False)
    tmp.replace(path)
    return path


def read_rows(path) -> pd.DataFrame:
    """A per-segment (or per-map) results CSV; ``error`` is "" where there was none."""
    df = pd.read_csv(path, dtype={"error": str, "shard": str, "method": str, "hole_model": str})
    df["error"] = df["error"].fillna("")
    if "coverage_error" in df.columns and "interval_low" not in df.columns:   # rows written before intervals
        at = df.columns.get_loc("coverage_error") + 1
        df.insert(at, "interval_low", np.nan)
        df.insert(at + 1, "interval_high", np.nan)
    if "interval_high" in df.columns and "review" not in df.columns:      # rows written before the review count
        df.insert(df.columns.get_loc("interval_high") + 1, "review", np.nan)
    return df


def json_default(o):
    """numpy scalars for :func:`json.dumps`."""
    if isinstance(o, (np.floating, np.integer)):
        return o.item()
    if isinstance(o, np.bool_):
        return bool(o)
    raise TypeError(f"not JSON serializable: {type(o).__name__}")


def write_json(path: Path, obj: dict) -> Path:
    """A JSON file, atomically (numpy scalars allowed)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    tmp.write_text(json.dumps(obj, indent=1, default=json_default))
    tmp.replace(path)
    return path


#: The libraries whose versions shape the numbers (recorded in every run).
PACKAGES = ("numpy", "scipy", "trimesh", "open3d", "manifold3d", "scikit-image", "scikit-fmm", "edt", "h5py",
            "pandas", "torch", "monai", "safetensors")


def versions() -> dict:
    """Versions of colonbench, Python and the libraries that shape the numbers."""
    from importlib.metadata import PackageNotFoundError, version

    out = {"colonbench": __version__, "python": platform.python_version()}
    for pkg in PACKAGES:
        try:
            out[pkg] = version(pkg)
        except PackageNotFoundError:
            pass
    return out


def environment() -> dict:
    """The machine a run ran on, so that a difference between two machines' numbers can be explained: platform,
    CPU model, the CPU features numpy dispatches on, and the BLAS numpy uses."""
    out = {"platform": platform.platform(), "machine": platform.machine(), "cpu": _cpu_model(),
           "cpu_count": os.cpu_count()}
    try:
        from numpy._core._multiarray_umath import __cpu_features__

        out["numpy_cpu_features"] = sorted(k for k, on in __cpu_features__.items() if on)
    except ImportError:   # numpy < 2 keeps it elsewhere; the record is informative only
        pass
    try:
        import numpy as np

        blas = np.show_config(mode="dicts").get("Build Dependencies", {}).get("blas", {})
        out["blas"] = f"{blas.get('name', '?')} {blas.get('version', '')}".strip()
    except (TypeError, AttributeError):
        pass
    out.update(kernels())
    return out


def kernels() -> dict:
    """The compute kernels this process runs, which move the last bits of a result: the BLAS's core type
    (OpenBLAS picks one per CPU; ``OPENBLAS_CORETYPE`` overrides it) and PyTorch's CPU capability
    (``ATEN_CPU_CAPABILITY``).

    Returns
    -------
    dict
        ``blas_core`` (e.g. ``"Haswell"``; one entry per distinct BLAS library loaded, joined by ``,``) and
        ``torch_cpu_capability`` (e.g. ``"AVX512"``), each where it can be told.
    """
    out = {}
    try:
        import scipy.linalg  # noqa: F401  (scipy's BLAS loaded, as numpy's is, for threadpoolctl to see)
        from threadpoolctl import threadpool_info

        cores = sorted({i.get("architecture") or "?" for i in threadpool_info() if i.get("user_api") == "blas"})
        if cores:
            out["blas_core"] = ",".join(cores)
    except ImportError:
        pass
    try:
        if "torch" in sys.modules:   # never imported for this: a method without the network runs without it
            out["torch_cpu_capability"] = sys.modules["torch"].backends.cpu.get_cpu_capability()
    except (AttributeError, RuntimeError):
        pass
    return out


def _cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def method_record(spec: str, m) -> dict:
    """What a run keeps of a method: how it was named, its version, whether it is a reference, its class."""
    return {"spec": spec, "version": str(getattr(m, "version", "unversioned")),
            "uses_truth": bool(getattr(m, "uses_truth", False)),
            "reference": bool(getattr(m, "reference", getattr(m, "uses_truth", False))),
            "class": f"{type(m).__module__}.{type(m).__qualname__}"}


def open_run(out: Path, settings: dict, methods: dict[str, dict]) -> dict:
    """The run record: a new one, or the existing one extended by new methods (after checking it matches)."""
    path = out / RUN_FILE
    if path.exists():
        try:
            run = json.loads(path.read_text())
        except json.JSONDecodeError as exc:
            raise InputError(f"{path}: unreadable ({exc})") from None
        if run.get("format") != RUN_FORMAT:
            raise InputError(f"{path}: not a colonbench run")
        if "track" in settings and tracks.of_run(run) != settings["track"]:
            raise RunMismatch(f"{out} is a run of the {tracks.label(tracks.of_run(run))}, not the "
                              f"{tracks.label(settings['track'])}; a run folder holds one "
                              "track: evaluate into a new run folder (colonbench benchmark: another --out)")
        for key, value in settings.items():
            if key == "track":
                continue
            if key == "suite" and _suite_grown(run.get(key), value):
                run[key] = value       # recorded by an earlier version, which counted less of the same check
                continue
            if json.dumps(run.get(key), sort_keys=True) != json.dumps(value, sort_keys=True, default=json_default):
                raise RunMismatch(f"{out} is a run with other {key} ({run.get(key)!r}, now {value!r}); "
                                  "evaluate into a new run folder")
        for name, rec in methods.items():
            old = run["methods"].get(name)
            if old is not None and old["version"] != rec["version"]:
                why = ("; an exec: method's version is a hash of its command line and of the files it names (its "
                       "script), so one of them changed" if str(rec["version"]).startswith("command:") else "")
                raise RunMismatch(f"{out}: method {name!r} was evaluated as version {old['version']!r}, it is now "
                                  f"{rec['version']!r}{why}; a run never mixes two versions of a method: evaluate "
                                  "into a new run folder (colonbench benchmark: another --out), or undo the change")
            run["methods"].setdefault(name, rec)
    else:
        run = {"format": RUN_FORMAT, "format_version": RUN_FORMAT_VERSION, **settings, "methods": dict(methods),
               "sessions": []}
    return run


def _suite_grown(old, new) -> bool:
    """Whether a run's suite record ``old`` is ``new`` as an earlier version wrote it: every key it has the same, the
    keys it lacks only counts a later version adds (``redrawn_samples``, ``diverged_samples``)."""
    if not isinstance(old, dict) or not isinstance(new, dict) or old == new:
        return False
    return set(new) - set(old) <= {"redrawn_samples", "diverged_samples"} and set(old) <= set(new) and all(
        json.dumps(old[k], sort_keys=True) == json.dumps(new[k], sort_keys=True) for k in old)


def check_run_folder(out: Path) -> None:
    """Create a run folder, refusing a non-empty folder that holds no run."""
    out = Path(out)
    if out.is_dir() and not (out / RUN_FILE).exists() and any(not p.name.startswith(".") for p in out.iterdir()):
        raise InputError(f"{out} is not empty and holds no {RUN_FILE}; give a new or empty run folder")
    out.mkdir(parents=True, exist_ok=True)


def begin_run(out: Path, settings: dict, loaded: dict, data: Path) -> dict:
    """Open (or extend) the run record of a locked run folder, write it, and clear leftovers of killed runs."""
    records = {name: method_record(spec, m) for name, (spec, m) in loaded.items()}
    if settings.get("track", tracks.DEFAULT) != tracks.DEFAULT:   # whether each method is given the length
        records = {name: {**rec, "takes_length": tracks.takes_length(loaded[name][1])} for name, rec in records.items()}
    run = open_run(out, settings, records)
    run["versions"] = run.get("versions") or versions()
    run["environment"] = run.get("environment") or environment()
    run["data_path"] = str(data)
    write_json(out / RUN_FILE, run)
    for tmp in out.rglob(".*.tmp*"):
        tmp.unlink()
    return run


def read_run(run_dir) -> dict:
    """A run folder's record.

    Raises
    ------
    InputError
        Not a run folder, unreadable, or of another format version.
    """
    run_dir = Path(run_dir)
    path = run_dir / RUN_FILE
    if not path.is_file():
        raise InputError(f"{run_dir}: not a colonbench run (no {RUN_FILE}); colonbench evaluate writes one")
    try:
        run = json.loads(path.read_text())
    except json.JSONDecodeError as exc:
        raise InputError(f"{path}: unreadable ({exc})") from None
    if run.get("format") != RUN_FORMAT or run.get("format_version") != RUN_FORMAT_VERSION:
        raise InputError(f"{path}: not a colonbench run of format version {RUN_FORMAT_VERSION}")
    return run


def save_example(path: Path, pts, est, truth):
    """One segment's input, completed mesh, holes and centerlines, kept as an example of a run (``examples/``)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    with open(tmp, "wb") as fh:
        np.savez_compressed(fh, partial_points=pts.astype(np.float32),
                            mesh_vertices=np.asarray(est.mesh_vertices, np.float32),
                            mesh_faces=np.asarray(est.mesh_faces, np.int32),
                            hole_vertices=np.asarray(est.hole_vertices, bool),
                            centerline=np.asarray(est.centerline, np.float32),
                            true_centerline=truth["centerline"].astype(np.float32),
                            coverage=np.float64(est.coverage), true_coverage=np.float64(truth["coverage"]))
    tmp.replace(path)
