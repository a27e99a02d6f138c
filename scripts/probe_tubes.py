"""Coverage error on tubes from a generator that shares no code with colonbench.datagen: a generalization probe.

    python scripts/probe_tubes.py --segments 150 --models small,old-model.safetensors --folds deep --seed 1
    python scripts/probe_tubes.py --methods completion,unwrap --models small

The held-out data issue 11 is scored on comes from other generators. This script is one we did not
train on, built another way, so that the error on it says something about those: a tube swept along a
random cubic spline (7 knots, turns of 5-35 degrees between them) with a rotation-minimising frame, its
radius 12-32 mm, an elliptic section (axis ratio 0.75-1), three lobes (taeniae, 0-12 % of the radius)
and, per ``--folds``, either gentle rings (``smooth``: a sine of 0-18 % with a 18-35 mm period, or none)
or narrow folds between wide pockets (``deep``: the radius dips by 15-40 % over about a tenth of each
18-35 mm haustrum). Each segment of 50, 60 or 70 mm is cut from the middle of an 80-100 mm tube, so
that its neighbours occlude and are seen as in a colon. Holes, in turn:

- ``spheres``: 2-8 balls of radius 4-16 mm centred on the wall remove the faces inside them;
- ``camera``: 9 cameras along the whole tube's axis (up to 0.35 of the radius off it), each looking
  back along it within 20 degrees, with a 140-degree field of view and a 90 mm reach, see what
  their rays reach first (open3d ray casting);
- ``band``: the faces whose normal is within 45-72 degrees of a random direction are unseen (a
  camera that never looked one way), plus 0-3 balls.

The partial cloud is sampled on the seen faces at 2 points/mm^2 (the held-out data's density;
``--density`` picks another, with the same tubes, holes and noise draws), and
the truth is the seen share of the segment's area. Every draw comes from ``--seed``. Prints the
coverage MAE and bias (points) per method, hole kind and noise level, and each method's paired
difference against the first; ``--csv`` keeps the rows.
"""

from __future__ import annotations

import argparse
import sys

import numpy as np
import pandas as pd
import trimesh
from scipy.interpolate import CubicSpline

from colonbench import seeding

HOLES = ("spheres", "camera", "band")
STEP_MM = 0.6


def spline_axis(rng, length_mm: float) -> tuple[np.ndarray, np.ndarray]:
    """A random smooth axis: (m,) arc lengths and (m, 3) points, mm."""
    knots, direction, turn = [np.zeros(3)], np.array([0.0, 0.0, 1.0]), rng.uniform(5.0, 35.0)
    for _ in range(6):
        axis = rng.normal(size=3)
        axis -= axis.dot(direction) * direction
        axis /= np.linalg.norm(axis)
        angle = np.radians(rng.uniform(-turn, turn))
        direction = direction * np.cos(angle) + np.cross(axis, direction) * np.sin(angle)
        knots.append(knots[-1] + direction * length_mm / 6)
    knots = np.array(knots)
    t = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(knots, axis=0), axis=1))]
    points = CubicSpline(t, knots)(np.linspace(0.0, t[-1], 4000))
    return np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(points, axis=0), axis=1))], points


