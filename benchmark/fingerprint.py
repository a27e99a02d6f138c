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


def _segment_record(geo: dict, sid: str, inputs: dict) -> dict:
    from colonbench.benchmark.signature import points_entry

    points = {f"input@{k}": points_entry(v) for k, v in inputs.items()}
    points["holes"] = points_entry(geo["hole_points"])
    points["centerline"] = points_entry(geo["centerline"])
    return {"sample": sid, "hole_model": str(geo["hole_model"]), "length_mm": float(geo["length_mm"]),
            "coverage": float(geo["coverage"]), "observed_faces": int(np.count_nonzero(geo["observed_faces"])),
            "exact": ["centerline"], "points": points}


def segments_fingerprint(data, picks, noise_mm, noise_seed: int) -> tuple[str, list[dict]]:
    """The content hash and per-sample signatures of the chosen samples of a segment dataset under a noise protocol.

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
    sha256 : str
        ``cb1-<sha256 hex>``: equal only for bit-identical data (after rounding).
    samples : list of dict
        One signature per sample (:mod:`colonbench.benchmark.signature`), in order.
    """
    from colonbench.benchmark.evaluate import noisy
    from colonbench.benchmark.exchange import sample_id
    from colonbench.shards.reader import Shard

    h = _Hasher()
    h.text("task", "segments")
    records = []
    for shard_name, indices in picks:
        with Shard(Path(data) / shard_name) as shard:
            for i in indices:
                geo = shard.geometry(i)
                h.text("hole_model", geo["hole_model"])
                h.lengths("length_mm", geo["length_mm"])
                h.fractions("coverage", geo["coverage"])
                h.lengths("hole_points", geo["hole_points"])
                h.lengths("centerline", geo["centerline"])
                inputs = {}
                for sigma in noise_mm:
                    h.text("sample", sample_id(shard_name, i, sigma))
                    inputs[f"{sigma:g}"] = noisy(geo["partial_points"], sigma, noise_seed, shard_name, i)
                    h.lengths("input", inputs[f"{sigma:g}"])
                records.append(_segment_record(geo, sample_id(shard_name, i, 0.0), inputs))
    return h.hexdigest(), records


def colons_fingerprint(data, picks, noise_mm, noise_seed: int) -> tuple[str, list[dict]]:
    """The content hash and per-sample signatures of the chosen samples of a whole-colon dataset (as above).

    A whole colon's signature also holds its true surface (vertices, and the observed faces' centres weighted by
    their areas: the per-face truth), centerline and face arc lengths, and the withdrawal trajectory.
    """
    from colonbench.benchmark.evaluate import noisy
    from colonbench.benchmark.exchange import sample_id
    from colonbench.benchmark.signature import points_entry, rounded, sketch
    from colonbench.meshes import triangle_areas
    from colonbench.shards.colonshard import ColonShard

    h = _Hasher()
    h.text("task", "colon")
    records = []
    for shard_name, indices in picks:
        shard = ColonShard(Path(data) / shard_name)
        truth = shard.colon()
        h.text("colon", shard_name)
        h.lengths("vertices", truth["vertices"])
        h.integers("faces", truth["faces"])
        h.lengths("centerline", truth["centerline"].points)
        h.lengths("face_arclength", truth["face_arclength"])
        centres = truth["vertices"][truth["faces"]].mean(axis=1)
        areas = triangle_areas(truth["vertices"], truth["faces"])
        # each face's arc length (the stretch of colon it belongs to) as the weight of its centre, in metres
        colon_entries = {"vertices": points_entry(truth["vertices"]),
                         "colon_centerline": points_entry(truth["centerline"].points),
                         "face_arclength": {"n": int(len(centres)),
                                            "s": rounded(sketch(centres, truth["face_arclength"] / 1e3))}}
        for i in indices:
            sample = shard.sample(i)
            h.text("hole_model", sample["hole_model"])
            h.fractions("coverage", sample["coverage"])
            h.integers("observed_faces", np.asarray(sample["observed_faces"], bool))
            h.lengths("positions", sample["positions"])
            points = dict(colon_entries)
            obs = np.asarray(sample["observed_faces"], bool)
            # the per-face truth: the observed faces' centres, each weighted by its area over the mean face area
            points["observed_surface"] = {"n": int(obs.sum()),
                                          "s": rounded(sketch(centres[obs], areas[obs] / areas.mean()))}
            points["positions"] = points_entry(sample["positions"])
            for sigma in noise_mm:
                h.text("sample", sample_id(shard_name, i, sigma))
                pts = noisy(sample["points"], sigma, noise_seed, shard_name, i)
                h.lengths("input", pts)
                points[f"input@{sigma:g}"] = points_entry(pts)
            records.append({"sample": sample_id(shard_name, i, 0.0), "hole_model": str(sample["hole_model"]),
                            "length_mm": 0.0, "coverage": float(sample["coverage"]),
                            "observed_faces": int(obs.sum()),
                            "exact": ["vertices", "colon_centerline", "face_arclength", "positions"],
                            "points": points})
    return h.hexdigest(), records


def surface_distances(data, shard_name: str, index: int, task: str = "segments") -> dict:
    """How far a sample's points lie from the true surface they are drawn on, mm.

    Returns
    -------
    dict
        ``input``: the largest distance of a noiseless input point from the sample's observed faces; ``holes``:
        of a hole point from its unobserved faces (segments only; 0 where a set is empty).
    """
    from colonbench.datagen.camera import SurfaceScene

    if task == "colon":
        from colonbench.shards.colonshard import ColonShard

        shard = ColonShard(Path(data) / shard_name)
        truth, sample = shard.colon(), shard.sample(index)
        sets = {"input": (sample["points"], sample["observed_faces"])}
        vertices, faces = truth["vertices"], truth["faces"]
    else:
        from colonbench.shards.reader import Shard

        with Shard(Path(data) / shard_name) as shard:
            geo = shard.geometry(index)
        obs = np.asarray(geo["observed_faces"], bool)
        sets = {"input": (geo["partial_points"], obs), "holes": (geo["hole_points"], ~obs)}
        vertices, faces = geo["vertices"], geo["faces"]
    out = {}
    for name, (points, on) in sets.items():
        points = np.asarray(points, float).reshape(-1, 3)
        if len(points) == 0:
            out[name] = 0.0
        elif not on.any():
            out[name] = float("inf")
        else:
            out[name] = float(SurfaceScene(vertices, np.asarray(faces)[on]).distance(points).max())
    return out
