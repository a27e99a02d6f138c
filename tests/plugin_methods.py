"""Methods a user might write, loaded by the tests through ``--methods plugin_methods:Name``."""

import numpy as np


class Oracle:
    """Returns the ground truth itself (a reference: it declares uses_truth)."""

    name = "oracle"
    version = "1.0"
    uses_truth = True

    def estimate(self, points, truth):
        return {"coverage": truth["coverage"], "holes": truth["hole_points"], "centerline": truth["centerline"]}


class Broken:
    """Raises on every segment."""

    name = "broken"

    def estimate(self, points):
        raise RuntimeError("this method is broken")


class HalfCoverage:
    """No name, no version: the registry names it after the class. Returns a bare dict."""

    def estimate(self, points):
        return {"coverage": 0.5, "holes": np.asarray(points)[:3], "centerline": []}