def tube(rng, segment_mm: float, folds: str) -> tuple[trimesh.Trimesh, np.ndarray, np.ndarray, dict]:
    """A closed-around, open-ended tube 30 mm longer than the segment.

    Returns
    -------
    mesh : trimesh.Trimesh
        The whole tube, mm.
    axis : (m, 3) float
        Its axis, 0.6 mm apart.
    in_segment : (f,) bool
        Faces of the segment (15 mm from the tube's start on).
    info : dict
        The drawn shape parameters.
    """
    radius = rng.uniform(12.0, 32.0)
    total = segment_mm + 30.0
    s, pts = spline_axis(rng, total)
    ss = np.arange(0.0, total + 1e-9, STEP_MM)
    axis = np.stack([np.interp(ss, s, pts[:, k]) for k in range(3)], axis=1)
    tangent = np.gradient(axis, axis=0)
    tangent /= np.linalg.norm(tangent, axis=1, keepdims=True)
    u = np.zeros_like(tangent)
    seed_dir = np.array([1.0, 0, 0]) if abs(tangent[0, 0]) < 0.9 else np.array([0, 1.0, 0])
    u[0] = np.cross(tangent[0], seed_dir) / np.linalg.norm(np.cross(tangent[0], seed_dir))
    for i in range(1, len(tangent)):        # rotation-minimising frame: no twist
        v = u[i - 1] - u[i - 1].dot(tangent[i]) * tangent[i]
        u[i] = v / np.linalg.norm(v)
    w = np.cross(tangent, u)
    n_around = int(2 * np.pi * radius * 1.3 / STEP_MM)
    theta = np.linspace(0.0, 2 * np.pi, n_around, endpoint=False)
    period, lobes, ratio, phase = rng.uniform(18.0, 35.0), rng.uniform(0.0, 0.12), rng.uniform(0.75, 1.0), \
        rng.uniform(0.0, 2 * np.pi)
    S, TH = np.meshgrid(ss, theta, indexing="ij")
    if folds == "deep":
        depth = rng.uniform(0.15, 0.4)
        rings = 1 - depth * np.abs(np.cos(np.pi * S / period + phase)) ** 12
    else:
        depth = float(rng.choice([0.0, rng.uniform(0.03, 0.18)]))
        rings = 1 + depth * np.sin(2 * np.pi * S / period + phase)
    R = radius * rings * (1 + lobes * np.cos(3 * TH))
    xyz = axis[:, None, :] + R[..., None] * (np.cos(TH)[..., None] * u[:, None, :]
                                              + ratio * np.sin(TH)[..., None] * w[:, None, :])
    i, j = np.meshgrid(np.arange(len(ss) - 1), np.arange(n_around), indexing="ij")
    a, b = i * n_around + j, i * n_around + (j + 1) % n_around
    c, d = a + n_around, b + n_around
    faces = np.r_[np.c_[a.ravel(), c.ravel(), b.ravel()], np.c_[b.ravel(), c.ravel(), d.ravel()]]
    mesh = trimesh.Trimesh(xyz.reshape(-1, 3), faces, process=False)
    s_face = np.repeat(ss, n_around)[faces].mean(axis=1)
    info = dict(radius=radius, folds=folds, fold_depth=depth, period=period, lobes=lobes, ratio=ratio)
    return mesh, axis, (s_face >= 15.0) & (s_face <= 15.0 + segment_mm), info


def camera_seen(rng, mesh: trimesh.Trimesh, axis: np.ndarray, radius: float, cameras: int = 9) -> np.ndarray:
    """(f,) bool: faces whose centre some camera's ray reaches first (``radius``: the tube's, mm)."""
    import open3d as o3d

    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.core.Tensor(mesh.vertices.astype(np.float32)),
                        o3d.core.Tensor(mesh.faces.astype(np.uint32)))
    centre = mesh.triangles_center
    tangent = np.gradient(axis, axis=0)
    tangent /= np.linalg.norm(tangent, axis=1, keepdims=True)
    seen = np.zeros(len(centre), bool)
    for k in np.linspace(0, len(axis) - 1, cameras).astype(int):
        off = rng.normal(size=3)
        off -= off.dot(tangent[k]) * tangent[k]
        cam = axis[k] + off / np.linalg.norm(off) * rng.uniform(0.0, 0.35) * radius
        look = -tangent[k] + rng.normal(scale=0.35, size=3)
        look /= np.linalg.norm(look)
        ray = centre - cam
        dist = np.linalg.norm(ray, axis=1)
        ray /= dist[:, None]
        candidates = np.flatnonzero((ray @ look > np.cos(np.radians(70.0))) & (dist < 90.0))
        if len(candidates):
            rays = np.c_[np.repeat(cam[None], len(candidates), 0), ray[candidates]].astype(np.float32)
            first = scene.cast_rays(o3d.core.Tensor(rays))["primitive_ids"].numpy()
            seen[candidates[first == candidates]] = True
    return seen


def balls(rng, mesh: trimesh.Trimesh, count: int, radius_mm: tuple) -> np.ndarray:
    """(f,) bool: faces outside ``count`` balls centred on random face centres."""
    centre = mesh.triangles_center
    keep = np.ones(len(centre), bool)
    for _ in range(count):
        c = centre[rng.integers(len(centre))]
        keep &= np.linalg.norm(centre - c, axis=1) > rng.uniform(*radius_mm)
    return keep


def seen_faces(rng, mesh: trimesh.Trimesh, axis: np.ndarray, radius: float, kind: str) -> np.ndarray:
    """(f,) bool: the faces the partial cloud is sampled on."""
    if kind == "spheres":
        return balls(rng, mesh, int(rng.integers(2, 9)), (4.0, 16.0))
    if kind == "camera":
        return camera_seen(rng, mesh, axis, radius)
    direction = rng.normal(size=3)
    direction /= np.linalg.norm(direction)
    one_side = mesh.face_normals @ direction > rng.uniform(0.3, 0.7)
    return ~one_side & balls(rng, mesh, int(rng.integers(0, 4)), (4.0, 12.0))


