"""Shared fixtures: small procedural colons and the real CT colon."""

from pathlib import Path

import pytest

REAL = Path(__file__).resolve().parents[1].parent / "shared" / "real"


@pytest.fixture(scope="session")
def small_config():
    """Default generator parameters on a coarser mesh, for speed."""
    from colonbench.datagen.generate import GeneratorConfig

    return GeneratorConfig.from_dict({"colon": {"ring_spacing_mm": 1.0, "edge_mm": 1.5}})


@pytest.fixture(scope="session")
def small_colon(small_config):
    from colonbench.datagen.generate import procedural_colon

    return procedural_colon(small_config, seed=7, colon_id=0)


@pytest.fixture(scope="session")
def real_dir():
    if not (REAL / "gca00090_large_intestine_mm.ply").is_file():
        pytest.skip("../shared/real is not beside this checkout")
    return REAL


MANIFESTS = Path(__file__).resolve().parents[1] / "data_manifests"


@pytest.fixture(scope="session")
def smoke_dataset(tmp_path_factory):
    """``data_manifests/smoke.yaml`` generated in one process: (folder, lock)."""
    from colonbench.shards.dataset import generate

    out = tmp_path_factory.mktemp("smoke") / "data"
    lock = generate(MANIFESTS / "smoke.yaml", out, workers=1, progress=False)
    return out, lock
