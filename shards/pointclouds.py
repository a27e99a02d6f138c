"""Point clouds from shards, for point-cloud networks (PointNet and the like).

:class:`PointCloudDataset` reads the geometry a shard stores (not its
heatmaps) and gives every item as fixed-size point sets, so that a batch is a
plain (B, N, 3) tensor: a sample of the partial cloud, and on request points
on the complete segment surface, GT hole points and the GT centerline. All
coordinates are mm in the shard's stored frame (the frame of the stored
``partial_points``; nothing is centred or scaled). Like
:class:`~colonbench.shards.reader.ShardDataset` it opens files lazily in the
process that reads them, so it can go to a ``torch.utils.data.DataLoader``
with any number of workers; PyTorch is imported only by :func:`collate_points`
(docs/shards.md, "Point clouds for point-cloud networks", has an example).
"""

from __future__ import annotations


import numpy as np

from colonbench import seeding
from colonbench.errors import InputError
from colonbench.shards import schema
from colonbench.shards.reader import ShardSamples, ragged_row

#: The point sets an item can hold (``fields`` of :class:`PointCloudDataset`).
FIELDS = ("partial", "complete", "holes", "centerline")


def fixed_size(rng: np.random.Generator, points: np.ndarray, n: int) -> np.ndarray:
    """A draw of exactly ``n`` rows of ``points``.

    Parameters
    ----------
    rng : numpy.random.Generator
    points : (m, 3) array, mm
    n : int, at least 1

    Returns
    -------
    (n, 3) float32
        ``n`` distinct rows drawn without replacement when ``m >= n``; else
        all ``m`` rows (shuffled) followed by ``n - m`` rows drawn with
        replacement; all NaN when ``m == 0``.
    """
    points = np.asarray(points, np.float32).reshape(-1, 3)
    m = len(points)
    if m == 0:
        return np.full((n, 3), np.nan, np.float32)
    if m >= n:
        idx = rng.choice(m, n, replace=False)
    else:
        idx = np.concatenate([rng.permutation(m), rng.integers(0, m, n - m)])
    return points[idx]


def surface_sample(rng: np.random.Generator, vertices, faces, n: int) -> np.ndarray:
    """``n`` points drawn uniformly by area on a triangle surface.

    Parameters
    ----------
    rng : numpy.random.Generator
    vertices : (v, 3) float, mm
    faces : (f, 3) int
    n : int

    Returns
    -------
    (n, 3) float32, mm
        Faces drawn in proportion to their area, then a uniform point in each
        (:func:`colonbench.meshes.sample_surface`); NaN if no area.
    """
    from colonbench.meshes import sample_surface

    pts = sample_surface(rng, vertices, faces, count=n)
    return pts.astype(np.float32) if len(pts) == n else np.full((n, 3), np.nan, np.float32)


def resample_polyline(line, n: int) -> np.ndarray:
    """A polyline resampled to ``n`` points evenly spaced by arc length, ends kept.

    Parameters
    ----------
    line : (m, 3) float, mm
    n : int

    Returns
    -------
    (n, 3) float32, mm
        Consecutive points ``L / (n - 1)`` apart along the line of length
        ``L``; a one-point line repeats its point, an empty one gives NaN.
    """
    p = np.asarray(line, float).reshape(-1, 3)
    if len(p) == 0:
        return np.full((n, 3), np.nan, np.float32)
    step = np.linalg.norm(np.diff(p, axis=0), axis=1)
    p = np.concatenate([p[:1], p[1:][step > 0]])          # repeated vertices would stall np.interp
    if len(p) == 1:
        return np.repeat(p, n, axis=0).astype(np.float32)
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(p, axis=0), axis=1))])
    t = np.linspace(0.0, s[-1], n)
    return np.stack([np.interp(t, s, p[:, j]) for j in range(3)], axis=1).astype(np.float32)


def _count(name: str, value, default=None) -> int:
    if value is None:
        return default
    if not isinstance(value, (int, np.integer)) or value < 1:
        raise InputError(f"PointCloudDataset: {name} must be an integer of at least 1, got {value!r}")
    return int(value)


