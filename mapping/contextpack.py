"""Context packs: training samples for the in-context model, cut from whole-colon reconstructions.

``colonbench pack DATA --context`` on a whole-colon dataset (a ``task: colon``
manifest, such as ``colon-train.yaml``) cuts each reconstruction the way
``colonbench map`` does, by default along the true centerline, into consecutive segments:

- each pass over a reconstruction starts at a random offset and draws each
  segment's arc length from :data:`LENGTH_MM`, its context margin from
  :data:`CONTEXT_MM` and the pass's Gaussian noise from :data:`NOISE_MM`
  (the widened suite's mix);
- a segment's points are those whose nearest centerline point lies within its
  window widened by the margin (the map's rule), its true surface the faces
  whose ``face_arclength`` does, and its centerline that stretch of the true
  centerline;
- with ``--context-line map`` the reconstruction is cut instead along the
  centerline ``colonbench map`` finds in each noisy pass (its pieces, its
  trajectory bridges), as inference cuts it: the slab and the grid follow that
  line, and the truth of a window is the stretch of the true centerline between
  the true points nearest to its ends (the whole-colon benchmark's rule); the
  target surface and centerline are the true ones either way;
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
from collections import Counter
from pathlib import Path

import numpy as np

from colonbench import seeding
from colonbench._version import __version__
from colonbench.completion.method import MIN_POINTS
from colonbench.errors import InputError
from colonbench.heatmaps import voxelize_mesh, voxelize_points, voxelize_polyline
from colonbench.shards.pack import (GRIDS, PACK_FORMAT, PACK_NAME, PACK_VERSION, SLAB, process_pool, dataset_lock,
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
#: The centerlines a context pack can cut along: the true one, or the one ``colonbench map`` finds in the cloud.
LINES = ("truth", "map")
#: A map window whose true stretch differs from its own arc length by more than this share of it is skipped.
MAX_STRETCH = 0.5


def segment_windows(length: float, rng: np.random.Generator, lengths=LENGTH_MM) -> list[tuple[float, float]]:
    """Consecutive arc-length windows ``(lo, hi)`` over ``[0, length]`` mm, from a random offset, drawn lengths."""
    out, lo = [], float(rng.uniform(0.0, lengths[0]))
    while True:
        hi = lo + float(rng.uniform(*lengths))
        if hi > length:
            return out
        out.append((lo, hi))
        lo = hi


def context_sample(pts: np.ndarray, slab: Slab, colon: dict, observed: np.ndarray, window: tuple[float, float],
                   context: tuple[float, float], grid_options: dict) -> tuple[dict, float] | None:
    """The occupancy grids of one segment in context, and its true coverage; None with fewer points than the
    method estimates (:data:`colonbench.completion.method.MIN_POINTS`).

    Parameters
    ----------
    pts : (n, 3) float
        The segment's points and its context's, mm (noise included).
    slab : colonbench.slab.Slab
        The stretch of the centerline the segment is cut along (the true one, or the map's), with the segment's
        window on it.
    colon : dict
        :meth:`colonbench.shards.colonshard.ColonShard.colon`.
    observed : (f,) bool
        Observed faces of the reconstruction.
    window : (float, float)
        The segment on the true centerline, arc lengths in mm: its true coverage.
    context : (float, float)
        The segment and its context on the true centerline, mm: the true surface and centerline the target
        heatmap is made of.
    grid_options : dict
        ``size``, ``margin``, ``min_extent_mm``.

    Returns
    -------
    grids : dict
        ``s0``, ``s1``, ``c``, ``slab``: (S, S, S) bool.
    coverage : float
        Observed share of the true surface in ``window`` (by area).
    """
    from colonbench.meshes import triangle_areas

    (lo, hi), (a, b) = window, context
    cl = colon["centerline"]
    on = (cl.arclength >= a) & (cl.arclength <= b)
    if len(pts) < MIN_POINTS or on.sum() < 2:
        return None
    grid = context_grid(pts, slab, **grid_options)
    fs = colon["face_arclength"]
    faces = colon["faces"][(fs >= a) & (fs <= b)]
    mine = (fs >= lo) & (fs <= hi)
    area = triangle_areas(colon["vertices"], colon["faces"][mine])
    coverage = float(area[observed[mine]].sum() / area.sum()) if area.sum() > 0 else float("nan")
    used, local = np.unique(faces, return_inverse=True)
    grids = {"s0": voxelize_points(grid, pts)[0],
             "s1": voxelize_mesh(grid, colon["vertices"][used], local.reshape(faces.shape))[0],
             "c": voxelize_polyline(grid, cl.points[on])[0], SLAB: slab_occupancy(grid, slab)}
    if not all(g.any() for g in grids.values()):
        return None
    return grids, coverage


def _true_line_samples(pts: np.ndarray, colon: dict, rng: np.random.Generator):
    """Windows cut along the true centerline: ``(points, slab, window, context)`` per segment."""
    cl = colon["centerline"]
    point_s = cl.closest(pts)[1]
    for lo, hi in segment_windows(float(cl.arclength[-1]), rng):
        margin = float(rng.uniform(*CONTEXT_MM))
        a, b = lo - margin, hi + margin
        on = (cl.arclength >= a) & (cl.arclength <= b)
        if on.sum() < 2:
            continue
        yield pts[(point_s >= a) & (point_s <= b)], Slab(cl.points[on], cl.arclength[on], lo, hi), (lo, hi), (a, b)


def _map_line_samples(pts: np.ndarray, colon: dict, positions, rng: np.random.Generator, skipped: Counter):
    """Windows cut along the centerline ``colonbench map`` finds in the noisy cloud, as the map cuts them.

    Each window's truth is the stretch of the true centerline between the true points nearest to its ends
    (the whole-colon benchmark's rule, :func:`colonbench.benchmark.colon_metrics.segment_truth`). A window
    whose true stretch differs from its own length by more than :data:`MAX_STRETCH` of it (the map's line
    jumped between limbs, or ran back on itself) is skipped and counted in ``skipped``.
    """
    from colonbench.errors import ColonbenchError
    from colonbench.mapping.colonmap import join_pieces, map_centerline
    from colonbench.slab import point_at, stretch

    try:
        joined = join_pieces(map_centerline(pts, positions)[0])
    except ColonbenchError:
        skipped["no centerline"] += 1
        return
    cl = colon["centerline"]
    point_s, point_piece = joined.assign(pts)
    for k, (start, stop) in enumerate(joined.spans):
        line, arc = joined.lines[k], joined.arcs[k]
        for lo, hi in segment_windows(stop - start, rng):
            lo, hi = start + lo, start + hi
            margin = float(rng.uniform(*CONTEXT_MM))
            ends = [point_at(line, arc, x) for x in (lo, hi, max(lo - margin, start), min(hi + margin, stop))]
            t = cl.closest(np.array(ends))[1]
            window, context = tuple(sorted(t[:2])), tuple(sorted(t[2:]))
            if abs((window[1] - window[0]) - (hi - lo)) > MAX_STRETCH * (hi - lo):
                skipped["stretch"] += 1
                continue
            sel = (point_piece == k) & (point_s >= lo - margin) & (point_s <= hi + margin)
            yield pts[sel], stretch(line, arc, lo, hi, margin), window, context


def _pack_colon_shard(job) -> tuple[dict, list, Counter]:
    """Packed context samples of one whole-colon shard: rows (grid -> (k, S^3 / 8) uint8), coverages, and the
    count of map windows skipped (by reason)."""
    from colonbench.shards.colonshard import ColonShard

    path, seed, grid_options, line = job
    shard = ColonShard(path)
    colon = shard.colon()
    rows = {g: [] for g in CONTEXT_GRIDS}
    coverages, skipped = [], Counter()
    for i in range(len(shard)):
        smp = shard.sample(i)
        for p in range(PASSES):
            rng = seeding.rng(seed, "context", shard.name, i, p)
            sigma = float(rng.choice(list(NOISE_MM), p=np.array(list(NOISE_MM.values())) / sum(NOISE_MM.values())))
            pts = smp["points"] + (rng.normal(0.0, sigma, smp["points"].shape) if sigma > 0 else 0.0)
            cut = _true_line_samples(pts, colon, rng) if line == "truth" else \
                _map_line_samples(pts, colon, smp.get("positions"), rng, skipped)
            for seg_pts, slab, window, context in cut:
                made = context_sample(seg_pts, slab, colon, smp["observed_faces"], window, context, grid_options)
                if made is None:
                    continue
                for g in CONTEXT_GRIDS:
                    rows[g].append(np.packbits(made[0][g].ravel()))
                coverages.append(made[1])
    size = grid_options["size"]
    return ({g: np.stack(r) if r else np.zeros((0, size ** 3 // 8), np.uint8) for g, r in rows.items()},
            coverages, skipped)


def write_context_pack(data_dir, out_dir, splits=("train", "validation"), workers: int = 1,
                       progress: bool = True, line: str = "truth") -> dict:
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
    line : {"truth", "map"}
        The centerline the reconstructions are cut along: the true one, or the one ``colonbench map`` finds
        in each noisy cloud (with the sample's camera positions), so that training sees the slabs and grids
        inference sees; the target heatmap is made of the true surface and centerline either way.

    Returns
    -------
    dict
        The contents of ``pack.json``.
    """
    from colonbench.shards.dataset import dataset_manifest
    from colonbench.shards.manifest import task

    if line not in LINES:
        raise InputError(f"--context-line {line!r}: one of {', '.join(LINES)}")
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
                        "noise_mm": {str(k): v for k, v in NOISE_MM.items()}, "passes": PASSES,
                        "line": line},
            "splits": {}}
    out.mkdir(parents=True, exist_ok=True)
    seed = int(manifest["seed"])
    for split in splits:
        files = sorted(str(data_dir / name) for name in lock["shards"] if name.startswith(f"{split}/"))
        if not files:
            raise InputError(f"{data_dir}: split {split} has no shards")
        with process_pool(workers) as pool:
            made = list(pool.map(_pack_colon_shard, [(f, seed, grid_options, line) for f in files]))
        n = sum(len(rows["s0"]) for rows, _, _ in made)
        if n == 0:
            raise InputError(f"{data_dir}: split {split} gave no segment with {MIN_POINTS} points or more")
        info["splits"][split] = write_split(out, split, grid_options["size"], n, CONTEXT_GRIDS,
                                            (rows for rows, _, _ in made), progress)
        if line == "map":
            info["splits"][split]["skipped"] = dict(sum((counts for _, _, counts in made), Counter()))
        if split == "train":
            info["train_coverage_mean"] = float(np.nanmean(np.concatenate([c for _, c, _ in made])))
    tmp = out / (PACK_NAME + ".tmp")
    tmp.write_text(json.dumps(info, indent=1) + "\n")
    tmp.replace(out / PACK_NAME)
    return info
