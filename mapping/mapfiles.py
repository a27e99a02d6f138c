"""The map's files: segments.json / .csv, centerline.npy, summary.json, and the segments coloured by coverage as a mesh
(map.ply / .glb) and a headless picture (map.png)."""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np

from colonbench.mapping.segments import round_or_none, whole_coverage


#: Coverage at or below this is red, 1 green (the paper's supplementary map).
RED_AT = 0.5


def write_map(result: dict, out, method_name: str, model: str | None, threshold: float = RED_AT,
              figure: bool = True, version: str = "") -> tuple[list[Path], dict]:
    """Write ``segments.json``/``.csv``, ``centerline.npy``, ``summary.json``, ``map.ply``/``.glb``, ``map.png``.

    ``version``: the method's version (a model's with its steps and its intervals' calibration id), recorded beside
    ``method`` and ``model``.

    Returns
    -------
    written : list of Path
    summary : dict
        What ``summary.json`` holds.
    """
    import pandas as pd

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    rows = [s.row() for s in result["segments"]]
    written = []
    doc = {"segments": rows, "method": method_name, "model": model, "version": version}
    (out / "segments.json").write_text(json.dumps(doc, indent=1) + "\n")
    flat = []
    for r in rows:
        f = {k: v for k, v in r.items() if k not in ("plane_start", "plane_end", "coverage_interval", "review")}
        low, high = r["coverage_interval"] or (None, None)
        f.update(coverage_low=low, coverage_high=high, review="; ".join(r["review"]))
        for name in ("plane_start", "plane_end"):
            for part in ("point", "normal"):
                for axis, v in zip("xyz", r[name][part]):
                    f[f"{name}_{part}_{axis}"] = v
        flat.append(f)
    pd.DataFrame(flat).to_csv(out / "segments.csv", index=False)
    np.save(out / "centerline.npy", np.asarray(result["centerline"], np.float64))
    written += [out / "segments.json", out / "segments.csv", out / "centerline.npy"]
    segs = result["segments"]
    seconds = {k: round(v, 3) for k, v in result["seconds"].items()}
    if any(s.mesh for s in segs):
        from colonbench.mapping.mapfiles import map_mesh, render_map

        mesh = map_mesh(segs, red_at=threshold)
        mesh.export(out / "map.ply")
        mesh.export(out / "map.glb")
        written += [out / "map.ply", out / "map.glb"]
        if figure:
            t = time.perf_counter()
            written.append(render_map(mesh, out / "map.png", red_at=threshold))
            seconds["figure"] = round(time.perf_counter() - t, 3)
    mapped = sum(s.end_mm - s.start_mm for s in segs)
    estimated_mm = sum(s.end_mm - s.start_mm for s in segs if s.coverage is not None)
    summary = {
        "coverage": round_or_none(whole_coverage(segs), 4),
        "segments": len(segs),
        "estimated": sum(s.coverage is not None for s in segs),
        "estimated_mm": round(estimated_mm, 1),
        "estimated_share": round(estimated_mm / mapped, 4) if mapped > 0 else 0.0,
        "reached": round(result.get("reached", 1.0), 4),
        "below_threshold": {"threshold": threshold,
                            "segments": [s.index for s in segs if s.coverage is not None and s.coverage < threshold]},
        "centerline_mm": round(float(result["arclength"][-1]), 1),
        "interruptions": result["interruptions"],
        "unreconstructed": result.get("unreconstructed", []),
        "orientation": result["orientation"],
        "context_mm": result.get("context_mm", 0.0),
        "method": method_name, "model": model, "version": version,
        "seconds": seconds,
    }
    (out / "summary.json").write_text(json.dumps(summary, indent=1) + "\n")
    written.append(out / "summary.json")
    return written, summary


#: Colour of estimated hole vertices (RGB, 0-255): blue, apart from the red-to-green scale.
HOLE_RGB = (40, 90, 235)


#: Colour of segments without an estimate.
NONE_RGB = (150, 150, 150)


def coverage_rgb(coverage, red_at: float = 0.5) -> np.ndarray:
    """(n, 3) uint8 colours of coverages: red at ``red_at`` or less, through yellow, to green at 1."""
    from matplotlib import colormaps

    c = np.atleast_1d(np.asarray(coverage, float))
    t = np.clip((c - red_at) / max(1.0 - red_at, 1e-9), 0.0, 1.0)
    return (np.asarray(colormaps["RdYlGn"](t))[:, :3] * 255).round().astype(np.uint8)


