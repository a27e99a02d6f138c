"""Context packs: training samples for the in-context model, cut from whole-colon reconstructions.

``colonbench pack DATA --context`` on a whole-colon dataset (a ``task: colon``
manifest, such as ``colon-train.yaml``) cuts each reconstruction the way
``colonbench map`` does, along the true centerline into consecutive segments:

- each pass over a reconstruction starts at a random offset and draws each
  segment's arc length from :data:`LENGTH_MM`, its context margin from
  :data:`CONTEXT_MM` and the pass's Gaussian noise from :data:`NOISE_MM`
  (the widened suite's mix);
- a segment's points are those whose nearest centerline point lies within its
  window widened by the margin (the map's rule), its true surface the faces
  whose ``face_arclength`` does, and its centerline that stretch of the true
  centerline;
- its grid and slab are :func:`colonbench.slab.context_grid` and
  :func:`colonbench.slab.slab_occupancy`, as at inference.

A sample stores the pack's three occupancy grids (:mod:`colonbench.shards.pack`)
and the slab as a fourth, so training makes its heatmaps as for any pack and
gives the slab as the network's second input channel
(:mod:`colonbench.completion.packdata`). Everything a sample draws comes from
stream ``("context", shard, sample, pass)`` under the manifest's seed, so a
pack is made again the same from the same dataset.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from colonbench import seeding
from colonbench._version import __version__
from colonbench.errors import InputError
from colonbench.completion.method import MIN_POINTS
from colonbench.heatmaps import voxelize_mesh, voxelize_points, voxelize_polyline
from colonbench.shards.pack import (GRIDS, PACK_FORMAT, PACK_NAME, PACK_VERSION, SLAB, _pool, dataset_lock,
                                    write_split)
from colonbench.slab import Slab, context_grid, slab_occupancy

#: Context margin of a sample, mm (uniform): from none (the segment alone, its planes known) to 15 mm.
CONTEXT_MM = (0.0, 15.0)
#: Segment arc length, mm (uniform): the benchmark's 50-70 mm and the map's 60 mm, and beyond.
LENGTH_MM = (40.0, 80.0)
#: Gaussian noise of a pass over a reconstruction, sigma mm -> weight (the widened suite's mix).
NOISE_MM = {0.0: 0.4, 0.25: 0.15, 0.5: 0.2, 0.75: 0.1, 1.0: 0.15}
#: Passes over each reconstruction (each its own offset, lengths, margins and noise).
PASSES = 2
#: The grids a context pack stores per sample.
CONTEXT_GRIDS = GRIDS + (SLAB,)


def segment_windows(length: float, rng: np.random.Generator, lengths=LENGTH_MM) -> list[tuple[float, float]]:
    """Consecutive arc-length windows ``(lo, hi)`` over ``[0, length]`` mm, from a random offset, drawn lengths."""
    out, lo = [], float(rng.uniform(0.0, lengths[0]))
    while True:
        hi = lo + float(rng.uniform(*lengths))
        if hi > length:
            return out
        out.append((lo, hi))
        lo = hi


def context_sample(points: np.ndarray, point_s: np.ndarray, colon: dict, observed: np.ndarray, lo: float,
                   hi: float, margin: float, grid_options: dict) -> tuple[dict, float] | None:
    """The occupancy grids of one segment in context, and its true coverage; None with fewer points than the
    method estimates (:data:`colonbench.completion.method.MIN_POINTS`).

    Parameters
    ----------
    points : (n, 3) float
        The whole reconstruction, mm (noise included).
    point_s : (n,) float
        Arc length of each point's nearest true-centerline point, mm.
    colon : dict
        :meth:`colonbench.shards.colonshard.ColonShard.colon`.
    observed : (f,) bool
        Observed faces of the reconstruction.
    lo, hi : float
        The segment's window, mm of arc length.
    margin : float
        Context margin, mm.
    grid_options : dict
        ``size``, ``margin``, ``min_extent_mm``.

    Returns
    -------
    grids : dict
        ``s0``, ``s1``, ``c``, ``slab``: (S, S, S) bool.
    coverage : float
        Observed share of the true surface between ``lo`` and ``hi`` (by area).
    """
    from colonbench.completion.surface import triangle_areas

    a, b = lo - margin, hi + margin
    pts = points[(point_s >= a) & (point_s <= b)]
    cl = colon["centerline"]
    on = (cl.arclength >= a) & (cl.arclength <= b)
    if len(pts) < MIN_POINTS or on.sum() < 2:
        return None
    slab = Slab(cl.points[on], cl.arclength[on], lo, hi)
    grid = context_grid(pts, slab, **grid_options)
    fs = colon["face_arclength"]
    faces = colon["faces"][(fs >= a) & (fs <= b)]
    mine = (fs >= lo) & (fs <= hi)
    area = triangle_areas(colon["vertices"], colon["faces"][mine])
    coverage = float(area[observed[mine]].sum() / area.sum()) if area.sum() > 0 else float("nan")
    used, local = np.unique(faces, return_inverse=True)
    grids = {"s0": voxelize_points(grid, pts)[0],
             "s1": voxelize_mesh(grid, colon["vertices"][used], local.reshape(faces.shape))[0],
             "c": voxelize_polyline(grid, slab.line)[0], SLAB: slab_occupancy(grid, slab)}
    if not all(g.any() for g in grids.values()):
        return None
    return grids, coverage


def _pack_colon_shard(job) -> tuple[dict, list]:
    """Packed context samples of one whole-colon shard: rows (grid -> (k, S^3 / 8) uint8) and coverages."""
    from scipy.spatial import cKDTree

    from colonbench.shards.colonshard import ColonShard

    path, seed, grid_options = job
    shard = ColonShard(path)
    colon = shard.colon()
    tree = cKDTree(colon["centerline"].points)
    rows = {g: [] for g in CONTEXT_GRIDS}
    coverages = []
    for i in range(len(shard)):
        smp = shard.sample(i)
        for p in range(PASSES):
            rng = seeding.rng(seed, "context", shard.name, i, p)
            sigma = float(rng.choice(list(NOISE_MM), p=np.array(list(NOISE_MM.values())) / sum(NOISE_MM.values())))
            pts = smp["points"] + (rng.normal(0.0, sigma, smp["points"].shape) if sigma > 0 else 0.0)
            point_s = colon["centerline"].arclength[tree.query(pts)[1]]
            for lo, hi in segment_windows(float(colon["centerline"].arclength[-1]), rng):
                made = context_sample(pts, point_s, colon, smp["observed_faces"], lo, hi,
                                      float(rng.uniform(*CONTEXT_MM)), grid_options)
                if made is None:
                    continue
                for g in CONTEXT_GRIDS:
                    rows[g].append(np.packbits(made[0][g].ravel()))
                coverages.append(made[1])
    size = grid_options["size"]
    return {g: np.stack(r) if r else np.zeros((0, size ** 3 // 8), np.uint8) for g, r in rows.items()}, coverages


def write_context_pack(data_dir, out_dir, splits=("train", "validation"), workers: int = 1,
                       progress: bool = True) -> dict:
    """Write the context pack of a whole-colon dataset's splits.

    Parameters
    ----------
    data_dir : path
        A whole-colon dataset folder (``colonbench generate`` on a ``task: colon`` manifest).
    out_dir : path
        The pack folder (created; one that exists is refused: a context pack is written whole).
    splits : sequence of str
    workers : int
        Processes cutting shards (spawn pool; 1 = this process).
    progress : bool

    Returns
    -------
    dict
        The contents of ``pack.json``.
    """
    from colonbench.shards.dataset import dataset_manifest
    from colonbench.shards.manifest import task

    data_dir, out = Path(data_dir), Path(out_dir)
    lock = dataset_lock(data_dir, splits)
    manifest = dataset_manifest(data_dir)
    if task(manifest) != "colon":
        raise InputError(f"{data_dir}: not a whole-colon dataset (its manifest has no task: colon); --context cuts "
                         "segments in context out of whole reconstructions")
    if (out / PACK_NAME).exists():
        raise InputError(f"{out} holds a pack already; a context pack is written whole: use another --out")
    grid = manifest["grid"]
    grid_options = {"size": int(grid["size"]), "margin": int(grid["margin"]),
                    "min_extent_mm": float(grid["min_extent_mm"])}
    info = {"format": PACK_FORMAT, "format_version": PACK_VERSION, "colonbench": __version__,
            "manifest_name": lock.get("manifest_name"), "manifest_sha256": lock["manifest_sha256"],
            "source": data_dir.name, "inputs": ["heatmap", SLAB], "grid_options": {**grid_options, "context": True},
            "context": {"context_mm": list(CONTEXT_MM), "length_mm": list(LENGTH_MM),
                        "noise_mm": {str(k): v for k, v in NOISE_MM.items()}, "passes": PASSES},
            "splits": {}}
    out.mkdir(parents=True, exist_ok=True)
    seed = int(manifest["seed"])
    for split in splits:
        files = sorted(str(data_dir / name) for name in lock["shards"] if name.startswith(f"{split}/"))
        if not files:
            raise InputError(f"{data_dir}: split {split} has no shards")
        with _pool(workers) as pool:
            made = list(pool.map(_pack_colon_shard, [(f, seed, grid_options) for f in files]))
        n = sum(len(rows["s0"]) for rows, _ in made)
        if n == 0:
            raise InputError(f"{data_dir}: split {split} gave no segment with {MIN_POINTS} points or more")
        info["splits"][split] = write_split(out, split, grid_options["size"], n, CONTEXT_GRIDS,
                                            (rows for rows, _ in made), progress)
        if split == "train":
            info["train_coverage_mean"] = float(np.nanmean(np.concatenate([c for _, c in made])))
    tmp = out / (PACK_NAME + ".tmp")
    tmp.write_text(json.dumps(info, indent=1) + "\n")
    tmp.replace(out / PACK_NAME)
    return info
