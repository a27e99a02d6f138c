"""Signals of a cloud unlike the colons the network learned from, for the estimate's interval and its review.

A colon unlike the training data is off as a whole (decision record 0325): its estimates share a shift that the
rims, the estimate and the line's length do not show. Three signals the estimate can see:

``spread``
    How much the network disagrees with itself: the mean ``|p - p'|`` of its heatmap ``p`` and the heatmap
    ``p'`` it predicts for the same grid turned half a turn about the tube's axis and reversed (one of the grid's
    symmetries, :mod:`colonbench.completion.symmetry`; nothing in a colon prefers either), over the voxels where
    either says something (differs from the background's 0.5 by more than :data:`SAYS`). One more network pass.
``radius_mm``
    The lumen's width as the cloud shows it: the median distance (mm) of the cloud's points to the line between
    the planes.
``extent_mm``
    The cloud's extent along its principal axis (mm): a line far longer than the cloud is long has wandered
    through pockets of a wide lumen.

And one of how much of the wall the network had to make up (decision record 0161): ``hole_depth_mm``, how far the
completed surface's hole vertices lie from the nearest point of the cloud (their 90th percentile, mm). A small
hole ringed by seen wall is shallow; a wall no camera saw is deep, and there the network guesses. And one of how
well the network's wall fits what was seen (decision record 0165): ``wall_misfit_mm``, how far the cloud's points
lie from the completed surface's nearest vertices (their 90th percentile, mm); a network that knows a colon puts its
wall through the points it was given. ``spread``, ``hole_depth_mm`` and ``wall_misfit_mm`` are computed where a
calibration uses them (:func:`signals`).
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from colonbench.grid import principal_axes

#: A heatmap voxel whose value differs from 0.5 by more than this says surface (0) or line (1).
SAYS = 0.2
#: The symmetry of :data:`colonbench.completion.symmetry.SYMMETRIES` the spread compares against: a half turn
#: about the tube's axis with the tube reversed.
SECOND_VIEW = (2, 1, 0)


def spread(forward, x, heatmap: np.ndarray | None = None) -> float:
    """The network's disagreement with itself under :data:`SECOND_VIEW` (fraction of the heatmap's range).

    Parameters
    ----------
    forward : callable
        The network, ``(1, C, S, S, S)`` tensors to ``(1, 1, S, S, S)``.
    x : (1, C, S, S, S) torch.Tensor
        Its input.
    heatmap : (S, S, S) float, optional
        Its single prediction for ``x``, clipped to [0, 1], where the caller has it (not an average over
        symmetries, not interpolated onto another grid); else the network runs on ``x`` once more.

    Returns
    -------
    float
        Mean ``|p - p'|`` over the voxels where either differs from 0.5 by more than :data:`SAYS`; 0 where none.
    """
    import torch

    from colonbench.completion.symmetry import transform

    with torch.inference_mode():
        y = transform(forward(transform(x, SECOND_VIEW).contiguous()), SECOND_VIEW, inverse=True)
        if heatmap is None:
            heatmap = np.clip(forward(x)[0, 0].float().cpu().numpy(), 0.0, 1.0)
    other = np.clip(y[0, 0].float().cpu().numpy(), 0.0, 1.0)
    says = (np.abs(heatmap - 0.5) > SAYS) | (np.abs(other - 0.5) > SAYS)
    return float(np.abs(heatmap - other)[says].mean()) if says.any() else 0.0


def shape(points: np.ndarray, line: np.ndarray) -> dict:
    """``radius_mm`` and ``extent_mm`` of a cloud (points, (n, 3) mm) around its line between the planes
    ((m, 3) mm, resampled); ``radius_mm`` is 0 where the line is empty."""
    pts = np.asarray(points, float)
    along = pts @ principal_axes(pts)[0]
    radius = float(np.median(cKDTree(line).query(pts)[0])) if len(line) else 0.0
    return {"radius_mm": round(radius, 2), "extent_mm": round(float(along.max() - along.min()), 2)}


#: The percentile of the hole vertices' distances :func:`hole_depth` reports.
DEPTH_PERCENTILE = 90.0


def hole_depth(points: np.ndarray, holes: np.ndarray) -> float:
    """``hole_depth_mm``: the :data:`DEPTH_PERCENTILE`-th percentile of the distances (mm) from the completed
    surface's hole vertices (``holes``, (h, 3) mm) to the nearest point of the cloud (``points``, (n, 3) mm); 0 where
    there is no hole vertex."""
    holes = np.asarray(holes, float).reshape(-1, 3)
    if not len(holes) or not len(points):
        return 0.0
    return round(float(np.percentile(cKDTree(np.asarray(points, float)).query(holes)[0], DEPTH_PERCENTILE)), 2)


#: The percentile of the cloud's distances to the completed surface :func:`wall_misfit` reports.
MISFIT_PERCENTILE = 90.0


def wall_misfit(points: np.ndarray, vertices: np.ndarray) -> float:
    """``wall_misfit_mm``: the :data:`MISFIT_PERCENTILE`-th percentile of the distances (mm) from the cloud's points
    (``points``, (n, 3) mm) to the nearest vertex of the completed surface (``vertices``, (v, 3) mm, holes
    included); 0 where either is empty."""
    vertices = np.asarray(vertices, float).reshape(-1, 3)
    if not len(vertices) or not len(points):
        return 0.0
    d = cKDTree(vertices).query(np.asarray(points, float))[0]
    return round(float(np.percentile(d, MISFIT_PERCENTILE)), 3)


def signals(points: np.ndarray, line: np.ndarray, holes: np.ndarray, prediction=None, depth: bool = False,
            vertices: np.ndarray | None = None) -> dict:
    """An estimate's novelty signals: :func:`shape` always; ``spread`` where ``prediction`` is given (its
    ``spread``: one more network pass), ``hole_depth_mm`` where ``depth`` (a search of the cloud) and
    ``wall_misfit_mm`` where the completed surface's ``vertices`` are given (a search of them), as a calibration's
    features use them. ``points``: the cloud, ``line``: its line between the planes, ``holes``: the completed
    surface's hole vertices ((n, 3), (m, 3), (h, 3) mm)."""
    out = shape(points, line)
    if prediction is not None:
        out["spread"] = round(prediction.spread, 5)
    if depth:
        out["hole_depth_mm"] = hole_depth(points, holes)
    if vertices is not None:
        out["wall_misfit_mm"] = wall_misfit(points, vertices)
    return out
