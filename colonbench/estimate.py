"""What every coverage-estimation method returns: the result contract shared by methods and the benchmark."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class Estimate:
    """What a coverage-estimation method returns for one partial segment (mm, the input's frame).

    Attributes
    ----------
    coverage : float
        Estimated observed fraction of the segment surface, in [0, 1].
    holes : (k, 3) float
        Points of the estimated holes, mm.
    centerline : (m, 3) float
        Estimated centerline, mm, spacing 0.5 mm.
    method : str
    mesh_vertices : (v, 3) float
        Completed mesh, mm (empty for methods without one).
    mesh_faces : (f, 3) int
    hole_vertices : (v,) bool
        Which mesh vertices are holes.
    seconds : dict
        Wall time per stage.
    """

    coverage: float
    holes: np.ndarray
    centerline: np.ndarray
    method: str
    mesh_vertices: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    mesh_faces: np.ndarray = field(default_factory=lambda: np.zeros((0, 3), dtype=np.int64))
    hole_vertices: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))
    seconds: dict = field(default_factory=dict)

    def to_json(self) -> dict:
        """The ``estimate`` command's JSON: coverage, holes, centerline (mm), method."""
        return {"coverage": float(self.coverage), "holes": np.round(self.holes, 4).tolist(),
                "centerline": np.round(self.centerline, 4).tolist(), "method": self.method,
                "seconds": {k: round(v, 4) for k, v in self.seconds.items()}}
