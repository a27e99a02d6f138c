"""The whole-colon benchmark's figure: per track, a colon's map, its truth and the error side by side.

The map's own coloured mesh and picture (red at 50 % coverage or less to green, holes blue) are
:mod:`colonbench.mapping.mapfiles`; this figure renders them headless beside the true coverage of the same
segments and the error, on a diverging scale.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from colonbench.mapping.mapfiles import HOLE_RGB, NONE_RGB, coverage_rgb, map_mesh, render_views


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
