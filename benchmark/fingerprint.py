"""A suite's content hash: the inputs a method sees and the truth it is scored on, robust to float noise.

The hash identifies *what is scored*, not the bytes of the HDF5 files (which
change with the h5py and HDF5 versions that wrote them). It is a sha256 over,
for every evaluated sample in order and every noise level of the suite:

* the sample's id (:func:`colonbench.benchmark.exchange.sample_id`), its hole model and length;
* the input cloud the method is given, noise added (the same draw as ``colonbench evaluate``);
* the truth: the coverage, the hole points and the centerline of a segment; for a whole colon, its
  withdrawal trajectory, its observed-face mask and (once per colon) the true surface, centerline and the
  arc length of every face.

Lengths are rounded to 1 µm (integers of µm) and fractions to 1e-6 before
hashing, so harmless float noise across machines (the last bits of a
float32) leaves the hash alone, while any real change (one input point
moved by a µm, one truth value changed) moves it. Every array enters with
its name and shape.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np

#: Rounding before hashing: lengths to this many mm (1 µm), fractions to this step.
LENGTH_STEP_MM = 1e-3
FRACTION_STEP = 1e-6
#: Prefix of every fingerprint, so that the hashes name their recipe.
PREFIX = "cb1"


class _Hasher:
    """A sha256 fed named, shaped, rounded arrays."""

    def __init__(self):
        self.h = hashlib.sha256()

    def text(self, name: str, value) -> None:
        self.h.update(f"{name}={value}\n".encode())

    def lengths(self, name: str, a) -> None:
        self._ints(name, np.rint(np.asarray(a, dtype=np.float64) / LENGTH_STEP_MM))

    def fractions(self, name: str, a) -> None:
        self._ints(name, np.rint(np.asarray(a, dtype=np.float64) / FRACTION_STEP))

    def integers(self, name: str, a) -> None:
        self._ints(name, np.asarray(a))

    def _ints(self, name: str, a: np.ndarray) -> None:
        a = np.asarray(a)
        self.h.update(f"{name}:{a.shape}\n".encode())
        self.h.update(np.ascontiguousarray(a, dtype="<i8").tobytes())

    def hexdigest(self) -> str:
        return f"{PREFIX}-{self.h.hexdigest()}"


def segments_fingerprint(data, picks, noise_mm, noise_seed: int) -> str:
    """The content hash of the chosen samples of a segment dataset under a noise protocol.

    Parameters
    ----------
    data : path
        Dataset folder.
    picks : list of (shard name, [index, ...])
        :func:`colonbench.benchmark.evaluate.select`'s choice.
    noise_mm : sequence of float
        Noise sigmas, mm.
    noise_seed : int

    Returns
    -------
    str
        ``cb1-<sha256 hex>``.
    """
    from colonbench.benchmark.evaluate import noisy
    from colonbench.benchmark.exchange import sample_id
    from colonbench.shards.reader import Shard

    h = _Hasher()
    h.text("task", "segments")
    for shard_name, indices in picks:
        with Shard(Path(data) / shard_name) as shard:
            for i in indices:
                geo = shard.geometry(i)
                h.text("hole_model", geo["hole_model"])
                h.lengths("length_mm", geo["length_mm"])
                h.fractions("coverage", geo["coverage"])
                h.lengths("hole_points", geo["hole_points"])
                h.lengths("centerline", geo["centerline"])
                for sigma in noise_mm:
                    h.text("sample", sample_id(shard_name, i, sigma))
                    h.lengths("input", noisy(geo["partial_points"], sigma, noise_seed, shard_name, i))
    return h.hexdigest()


def colons_fingerprint(data, picks, noise_mm, noise_seed: int) -> str:
    """The content hash of the chosen samples of a whole-colon dataset under a noise protocol (as above)."""
    from colonbench.benchmark.evaluate import noisy
    from colonbench.benchmark.exchange import sample_id
    from colonbench.shards.colonshard import ColonShard

    h = _Hasher()
    h.text("task", "colon")
    for shard_name, indices in picks:
        shard = ColonShard(Path(data) / shard_name)
        truth = shard.colon()
        h.text("colon", shard_name)
        h.lengths("vertices", truth["vertices"])
        h.integers("faces", truth["faces"])
        h.lengths("centerline", truth["centerline"].points)
        h.lengths("face_arclength", truth["face_arclength"])
        for i in indices:
            sample = shard.sample(i)
            h.text("hole_model", sample["hole_model"])
            h.fractions("coverage", sample["coverage"])
            h.integers("observed_faces", np.asarray(sample["observed_faces"], bool))
            h.lengths("positions", sample["positions"])
            for sigma in noise_mm:
                h.text("sample", sample_id(shard_name, i, sigma))
                h.lengths("input", noisy(sample["points"], sigma, noise_seed, shard_name, i))
    return h.hexdigest()
