"""colonbench: synthetic colonoscopy coverage data and a coverage-estimation benchmark.

The package is one import namespace mapped onto the data-flow folders of the
repository::

    colonbench/      -> colonbench             command line, seeds, errors, grid, heatmaps, point I/O
    datagen/         -> colonbench.datagen     procedural and real colons, camera, holes, segments, video
    shards/          -> colonbench.shards      HDF5 shards, manifests, readers, packs
    completion/      -> colonbench.completion  the paper's learned completion method
    baselines/       -> colonbench.baselines   thresholding and 2D-unwrapping baselines
    mapping/         -> colonbench.mapping     whole-colon coverage maps
    benchmark/       -> colonbench.benchmark   suites, evaluation harness, statistics, shipped results
    reports/         -> colonbench.reports     leaderboards and figures
    data_manifests/  -> colonbench.data_manifests  the manifests and the real meshes they name

From Python::

    import colonbench as cb
    est = cb.load_method("completion").estimate(points_mm)     # an Estimate: coverage, holes, centerline
    result = cb.benchmark(my_method, "real-v1")                # any object with name and estimate(points)
    print(result["markdown"])

Geometry is in millimetres everywhere a user sees it. Importing colonbench
loads nothing heavy; each name below is imported when first used.
"""

import sys
import types

from colonbench._version import __version__
import colonbench.benchmark as _benchmark_package  # its __init__ imports nothing: this stays cheap
from colonbench.errors import ColonbenchError, InputError

__all__ = ["__version__", "ColonbenchError", "InputError", "Estimate", "Method", "load_method", "benchmark",
           "suites"]


class _CallableBenchmark(types.ModuleType):
    """The subpackage ``colonbench.benchmark``, callable as the function ``colonbench.benchmark(...)``."""

    def __call__(self, methods=(), suites="demo-v1", out=None, **options) -> dict:
        """Evaluate methods (names, specs or objects with ``name`` and ``estimate(points)``) on named suites.

        Parameters
        ----------
        methods : str, object or list of them
        suites : str or list of str
            Suite ids or names, or ``"all"``.
        out : path, optional
            The benchmark folder (default: a new temporary folder, kept after the call: ``result["out"]`` names it,
            and so does the markdown's last paragraph; delete it when done).
        **options
            As :func:`colonbench.pipeline.run_benchmark` (``data``, ``workers``, ``progress``, ...).

        Returns
        -------
        dict
            ``summary`` (a DataFrame: suite, noise, method, MAE and its interval, ...), ``markdown`` (the
            folder's ``leaderboard.md`` and a last paragraph naming the files written: the leaderboard and each
            suite's page, and whether the folder is a temporary one), ``paths``, ``runs``, ``seconds``,
            ``failures`` and ``out``.

        Raises
        ------
        colonbench.pipeline.RunFailed
            A method failed on every sample: no tables are written; the benchmark folder keeps its run folders
            (a temporary one too), whose rows say why.
        """
        import tempfile
        from pathlib import Path

        from colonbench.pipeline import RunFailed, run_benchmark

        made = out is None
        out = tempfile.mkdtemp(prefix="colonbench-benchmark-") if made else out
        try:
            result = run_benchmark(methods, suites, out, **options)
        except RunFailed:
            raise  # its message names the run folders, which hold every failure: kept
        except BaseException:
            if made:
                import shutil

                shutil.rmtree(out, ignore_errors=True)
            raise
        result["out"] = out
        pages = ", ".join(str(Path(out) / "suites" / s / "leaderboard.md") for s in result["summary"]["suite"].unique())
        made_here = (" (a temporary folder made for this call and kept: delete it when done, or give out=)"
                     if made else "")
        result["markdown"] += (f"\nWritten to {out}{made_here}: {Path(out) / 'leaderboard.md'} (.csv, .json), and "
                               f"each suite's page: {pages}.\n")
        return result


_benchmark_package.__class__ = _CallableBenchmark
benchmark = sys.modules["colonbench.benchmark"]


def suites():
    """The newest version of every named suite (:class:`colonbench.benchmark.suites.Suite`), in registry order."""
    from colonbench.benchmark.suites import latest

    return list(latest().values())


def __getattr__(name):
    if name in ("Estimate", "Method"):
        from colonbench import estimate

        return getattr(estimate, name)
    if name == "load_method":
        from colonbench.benchmark.registry import load_method

        return load_method
    raise AttributeError(f"module 'colonbench' has no attribute {name!r}")
