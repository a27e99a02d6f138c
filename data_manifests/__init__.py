"""The dataset manifests and the real colon meshes they name (``colonbench.data_manifests``).

Importable so that an installed colonbench finds the suites' manifests
(:func:`colonbench.benchmark.suites.manifest_dir`); the files are data, read
with ``colonbench generate data_manifests/NAME.yaml`` or through a suite.
"""
