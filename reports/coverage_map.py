"""The coverage map as a coloured mesh and a picture: segments red (coverage 50 % or less) to green, holes blue.

The picture is rendered headless with pyrender (EGL: ``PYOPENGL_PLATFORM=egl``,
set here when unset) from the two sides of the colon's broadest plane, beside a
colour bar (matplotlib).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

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


#: Segment coverage errors beyond this are drawn in the end colours of the error scale, points.
ERROR_SPAN = 10.0


def _error_rgb(error_points) -> np.ndarray:
    from matplotlib import colormaps

    t = np.clip(0.5 + np.atleast_1d(np.asarray(error_points, float)) / (2 * ERROR_SPAN), 0.0, 1.0)
    return (np.asarray(colormaps["RdBu_r"](t))[:, :3] * 255).round().astype(np.uint8)


def map_truth_error(example, path, red_at: float = 0.5, size: int = 480) -> Path:
    """A whole-colon benchmark figure: per track, the map, the truth and the error side by side.

    Parameters
    ----------
    example : path
        An ``examples/*.pkl`` of a whole-colon run (:mod:`colonbench.benchmark.colon_evaluate`).
    path : path
        The PNG to write.

    The map is every segment's completed mesh coloured by its estimated coverage
    (holes blue; for a method without a completed mesh, the true surface's
    stretch of each segment coloured by its estimate); the truth is the true
    surface, each map segment's stretch coloured by its true coverage and
    unobserved faces blue; the error colours the same stretches by estimated -
    true coverage (blue under, red over, grey without an estimate). All three
    are seen from the same camera.
    """
    import pickle
    from types import SimpleNamespace

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import trimesh
    from matplotlib.colors import LinearSegmentedColormap, Normalize

    with open(example, "rb") as fh:
        ex = pickle.load(fh)
    keys = [k for k in ex["maps"] if k.startswith("completion|")] or list(ex["maps"])[:1]
    fs = ex["face_arclength"]
    opaque = np.full((len(fs), 1), 255, np.uint8)

    def surface(values, rgb, holes: bool = False):
        """The true surface, each map segment's stretch coloured by ``rgb(value)`` (grey where NaN)."""
        colour = np.tile(np.array(NONE_RGB, np.uint8), (len(fs), 1))
        for k, (lo, hi) in enumerate(zip(m["true_start_mm"], m["true_end_mm"])):
            if np.isfinite(values[k]):
                colour[(fs >= lo) & (fs < hi)] = rgb(values[k])[0]
        if holes:
            colour[~ex["observed"]] = HOLE_RGB
        mesh = trimesh.Trimesh(ex["vertices"], ex["faces"], process=False)
        mesh.visual.face_colors = np.concatenate([colour, opaque], axis=1)
        return mesh

    truth_frame = trimesh.Trimesh(ex["vertices"], ex["faces"], process=False)
    fig, axs = plt.subplots(len(keys), 3, figsize=(14, 4.8 * len(keys)), constrained_layout=True, squeeze=False)
    for row, key in zip(axs, keys):
        m = ex["maps"][key]
        est = np.array([np.nan if r["coverage"] is None else r["coverage"] for r in m["segments"]], float)
        truth = np.asarray(m["truth"], float)
        segs = [SimpleNamespace(index=r["index"], coverage=r["coverage"], mesh=mesh)
                for r, mesh in zip(m["segments"], m["meshes"])]
        cov_rgb = lambda c: coverage_rgb(c, red_at)  # noqa: E731
        if any(s.mesh for s in segs):
            estimated = ("map: completed segments by estimated coverage, holes blue", map_mesh(segs, red_at))
        else:
            estimated = ("map: each stretch by its estimated coverage", surface(est, cov_rgb))
        panels = [estimated, ("truth: true coverage, unobserved faces blue", surface(truth, cov_rgb, holes=True)),
                  ("error: estimated - true", surface(100 * (est - truth), _error_rgb))]
        for ax, (title, mesh), bg in zip(row, panels, ((1.0,) * 3, (1.0,) * 3, (0.45,) * 3)):
            ax.imshow(render_views(mesh, size, like=truth_frame, sides=(1.0,), background=bg)[0])
            ax.set_title(f"{key.replace('|', ', ')}\n{title}", fontsize=9)
            ax.set_axis_off()
    cov = LinearSegmentedColormap.from_list("coverage", coverage_rgb(np.linspace(red_at, 1, 64), red_at) / 255.0)
    fig.colorbar(plt.cm.ScalarMappable(norm=Normalize(red_at * 100, 100), cmap=cov), ax=axs[:, :2], shrink=0.6,
                 label="coverage, % (blue: holes / unobserved)")
    errmap = LinearSegmentedColormap.from_list("error", _error_rgb(np.linspace(-ERROR_SPAN, ERROR_SPAN, 64)) / 255.0)
    fig.colorbar(plt.cm.ScalarMappable(norm=Normalize(-ERROR_SPAN, ERROR_SPAN), cmap=errmap), ax=axs[:, 2],
                 shrink=0.6, label="coverage error, points")
    path = Path(path)
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path
