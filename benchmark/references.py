"""Reference rows that bound the problem. Each is given the ground truth, so none is a method a user could run.

* ``gt-heatmap``: the full method's steps after the network, fed the GT
  target heatmap: the error of everything after the network.
* ``unwrap-gt``: 2D unwrapping around the GT centerline: the unwrapping
  baseline with a perfect centerline.
* ``constant``: the mean coverage of the model's training data for every
  segment (holes and centerline empty, so their metrics are undefined).

Methods that declare ``uses_truth = True`` are called by the harness as
``estimate(points, truth=truth)``; ``truth`` is a dict with ``coverage``,
``hole_points`` (k, 3) mm, ``centerline`` (m, 3) mm, ``vertices`` (v, 3) mm,
``faces`` (f, 3), ``target`` (S, S, S) float32, the GT target heatmap, and
``grid`` (:class:`colonbench.grid.Grid`), the grid it lies on. The
leaderboard marks their rows as references.
"""

from __future__ import annotations

import numpy as np

from colonbench.baselines.unwrap import RASTER, unwrap_coverage
from colonbench.errors import InputError
from colonbench.estimate import Estimate


class GTHeatmapMethod:
    """The completion method's centerline, mesh and hole steps on the GT target heatmap."""

    name = "gt-heatmap"
    uses_truth = True

    def __init__(self):
        from colonbench.completion.method import steps_version

        self.version = steps_version()

    def estimate(self, points, truth: dict) -> Estimate:
        from colonbench.completion.method import from_heatmap, method_cloud

        # the method's own cloud: a dense one thinned as completion thins it (its holes are counted from it)
        return from_heatmap(truth["target"], truth["grid"], method_cloud(points), self.name)


class UnwrapGTMethod:
    """2D unwrapping around the GT centerline."""

    name = "unwrap-gt"
    version = RASTER
    uses_truth = True

    def estimate(self, points, truth: dict) -> Estimate:
        from colonbench.completion.method import check_cloud

        return unwrap_coverage(check_cloud(points), truth["centerline"], self.name)


class ConstantMethod:
    """The same coverage for every segment: the mean coverage of the model's training data.

    Parameters
    ----------
    model : path, optional
        The model whose metadata holds ``train_coverage_mean`` (default: the shipped one).
    coverage : float, optional
        Use this value instead.
    """

    name = "constant"
    uses_truth = False
    reference = True

    def __init__(self, model=None, device: str = "cpu", coverage: float | None = None):
        if coverage is None:
            from colonbench.completion.method import shared_predictor

            coverage = shared_predictor(model, device).meta.get("train_coverage_mean")
            if coverage is None:
                raise InputError("the model records no train_coverage_mean; give the constant's coverage")
        self.coverage = float(coverage)
        self.version = f"{self.coverage:.4f}"

    def estimate(self, points) -> Estimate:
        return Estimate(self.coverage, np.zeros((0, 3)), np.zeros((0, 3)), self.name)
