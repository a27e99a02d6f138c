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

from colonbench._version import __version__
from colonbench.errors import ColonbenchError, InputError

__all__ = ["__version__", "ColonbenchError", "InputError", "Estimate", "Method", "load_method", "benchmark",
           "suites"]


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
    if name == "benchmark":  # the subpackage, callable: cb.benchmark(method, "real-v1")
        import importlib

        return importlib.import_module("colonbench.benchmark")
    raise AttributeError(f"module 'colonbench' has no attribute {name!r}")
