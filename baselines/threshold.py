"""Thresholding (the paper's baseline 1): the learned heatmap, with mesh extraction replaced by thresholding.

The voxels of the (predicted) target heatmap below ``threshold`` (near its
zero, the surface) stand for the completed surface; those farther than
sqrt(2)/2 voxel from every partial point are hole voxels, and

    coverage = 1 - hole voxels / surface voxels.

As the paper notes, such a surface varies in thickness, which is what the
mesh step fixes. For a fair comparison the surface voxels are cut at the
same segment end planes as the mesh of the full method
(:func:`colonbench.completion.planes.segment_planes`), so the two differ only in
the step the paper compares.
"""

from __future__ import annotations

import numpy as np

from colonbench.completion.heatmap_centerline import extract_centerline
from colonbench.completion.planes import END_INSET, inside_planes, line_between, segment_planes
from colonbench.completion.surface import HOLE_DISTANCE, hole_vertices
from colonbench.estimate import Estimate
from colonbench.grid import Grid
from colonbench.polyline import resample

#: Voxels below this heatmap value are surface voxels.
THRESHOLD = 0.1


def threshold_coverage(heatmap: np.ndarray, grid: Grid, points, threshold: float = THRESHOLD,
                       method: str = "thresholding", centerline_vox: np.ndarray | None = None,
                       cut_rims: bool = True) -> Estimate:
    """Coverage, hole points and centerline from a target heatmap by thresholding (points and results in mm).

    Parameters
    ----------
    heatmap : (S, S, S) float
        Target heatmap on ``grid``.
    grid : Grid
    points : (n, 3) float
        Partial cloud, mm.
    threshold : float
    centerline_vox : (m, 3) float, optional
        Centerline in voxels, if already extracted from the same heatmap.
    cut_rims : bool
        Cut at the cloud's cut rims where found, as the full method does.
    """
    cl = extract_centerline(heatmap) if centerline_vox is None else np.asarray(centerline_vox, float)
    vox = np.argwhere(np.asarray(heatmap) < threshold).astype(float)
    partial = grid.to_voxel(np.asarray(points, dtype=float))
    planes = segment_planes(cl, partial, cut_rims)
    vox = vox[inside_planes(vox, planes, END_INSET)]
    hole = hole_vertices(vox, partial, HOLE_DISTANCE, false_hole_rate=None)  # the baseline as the paper ran it
    coverage = float(1.0 - hole.mean()) if len(vox) else float("nan")
    cl = line_between(cl, planes)
    centerline = resample(grid.to_mm(cl), 0.5) if len(cl) else np.zeros((0, 3))
    return Estimate(coverage, grid.to_mm(vox[hole]) if hole.any() else np.zeros((0, 3)), centerline, method)


class ThresholdMethod:
    """Baseline 1 behind the method interface: the shared network prediction, thresholded.

    Parameters
    ----------
    model : path, optional
        Model of the prediction (default: the shipped one); shared with the
        ``completion`` method in the same process, so the network runs once.
    device : str
    threshold : float
        Voxels of the predicted heatmap below this are surface voxels.
    cut_rims : bool
        Cut at the cloud's cut rims where found, as the full method does.
    tta : int
        Symmetries the shared prediction is averaged over (:mod:`colonbench.completion.symmetry`).
    """

    name = "thresholding"

    def __init__(self, model=None, device: str = "cpu", threshold: float = THRESHOLD, cut_rims: bool = True,
                 tta: int = 1):
        from colonbench.completion.method import prediction_version, shared_predictor

        self.predictor = shared_predictor(model, device, tta)
        self.threshold = float(threshold)
        self.cut_rims = cut_rims
        self.version = f"{prediction_version(self.predictor)},threshold={self.threshold:g}"

    def estimate(self, points) -> Estimate:
        """Coverage, holes and centerline of one partial segment (mm)."""
        from colonbench.completion.method import on_prediction

        return on_prediction(self.predictor, points, "threshold", lambda pts, p: threshold_coverage(
            p.heatmap, p.grid, pts, self.threshold, self.name, p.centerline_vox, self.cut_rims))
