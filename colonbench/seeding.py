"""Seeded random streams.

Every random draw in colonbench takes a :class:`numpy.random.Generator` that
descends from one root seed through :class:`numpy.random.SeedSequence`. Streams
are addressed by a path of non-negative integers (for example
``(colon_id, segment_id, permutation)``), so the same path always gives the same
stream whatever order or process computes it. There is no global random state.
"""

from __future__ import annotations

import hashlib

import numpy as np

#: Stable integer tags for the purposes that draw random numbers, so that adding
#: a new purpose never shifts the streams of the existing ones.
PURPOSE = {
    "colon": 1,
    "camera": 2,
    "spheres": 3,
    "points": 4,
    "noise": 5,
    "retry": 6,
    "split": 7,
    "augment": 8,
    "sample": 9,
}


def _tag(key) -> int:
    if isinstance(key, str):
        if key in PURPOSE:
            return PURPOSE[key]
        # any other string: a stable 32-bit hash (Python's hash() is salted)
        return int.from_bytes(hashlib.sha256(key.encode()).digest()[:4], "little")
    key = int(key)
    if key < 0:
        raise ValueError(f"seed path entries must be non-negative, got {key}")
    return key


def seed_sequence(root_seed: int, *path) -> np.random.SeedSequence:
    """The :class:`~numpy.random.SeedSequence` for ``path`` under ``root_seed``.

    Parameters
    ----------
    root_seed : int
        The root seed of a dataset or run (0 is a seed like any other).
    *path : int or str
        Where the stream sits below the root, e.g. ``("colon", 3)``.
    """
    if root_seed is None:
        raise ValueError("a root seed is required (0 is a valid seed)")
    return np.random.SeedSequence(entropy=int(root_seed), spawn_key=tuple(_tag(k) for k in path))


def rng(root_seed: int, *path) -> np.random.Generator:
    """A fresh :class:`numpy.random.Generator` for ``path`` under ``root_seed``."""
    return np.random.Generator(np.random.PCG64(seed_sequence(root_seed, *path)))