def map_mesh(segments, red_at: float = 0.5):
    """One trimesh of every segment's completed mesh, vertex-coloured by its coverage, holes in blue.

    Parameters
    ----------
    segments : list of colonbench.mapping.colonmap.Segment
        Those with a completed mesh (``segment.mesh``) are drawn.

    Returns
    -------
    trimesh.Trimesh
        With ``metadata["segment"]``: (f,) int, the segment index of each face.
    """
    import trimesh

    verts, faces, colours, owner = [], [], [], []
    offset = 0
    for seg in segments:
        if not seg.mesh:
            continue
        v, f, hole = seg.mesh
        rgb = coverage_rgb(seg.coverage, red_at)[0] if seg.coverage is not None else np.array(NONE_RGB)
        col = np.where(np.asarray(hole, bool)[:, None], np.array(HOLE_RGB), rgb).astype(np.uint8)
        verts.append(v)
        faces.append(f + offset)
        colours.append(col)
        owner.append(np.full(len(f), seg.index))
        offset += len(v)
    mesh = trimesh.Trimesh(np.concatenate(verts), np.concatenate(faces), process=False)
    mesh.visual.vertex_colors = np.concatenate([np.concatenate(colours),
                                                np.full((offset, 1), 255, np.uint8)], axis=1)
    mesh.metadata["segment"] = np.concatenate(owner)
    return mesh


def render_views(mesh, size: int = 640, like=None, sides=(1.0, -1.0), background=(1.0, 1.0, 1.0)) -> list[np.ndarray]:
    """(size, size, 3) uint8 renderings of ``mesh`` from either side of its broadest plane.

    Parameters
    ----------
    mesh : trimesh.Trimesh
        Vertex- or face-coloured.
    size : int
        Image side, px.
    like : trimesh.Trimesh, optional
        Take the plane and the distance from this mesh instead (the same view of several meshes).
    sides : tuple of float
        ``1.0`` (front) and / or ``-1.0`` (back).
    background : (3,) float
        RGB in [0, 1].
    """
    from colonbench.offscreen import pyrender as _load

    pyrender = _load()
    frame = mesh if like is None else like
    centre = frame.vertices.mean(axis=0)
    rel = frame.vertices - centre
    _, _, axes = np.linalg.svd(rel[:: max(1, len(rel) // 20000)], full_matrices=False)
    up, view = axes[1], axes[2]  # the second spread is up; look along the least spread
    extent = np.ptp(rel @ axes[:2].T, axis=0).max()
    yfov = np.deg2rad(40.0)
    distance = 0.6 * extent / np.tan(yfov / 2) + np.ptp(rel @ view)
    scene = pyrender.Scene(ambient_light=np.full(3, 1.0), bg_color=[*background, 1.0])
    scene.add(pyrender.Mesh.from_trimesh(mesh, smooth=False))
    renderer = pyrender.OffscreenRenderer(size, size)
    images = []
    try:
        for sign in sides:
            z = sign * view
            x = np.cross(up, z)
            x /= np.linalg.norm(x)
            pose = np.eye(4)
            pose[:3, :3] = np.stack([x, np.cross(z, x), z], axis=1)
            pose[:3, 3] = centre + distance * z
            cam = scene.add(pyrender.PerspectiveCamera(yfov=yfov, znear=1.0, zfar=4 * distance), pose=pose)
            light = scene.add(pyrender.DirectionalLight(intensity=2.0), pose=pose)
            colour, _ = renderer.render(scene, flags=pyrender.RenderFlags.SKIP_CULL_FACES)
            images.append(np.asarray(colour)[..., :3].copy())
            scene.remove_node(cam)
            scene.remove_node(light)
    finally:
        renderer.delete()
    return images


def render_map(mesh, path, red_at: float = 0.5, size: int = 640) -> Path:
    """``map.png``: the coloured map from two sides, with the colour bar and the hole colour."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.colors import LinearSegmentedColormap, Normalize
    from matplotlib.patches import Patch

    views = render_views(mesh, size)
    fig, axs = plt.subplots(1, 2, figsize=(11, 5.4), constrained_layout=True)
    for ax, img, title in zip(axs, views, ("front", "back")):
        ax.imshow(img)
        ax.set_title(title)
        ax.set_axis_off()
    grid = np.linspace(red_at, 1.0, 64)
    cmap = LinearSegmentedColormap.from_list("coverage", coverage_rgb(grid, red_at) / 255.0)
    bar = fig.colorbar(plt.cm.ScalarMappable(norm=Normalize(red_at * 100, 100), cmap=cmap), ax=axs,
                       shrink=0.8, label="segment coverage, % (red: 50 % or less)")
    bar.ax.tick_params(labelsize=8)
    fig.legend(handles=[Patch(color=np.array(HOLE_RGB) / 255, label="estimated holes")], loc="lower left")
    path = Path(path)
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path
