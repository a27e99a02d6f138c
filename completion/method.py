"""The paper's coverage estimation, end to end: partial points (mm) -> coverage, holes, centerline (mm).

:class:`CompletionMethod` is the one API for it: the ``estimate`` command, the
benchmark harness and users' scripts all call :meth:`CompletionMethod.estimate`.
Steps and where they live:

1. grid from the partial points alone (:func:`colonbench.grid.fit_grid`) and the
   input heatmap (:func:`colonbench.heatmaps.input_from_points`), exactly as the
   training data were made;
2. the UNet predicts the target heatmap (:mod:`colonbench.completion.network`);
3. centerline (:mod:`colonbench.completion.centerline`);
4. completed mesh, hole vertices and coverage (:mod:`colonbench.completion.surface`);
5. back to mm in the input's frame.

:meth:`CompletionMethod.from_heatmap` runs steps 3-5 on any target heatmap,
e.g. the ground truth, which bounds the error of everything after the network.
"""

from __future__ import annotations

import time
from importlib import resources
from pathlib import Path

import numpy as np

from colonbench.completion.centerline import extract_centerline, resample
from colonbench.completion.surface import complete
from colonbench.errors import InputError
from colonbench.estimate import Estimate
from colonbench.grid import Grid, check_points, fit_grid, principal_axes
from colonbench.heatmaps import input_from_points

#: Fewest points accepted: below this there is no segment to complete.
MIN_POINTS = 200
#: A cloud whose largest side is below this is taken to be in metres, mm.
METRES_BELOW_MM = 2.0
#: A cloud whose largest side is above this is not one segment, mm.
MAX_SEGMENT_MM = 250.0
#: Spacing of the centerline returned, mm.
CENTERLINE_SPACING_MM = 0.5


def shipped_model() -> Path:
    """Path of the model that ships in the package (``colonbench/completion/models/small.safetensors``)."""
    return Path(str(resources.files("colonbench.completion").joinpath("models/small.safetensors")))


def check_cloud(points, what: str = "point cloud") -> np.ndarray:
    """A partial segment cloud in mm, or an :class:`InputError` saying what is wrong with it."""
    pts = check_points(points, what, min_points=1)
    if len(pts) < MIN_POINTS:
        raise InputError(f"{what}: only {len(pts)} point(s); a partial colon segment needs at least {MIN_POINTS} "
                         "(colonbench's clouds have about 2 points per mm^2)")
    extent = float(np.ptp((pts - pts.mean(axis=0)) @ principal_axes(pts).T, axis=0).max())
    if extent < METRES_BELOW_MM:
        raise InputError(f"{what}: spans only {extent:.3g} units; colonbench works in millimetres, and this looks "
                         "like metres (multiply by 1000)")
    if extent > MAX_SEGMENT_MM:
        raise InputError(f"{what}: spans {extent:.0f} mm, far more than one colon segment (5-7 cm); cut the "
                         "reconstruction into segments along its centerline first")
    return pts


class CompletionMethod:
    """The learned completion method of the paper.

    Parameters
    ----------
    model : path, optional
        A ``.safetensors`` model from ``colonbench train`` (default: the shipped one).
    device : str
        ``cpu``, ``cuda``, ``auto``.
    hole_distance : float, optional
        Vertices farther than this from the partial cloud are holes, voxels
        (default: the paper's sqrt(2)/2).

    The model is loaded once, at construction; call :meth:`estimate` on as
    many clouds as needed.
    """

    name = "completion"

    def __init__(self, model=None, device: str = "cpu", hole_distance: float | None = None):
        from colonbench.completion.network import load_model, resolve_device

        path = Path(model) if model is not None else shipped_model()
        if model is None and not path.is_file():
            raise InputError("no model ships with this installation; train one (colonbench train) and pass it")
        self.device = resolve_device(device)
        self.net, self.config, self.meta = load_model(path, self.device)
        self.model_path = path
        self.hole_distance = hole_distance
        self.version = f"{path.stem}@{self.meta.get('steps', '?')}"
        self.grid_options = self.meta.get("grid_options", {})

    def predict(self, points) -> tuple[Grid, np.ndarray, np.ndarray]:
        """Grid, input heatmap and predicted target heatmap of a partial cloud (mm)."""
        import torch

        grid = fit_grid(points, **self.grid_options)
        h_in, _ = input_from_points(grid, points)
        with torch.no_grad():
            x = torch.from_numpy(h_in[None, None]).to(self.device)
            pred = self.net(x)[0, 0].float().cpu().numpy()
        return grid, h_in, np.clip(pred, 0.0, 1.0)

    def estimate(self, points) -> Estimate:
        """Coverage, holes and centerline of one partial segment (points in mm)."""
        t0 = time.perf_counter()
        pts = check_cloud(points)
        t1 = time.perf_counter()
        grid, _, pred = self.predict(pts)
        t2 = time.perf_counter()
        est = from_heatmap(pred, grid, pts, self.name, self.hole_distance)
        est.seconds = {"check": t1 - t0, "network": t2 - t1, **est.seconds}
        return est


def from_heatmap(heatmap: np.ndarray, grid: Grid, points, method: str = "completion",
                 hole_distance: float | None = None) -> Estimate:
    """Steps after the network: centerline, completed mesh, holes and coverage of a target heatmap.

    Parameters
    ----------
    heatmap : (S, S, S) float
        A target heatmap (predicted, or the ground truth) on ``grid``.
    grid : Grid
    points : (n, 3) float
        The partial cloud, mm.
    """
    t0 = time.perf_counter()
    cl_vox = extract_centerline(heatmap)
    t1 = time.perf_counter()
    pts = np.asarray(points, dtype=float)
    comp = complete(heatmap, cl_vox, grid.to_voxel(pts), hole_distance)
    t2 = time.perf_counter()
    verts = grid.to_mm(comp.vertices) if len(comp.vertices) else np.zeros((0, 3))
    cl = resample(grid.to_mm(cl_vox), CENTERLINE_SPACING_MM) if len(cl_vox) else np.zeros((0, 3))
    return Estimate(coverage=comp.coverage, holes=verts[comp.hole], centerline=cl, method=method,
                    mesh_vertices=verts, mesh_faces=comp.faces, hole_vertices=comp.hole,
                    seconds={"centerline": t1 - t0, "mesh_holes": t2 - t1})
