"""colonbench.benchmark: named suites, the evaluation harness, statistics and the shipped reference results.

``colonbench.benchmark`` is also callable: ``colonbench.benchmark(methods, suites="demo-v1", out=None, **options)``
runs :func:`colonbench.pipeline.run_benchmark` (``colonbench benchmark`` from Python; see :mod:`colonbench`).
"""
