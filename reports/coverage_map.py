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


def render_views(mesh, size: int = 640) -> list[np.ndarray]:
    """Two (size, size, 3) uint8 renderings of ``mesh`` from either side of its broadest plane."""
    from colonbench.offscreen import pyrender as _load

    pyrender = _load()
    centre = mesh.vertices.mean(axis=0)
    rel = mesh.vertices - centre
    _, _, axes = np.linalg.svd(rel[:: max(1, len(rel) // 20000)], full_matrices=False)
    up, view = axes[1], axes[2]  # the second spread is up; look along the least spread
    extent = np.ptp(rel @ axes[:2].T, axis=0).max()
    yfov = np.deg2rad(40.0)
    distance = 0.6 * extent / np.tan(yfov / 2) + np.ptp(rel @ view)
    scene = pyrender.Scene(ambient_light=np.full(3, 1.0), bg_color=[1.0, 1.0, 1.0, 1.0])
    scene.add(pyrender.Mesh.from_trimesh(mesh, smooth=False))
    renderer = pyrender.OffscreenRenderer(size, size)
    images = []
    try:
        for sign in (1.0, -1.0):
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
