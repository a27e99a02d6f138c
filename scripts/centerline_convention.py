"""How far a dataset's true centerline lies from the lumen's centre, and which of the two the network follows.

    python scripts/centerline_convention.py data/train-wide --split validation
    python scripts/centerline_convention.py --manifest data_manifests/wide.yaml --colon 220 [--plain]

Segments (first form): for every noiseless sample of the split, the lumen's
centre is found on the true segment mesh the way the real colons' importer
re-centres their lines (``colonbench.datagen.lumen``): the mesh is cut square
to the true centerline every 2 mm, each section's core (the part at least 0.8
of its deepest point away from the wall) gives a centroid, and the centroids
are median-filtered and smoothed along the line. Printed: the median distance
from the true line to that centre, and the completion method's centerline
precision / recall at 2 mm against each of the two.

Whole colon (second form): a procedural colon of the manifest's generator is
drawn, its lumen voxelised and its axis re-centred by
``colonbench.datagen.lumen_midline.recentre``, as an imported colon's midline is;
``--plain`` draws the colon of the same id without ellipticity and flattening
(its other draws then differ too: another shape of the same generator). Printed:
the distances from the generator's axis to the re-centred line. Prints figures
only (docs/benchmark.md, Suites).
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time

import numpy as np
from scipy.spatial import cKDTree

#: Distance between the sections, mm (4 points of a 0.5 mm centerline).
SECTION_EVERY = 4
#: Pixel of a section's raster, mm.
PIXEL_MM = 0.5
#: Farthest a section's outline may lie from the line, mm.
MAX_RADIUS_MM = 60.0


def section_centre(mesh, point: np.ndarray, tangent: np.ndarray) -> np.ndarray | None:
    """Centroid of the core of the mesh's section through ``point`` square to ``tangent``, mm; None if open.

    Parameters
    ----------
    mesh : trimesh.Trimesh
        Lumen surface, mm.
    point, tangent : (3,) float
        A point of the centerline and its unit tangent.
    """
    from matplotlib.path import Path as Outline

    from colonbench.datagen.lumen_midline import outline_core_centre

    sec = mesh.section(plane_origin=point, plane_normal=tangent)
    if sec is None:
        return None
    u = np.cross(tangent, np.eye(3)[int(np.argmin(np.abs(tangent)))])
    u /= np.linalg.norm(u)
    v = np.cross(tangent, u)
    outline = None
    for entity in sec.entities:
        xy = (sec.vertices[entity.points] - point) @ np.stack([u, v], axis=1)
        if len(xy) >= 8 and np.min((xy ** 2).sum(axis=1)) < MAX_RADIUS_MM ** 2 \
                and Outline(xy).contains_point((0.0, 0.0)):
            outline = xy  # the closed outline around the line's point
    if outline is None:
        return None
    centre = outline_core_centre(outline, PIXEL_MM)
    return point + centre[0] * u + centre[1] * v


def lumen_line(vertices: np.ndarray, faces: np.ndarray, centerline: np.ndarray) -> np.ndarray:
    """(m, 3) the lumen-centred line of a segment, mm, 0.5 mm apart (see the module's description)."""
    import trimesh

    from colonbench.polyline import resample
    from colonbench.datagen.lumen_midline import smooth_along

    mesh = trimesh.Trimesh(vertices, faces, process=False)
    cl = np.asarray(centerline, float)
    k = SECTION_EVERY
    centres = []
    for i in range(k, len(cl) - k, k):
        t = cl[min(i + 2, len(cl) - 1)] - cl[i - 2]
        c = section_centre(mesh, cl[i], t / np.linalg.norm(t))
        centres.append(cl[i] if c is None else c)
    if len(centres) < 3:
        return cl
    step = SECTION_EVERY * 0.5  # mm between sections of a 0.5 mm centerline
    return resample(smooth_along(np.array(centres), step, 5 * step, 1.5 * step), 0.5)


def _pr(estimate: np.ndarray, truth: np.ndarray, th: float = 2.0) -> tuple[float, float]:
    return (float(np.mean(cKDTree(truth).query(estimate)[0] < th)),
            float(np.mean(cKDTree(estimate).query(truth)[0] < th)))


def segments(args) -> None:
    import torch

    from colonbench.benchmark.evaluate import select
    from colonbench.completion.method import CompletionMethod
    from colonbench.shards.reader import Shard

    torch.set_num_threads(args.threads)
    method = CompletionMethod(model=args.model)
    _, picks = select(args.data, args.split, args.limit)
    rows = []
    t0 = time.perf_counter()
    for shard_name, idx in picks:
        with Shard(f"{args.data}/{shard_name}") as sh:
            for i in idx:
                geo = sh.geometry(i)
                axis = geo["centerline"]
                centre = lumen_line(geo["vertices"], geo["faces"], axis)
                est = method.estimate(geo["partial_points"]).centerline
                inner = axis[2 * SECTION_EVERY: len(axis) - 2 * SECTION_EVERY]  # where sections were cut
                if len(est) == 0 or len(inner) == 0:
                    continue
                rows.append((float(np.median(cKDTree(centre).query(inner)[0])), *_pr(est, inner), *_pr(est, centre)))
    r = np.array(rows)
    print(f"{args.data} {args.split}: {len(r)} samples ({time.perf_counter() - t0:.0f} s)")
    print(f"  true line to the lumen's centre: median over samples of the median distance {np.median(r[:, 0]):.2f} mm")
    print(f"  completion centerline P / R @2 mm against the true line     {r[:, 1].mean():.2f} / {r[:, 2].mean():.2f}")
    print(f"  completion centerline P / R @2 mm against the lumen's centre {r[:, 3].mean():.2f} / {r[:, 4].mean():.2f}")


def whole_colon(args) -> None:
    import trimesh

    from colonbench.datagen.colon import generate_colon
    from colonbench.datagen.generate import GeneratorConfig
    from colonbench.datagen.lumen import extract_lumen
    from colonbench.datagen.lumen_midline import recentre
    from colonbench.shards.manifest import load

    manifest = load(args.manifest)
    config = GeneratorConfig.from_dict(manifest["config"]).colon
    if args.plain:
        config = dataclasses.replace(config, ellipticity=(0.0, 0.0), flattening=(0.0, 0.0))
    t0 = time.perf_counter()
    colon = generate_colon(config, seed=manifest["seed"], colon_id=args.colon)
    axis = colon.centerline.points
    mesh = colon.mesh if isinstance(colon.mesh, trimesh.Trimesh) else trimesh.Trimesh(*colon.mesh)
    _, cavity, origin, voxel, _ = extract_lumen(mesh, axis, 1.0)
    line, _, _ = recentre(cavity, origin, voxel, axis)
    d = cKDTree(line.points).query(axis)[0]
    print(f"colon {args.colon} of {args.manifest}{' without ellipticity and flattening' if args.plain else ''} "
          f"(ellipticity {colon.info.get('ellipticity', 0.0):.2f}, flattening {colon.info.get('flattening', 0.0):.2f}, "
          f"{colon.centerline.length:.0f} mm, {time.perf_counter() - t0:.0f} s): axis to the re-centred line "
          f"median {np.median(d):.2f} mm, 90th percentile {np.percentile(d, 90):.2f} mm, "
          f"{100 * np.mean(d < 2):.0f} % within 2 mm")


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("data", nargs="?", help="a dataset folder (segments)")
    ap.add_argument("--split", default="validation")
    ap.add_argument("--limit", type=int, help="samples, spread evenly over the split (default all)")
    ap.add_argument("--model", help="model file or shipped name (default: the shipped one)")
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--manifest", help="whole colon: the manifest whose generator draws it")
    ap.add_argument("--colon", type=int, default=0, help="whole colon: its colon id")
    ap.add_argument("--plain", action="store_true", help="whole colon: without ellipticity and flattening")
    args = ap.parse_args(argv)
    if (args.data is None) == (args.manifest is None):
        sys.exit("give a dataset folder (segments) or --manifest (a whole colon), not both")
    segments(args) if args.data else whole_colon(args)


if __name__ == "__main__":
    main()
