"""Quick pictures of colons and segments for people (matplotlib, headless).

Large meshes are decimated (open3d quadric decimation) to keep the plot light.
Geometry stays in mm; axes are equal so shapes are not distorted.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np


def _decimate(vertices, faces, max_faces):
    if len(faces) <= max_faces:
        return np.asarray(vertices), np.asarray(faces)
    import open3d as o3d

    m = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(np.asarray(vertices, float)),
                                  o3d.utility.Vector3iVector(np.asarray(faces, np.int32)))
    m = m.simplify_quadric_decimation(int(max_faces))
    return np.asarray(m.vertices), np.asarray(m.triangles)


def _shade(vertices, faces, color, light=(0.4, -0.5, 0.75)):
    tri = vertices[faces]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)
    light = np.asarray(light, float) / np.linalg.norm(light)
    lam = 0.35 + 0.65 * np.abs(n @ light)
    base = np.broadcast_to(np.asarray(color, float)[..., :3], (len(faces), 3))
    return np.concatenate([base * lam[:, None], np.full((len(faces), 1), 1.0)], axis=1)


def axes_3d(fig, pos=111, title=None):
    """A 3D axes of ``fig`` at subplot ``pos`` (an int such as 111 or a (rows, columns, index) tuple), in mm."""
    ax = fig.add_subplot(*pos, projection="3d") if isinstance(pos, tuple) else fig.add_subplot(pos, projection="3d")
    ax.set_xlabel("x (mm)")
    ax.set_ylabel("y (mm)")
    ax.set_zlabel("z (mm)")
    if title:
        ax.set_title(title, fontsize=9)
    return ax


def set_equal(ax, points):
    """Equal scales on the three axes of ``ax``, a cube around ``points`` ((n, 3) mm), so shapes keep their form."""
    lo, hi = points.min(axis=0), points.max(axis=0)
    c, r = (lo + hi) / 2, (hi - lo).max() / 2
    ax.set_xlim(c[0] - r, c[0] + r)
    ax.set_ylim(c[1] - r, c[1] + r)
    ax.set_zlim(c[2] - r, c[2] + r)
    ax.set_box_aspect((1, 1, 1))


def draw_surface(ax, vertices, faces, color, max_faces=30000, alpha=1.0):
    """Add a shaded triangle surface (decimated to ``max_faces``) to a 3D axes."""
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    v, f = _decimate(vertices, faces, max_faces)
    if len(f) == 0:
        return
    colors = _shade(v, f, color)
    colors[:, 3] = alpha
    ax.add_collection3d(Poly3DCollection(v[f], facecolors=colors, edgecolors="none"))


def colon_picture(colon, path, segments=None, title=None, max_faces=40000, dpi=110):
    """Write a picture of a whole colon: its surface (cut open) and its centerline.

    Parameters
    ----------
    colon : Colon
    path : str or Path
        PNG (or any matplotlib format) to write.
    segments : list of (s0, s1), optional
        Arc-length windows to mark on the centerline, mm.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig = plt.figure(figsize=(11, 5.5))
    ax = axes_3d(fig, 121, "surface")
    draw_surface(ax, colon.mesh.vertices, colon.mesh.faces, (0.86, 0.62, 0.55), max_faces)
    set_equal(ax, colon.mesh.vertices)
    ax.view_init(elev=10, azim=-80)
    ax2 = axes_3d(fig, 122, "centerline" + (" and segments" if segments else ""))
    cl = colon.centerline
    ax2.plot(*cl.points.T, color="k", lw=1)
    if segments:
        cmap = plt.get_cmap("tab10")
        for i, (a, b) in enumerate(segments):
            w = cl.window(a, b)
            ax2.plot(*w.T, color=cmap(i % 10), lw=3)
    set_equal(ax2, colon.mesh.vertices)
    ax2.view_init(elev=10, azim=-80)
    if title:
        fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=dpi)
    plt.close(fig)
    return Path(path)


def segment_picture(segment, path, title=None, max_faces=25000, dpi=110):
    """Write a picture of a segment: observed surface grey, holes red, GT centerline black.

    Parameters
    ----------
    segment : Segment
        As made by :func:`colonbench.datagen.segments.make_sample`.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig = plt.figure(figsize=(11, 5.5))
    views = [(20, -60), (20, 120)]
    for i, (elev, azim) in enumerate(views):
        ax = axes_3d(fig, 121 + i)
        m = segment.complete
        obs = segment.observed_faces
        draw_surface(ax, m.vertices, m.faces[obs], (0.75, 0.75, 0.78), max_faces)
        draw_surface(ax, m.vertices, m.faces[~obs], (0.9, 0.1, 0.1), max_faces)
        ax.plot(*segment.centerline.T, color="k", lw=2)
        set_equal(ax, m.vertices)
        ax.view_init(elev=elev, azim=azim)
    fig.suptitle(title or f"coverage {segment.coverage:.1%} (holes in red)", fontsize=10)
    fig.tight_layout()
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=dpi)
    plt.close(fig)
    return Path(path)
