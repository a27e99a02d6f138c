"""colonbench.benchmark: named suites, the evaluation harness, statistics and the shipped reference results.

The package is also a function: ``colonbench.benchmark(methods, suites="demo-v1", out=None, **options)`` runs
:func:`colonbench.benchmark.runner.run_benchmark` (``colonbench benchmark`` from Python), with ``out`` a new
temporary folder when not given.
"""

import sys
import types


class _CallableModule(types.ModuleType):
    def __call__(self, methods=(), suites="demo-v1", out=None, **options) -> dict:
        """Evaluate methods (names, specs or objects with ``name`` and ``estimate(points)``) on named suites.

        Parameters
        ----------
        methods : str, object or list of them
        suites : str or list of str
            Suite ids or names, or ``"all"``.
        out : path, optional
            The benchmark folder (default: a new temporary folder).
        **options
            As :func:`colonbench.benchmark.runner.run_benchmark` (``data``, ``workers``, ``progress``, ...).

        Returns
        -------
        dict
            ``summary`` (a DataFrame: suite, noise, method, MAE and its interval, ...), ``markdown``, ``paths``,
            ``runs``, ``seconds`` and ``out``.
        """
        import tempfile

        from colonbench.benchmark.runner import run_benchmark

        out = out if out is not None else tempfile.mkdtemp(prefix="colonbench-benchmark-")
        result = run_benchmark(methods, suites, out, **options)
        result["out"] = out
        return result


sys.modules[__name__].__class__ = _CallableModule
