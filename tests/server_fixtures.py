"""Shared by the hidden-suite and server tests: a tiny hidden suite built once per test session."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

ROOT = Path(__file__).resolve().parents[1]
#: A seed of the size a secret seed must have (tests only: a real one is drawn or kept secret).
SEED = 2 ** 41 + 12345


def tiny_manifest(path: Path) -> Path:
    """The demo manifest cut to one test colon and two segments (50 and 60 mm): a hidden suite in seconds."""
    m = yaml.safe_load((ROOT / "data_manifests" / "demo.yaml").read_text())
    m["name"] = "tiny"
    m["config"]["segments"]["lengths_mm"] = [50.0, 60.0]
    m["splits"] = {"test": {**m["splits"]["test"], "colons": {"first": 3, "count": 1}, "segments_per_length": 1}}
    path.write_text(yaml.safe_dump(m, sort_keys=False))
    return path


@pytest.fixture(scope="session")
def hidden_suite(tmp_path_factory):
    """A tiny hidden suite built through the command line: (suite id, private root, published folder, seed)."""
    from colonbench.cli import main

    base = tmp_path_factory.mktemp("hidden")
    (base / "seed.txt").write_text(f"{SEED}\n")
    rc = main(["suites", "build", "hidden", "--from", str(tiny_manifest(base / "tiny.yaml")), "--data",
               str(base / "private"), "--publish", str(base / "public"), "--seed-file", str(base / "seed.txt"),
               "--quiet"])
    assert rc == 0
    (sid,) = [p.name for p in (base / "private").iterdir() if not p.name.startswith(".")]
    return sid, base / "private", base / "public", SEED


def write_predictions(folder: Path, ids, coverage: float = 0.5) -> Path:
    """One valid prediction per sample id."""
    import json

    folder.mkdir(parents=True, exist_ok=True)
    for sid in ids:
        (folder / f"{sid}.json").write_text(json.dumps({"coverage": coverage, "holes": [[0.0, 0.0, 1.0]],
                                                        "centerline": [[0.0, 0.0, 0.0], [0.0, 0.0, 1.0]]}))
    return folder
