"""Shared fixtures: small procedural colons, the real CT colon, and the tiny hidden suite of the server's tests
(built once per session)."""

from pathlib import Path

import pytest

#: The real CT colons the project carries (data_manifests/meshes/README.md: source and licence).
REAL = Path(__file__).resolve().parents[1] / "data_manifests" / "meshes"


def script(name: str):
    """scripts/<name>.py as a module (a script, not part of the package)."""
    import importlib.util

    spec = importlib.util.spec_from_file_location(name, Path(__file__).resolve().parents[1] / "scripts" / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="session")
def calibrate_intervals():
    """scripts/calibrate_intervals.py as a module."""
    return script("calibrate_intervals")


@pytest.fixture(scope="session")
def map_intervals():
    """scripts/map_intervals.py as a module."""
    return script("map_intervals")


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
        pytest.skip("data_manifests/meshes holds no real colon (a partial checkout?)")
    return REAL


MANIFESTS = Path(__file__).resolve().parents[1] / "data_manifests"


@pytest.fixture(scope="session", autouse=True)
def no_submitted_results(tmp_path_factory):
    """Every test sees an empty registry of submitted results (the repository's results/ grows by pull request,
    and the tables a test checks must not change with it); a test of submitted results sets its own
    ($COLONBENCH_RESULTS)."""
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("COLONBENCH_RESULTS", str(tmp_path_factory.mktemp("no-submitted-results")))
        yield


@pytest.fixture(scope="session")
def smoke_dataset(tmp_path_factory):
    """``data_manifests/smoke.yaml`` generated in one process: (folder, lock)."""
    from colonbench.shards.dataset import generate

    out = tmp_path_factory.mktemp("smoke") / "data"
    lock = generate(MANIFESTS / "smoke.yaml", out, workers=1, progress=False)
    return out, lock


@pytest.fixture(scope="session")
def smoke_pack(smoke_dataset, tmp_path_factory):
    """The smoke dataset packed (``colonbench pack``): (data folder, lock, pack folder, pack.json)."""
    from colonbench.shards.pack import write_pack

    data, lock = smoke_dataset
    out = tmp_path_factory.mktemp("pack") / "pack"
    info = write_pack(data, out, workers=1, progress=False)
    return data, lock, out, info


@pytest.fixture(scope="session")
def tiny_run(smoke_dataset, tmp_path_factory):
    """One epoch of the completion network on the smoke dataset: (data, run folder, TrainConfig, result)."""
    pytest.importorskip("torch")
    from colonbench.completion.train import TrainConfig, train

    out, _ = smoke_dataset
    run = tmp_path_factory.mktemp("run")
    cfg = TrainConfig(epochs=1, batch_size=2, workers=0, augment_prob=0.5)
    result = train(out, run, cfg, device="cpu", progress=False)
    return out, run, cfg, result


@pytest.fixture(scope="session")
def demo_data(tmp_path_factory):
    """demo-v1 generated from its manifest, as colonbench benchmark makes it: the data root."""
    from colonbench.benchmark import suites

    root = tmp_path_factory.mktemp("suites")
    suites.ensure_data(suites.get("demo-v1"), root, workers=2, progress=False)
    return root


@pytest.fixture(scope="session")
def hidden_suite(tmp_path_factory):
    """A tiny hidden suite built through the command line: (suite id, private root, published folder, seed)."""
    from server_fixtures import SEED, tiny_manifest

    from colonbench.cli import main

    base = tmp_path_factory.mktemp("hidden")
    (base / "seed.txt").write_text(f"{SEED}\n")
    rc = main(["suites", "build", "hidden", "--from", str(tiny_manifest(base / "tiny.yaml")), "--data",
               str(base / "private"), "--publish", str(base / "public"), "--seed-file", str(base / "seed.txt"),
               "--quiet"])
    assert rc == 0
    (sid,) = [p.name for p in (base / "private").iterdir() if not p.name.startswith(".")]
    return sid, base / "private", base / "public", SEED