class PointCloudDataset(ShardSamples):
    """A map-style dataset over shards: ``ds[k]`` is one sample as fixed-size point sets.

    Parameters
    ----------
    source : path or list of paths
        A dataset folder (its lock lists the shards) or shard files, as for
        :class:`~colonbench.shards.reader.ShardDataset`.
    split : str, optional
        Only this split of a dataset folder.
    points : int
        Points per set (N), at least 1.
    fields : sequence of str
        The point sets to return, any of ``"partial"``, ``"complete"``,
        ``"holes"``, ``"centerline"``.
    seed : int
        Root seed of the draws. Item ``k`` in epoch ``e`` draws field ``f``
        from stream ``("points", e, k, f)`` under ``seed``: the same whatever
        worker reads it, and one field's draw does not depend on the others.
    complete_points, hole_points : int, optional
        Size of ``"complete"`` and ``"holes"`` (default ``points``).
    centerline_points : int, optional
        Size of ``"centerline"`` (default 256).

    Items
    -----
    dict with, always:

    - ``partial_count`` int: the number of points of the stored partial cloud;
    - ``coverage`` float, ``noise_mm`` float (mm), ``hole_model`` str, ``index`` int;

    and per requested field (all float32, mm, the shard's stored frame):

    - ``partial`` (points, 3): the partial cloud, without replacement when it
      has at least ``points`` points, else all of them plus repeats;
    - ``complete`` (complete_points, 3): uniform by area on the complete segment surface;
    - ``holes`` (hole_points, 3): the GT hole points, sampled as ``partial``,
      all NaN when the segment has no holes; with ``holes_count`` int (0 then);
    - ``centerline`` (centerline_points, 3): the GT centerline, evenly spaced by arc length.
    """

    def __init__(self, source, split=None, points: int = 2048, fields=("partial",), seed: int = 0,
                 complete_points: int | None = None, hole_points: int | None = None,
                 centerline_points: int | None = None):
        self.points = _count("points", points)
        fields = (fields,) if isinstance(fields, str) else tuple(fields)
        unknown = [f for f in fields if f not in FIELDS]
        if unknown:
            raise InputError(f"PointCloudDataset: unknown field {unknown[0]!r}; choose from {list(FIELDS)}")
        self.fields = fields
        self.sizes = {"complete": _count("complete_points", complete_points, self.points),
                      "holes": _count("hole_points", hole_points, self.points),
                      "centerline": _count("centerline_points", centerline_points, 256)}
        super().__init__(source, split)
        self.seed = int(seed)

    def __getitem__(self, k: int) -> dict:
        shard, i = self.locate(k)
        k %= len(self)
        smp = shard.h5["samples"]
        off = smp["partial_points_offsets"]
        rng = {f: seeding.rng(self.seed, "points", self.epoch, k, f) for f in self.fields}  # per field
        item = {"index": int(k), "partial_count": int(off[i + 1] - off[i]),
                "coverage": float(smp["coverage"][i]), "noise_mm": float(smp["noise_mm"][i]),
                "hole_model": schema.HOLE_MODEL_NAMES[int(smp["hole_model"][i])]}
        if "partial" in self.fields:
            item["partial"] = fixed_size(rng["partial"], ragged_row(smp, "partial_points", i), self.points)
        if "complete" in self.fields:
            seg, m = shard.h5["segments"], int(smp["segment"][i])
            item["complete"] = surface_sample(rng["complete"], ragged_row(seg, "vertices", m),
                                              ragged_row(seg, "faces", m), self.sizes["complete"])
        if "holes" in self.fields:
            holes = ragged_row(smp, "hole_points", i)
            item["holes"] = fixed_size(rng["holes"], holes, self.sizes["holes"])
            item["holes_count"] = int(len(holes))
        if "centerline" in self.fields:
            item["centerline"] = resample_polyline(shard.centerline(i), self.sizes["centerline"])
        return item


def collate_points(items) -> dict:
    """Batch a list of :class:`PointCloudDataset` items into PyTorch tensors.

    Parameters
    ----------
    items : list of dict
        Items with the same keys and the same array shapes.

    Returns
    -------
    dict
        Arrays stacked to (B, N, 3) float32 tensors; ints to (B,) int64,
        floats to (B,) float32 tensors; strings to lists of length B.
    """
    import torch

    out = {}
    for key in items[0]:
        vals = [it[key] for it in items]
        first = vals[0]
        if isinstance(first, np.ndarray):
            out[key] = torch.from_numpy(np.stack(vals).astype(np.float32, copy=False))
        elif isinstance(first, (int, np.integer)):
            out[key] = torch.tensor(np.asarray(vals, np.int64))
        elif isinstance(first, (float, np.floating)):
            out[key] = torch.tensor(np.asarray(vals, np.float32))
        else:                                             # strings (and anything else): a list
            out[key] = list(vals)
    return out
