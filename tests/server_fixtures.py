"""Shared by the hidden-suite and server tests: the tiny hidden suite's manifest and seed (the ``hidden_suite``
fixture, built from them once per test session, is in conftest.py) and predictions for it."""

from __future__ import annotations

from pathlib import Path

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


def write_predictions(folder: Path, ids, coverage: float = 0.5) -> Path:
    """One valid prediction per sample id."""
    import json

    folder.mkdir(parents=True, exist_ok=True)
    for sid in ids:
        (folder / f"{sid}.json").write_text(json.dumps({"coverage": coverage, "holes": [[0.0, 0.0, 1.0]],
                                                        "centerline": [[0.0, 0.0, 0.0], [0.0, 0.0, 1.0]]}))
    return folder