def probe(segments: int, seed: int, folds: str, holes, methods: dict, noise=(0.0, 0.5),
          density: float = 2.0) -> pd.DataFrame:
    """One row per segment, noise level and method: truth, estimate, error (points); clouds of ``density``
    points/mm^2."""
    rows = []
    for k in range(segments):
        rng = seeding.rng(seed, "probe-tubes", k)
        length = float(rng.choice([50.0, 60.0, 70.0]))
        mesh, axis, in_segment, info = tube(rng, length, folds)
        kind = holes[k % len(holes)]
        seen = seen_faces(rng, mesh, axis, info["radius"], kind)[in_segment]
        segment = trimesh.Trimesh(mesh.vertices, mesh.faces[in_segment], process=False)
        area = segment.area_faces
        truth = float(area[seen].sum() / area.sum())
        partial = trimesh.Trimesh(segment.vertices, segment.faces[seen], process=False)
        points, _ = trimesh.sample.sample_surface(partial, int(round(density * partial.area)),
                                                  seed=int(rng.integers(2**31)))
        for sigma in noise:
            cloud = points + rng.normal(scale=sigma, size=points.shape) if sigma else points
            for name, method in methods.items():
                try:
                    estimate = float(method.estimate(cloud).coverage)
                except Exception as exc:  # noqa: BLE001 - a failure is a row, as in colonbench evaluate
                    estimate = np.nan
                    print(f"segment {k}, {name}: {exc}", file=sys.stderr)
                rows.append(dict(segment=k, holes=kind, noise_mm=sigma, length_mm=length, truth=truth,
                                 estimate=estimate, method=name, **info))
    table = pd.DataFrame(rows)
    table["error"] = 100.0 * (table.estimate - table.truth)
    return table


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--segments", type=int, default=60)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--folds", choices=["smooth", "deep"], default="smooth")
    ap.add_argument("--holes", default=",".join(HOLES), help=f"hole kinds, in turn ({', '.join(HOLES)})")
    ap.add_argument("--methods", default="completion", help="registered methods or package.module:Class")
    ap.add_argument("--models", default="small", help="models for the methods built on the network")
    ap.add_argument("--density", type=float, default=2.0, help="points/mm^2 of the partial clouds (default 2)")
    ap.add_argument("--noise", default="0,0.5", help="Gaussian noise sigmas, mm (default 0,0.5)")
    ap.add_argument("--csv", help="write the rows here")
    args = ap.parse_args(argv)
    from colonbench.benchmark.registry import load_method

    holes = [h for h in args.holes.split(",") if h]
    if not holes or set(holes) - set(HOLES):
        ap.error(f"--holes: choose from {', '.join(HOLES)}")
    if not (np.isfinite(args.density) and args.density > 0):
        ap.error("--density: a positive number of points/mm^2")
    try:
        noise = [float(x) for x in args.noise.split(",") if x.strip()]
    except ValueError:
        ap.error("--noise: comma-separated sigmas in mm")
    if not noise or not all(np.isfinite(x) and x >= 0 for x in noise):
        ap.error("--noise: comma-separated sigmas in mm, each finite and >= 0")
    # the arguments are checked before the models load (seconds each)
    methods = {f"{m}[{model}]": load_method(m, model=model) for m in args.methods.split(",")
               for model in args.models.split(",")}
    table = probe(args.segments, args.seed, args.folds, holes, methods, noise, args.density)
    if args.csv:
        table.to_csv(args.csv, index=False)
    truth = table.drop_duplicates(["segment", "noise_mm"]).truth
    print(f"{args.segments} segments, folds {args.folds}, seed {args.seed}, {args.density:g} points/mm^2; "
          f"mean coverage {truth.mean():.3f}")
    table["abs"] = table.error.abs()
    summary = table.groupby(["method", "holes", "noise_mm"]).agg(mae=("abs", "mean"), bias=("error", "mean"))
    print(summary.unstack("noise_mm").round(2).to_string())
    print(table.groupby(["method", "noise_mm"])["abs"].mean().unstack().round(2).to_string())
    first = next(iter(methods))
    wide = table.pivot_table(index=["segment", "noise_mm"], columns="method", values="abs")
    for name in list(methods)[1:]:
        diff = wide[name] - wide[first]
        print(f"{name} - {first}: {diff.mean():+.2f} +- {diff.std(ddof=1) / np.sqrt(len(diff)):.2f} points "
              f"per evaluation ({len(diff)})")


if __name__ == "__main__":
    main()
