"""A whole colon's partial reconstruction with sphere holes and a withdrawal trajectory (the map demo's input).

The sphere hole model (the paper's for CT colons) over the whole colon:
spheres centred on the surface crop the wall, and every point of the
partial cloud lies outside them; a face is observed when its centroid is
outside every sphere, which is the exact ground truth of this hole model.
The camera positions follow the centerline from the caecum to the rectum
(a withdrawal), with the back-and-forth of a real examination.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from colonbench import seeding
from colonbench.datagen.holes import inside_spheres, sample_surface


@dataclass
class WholePartial:
    """A whole colon's partial reconstruction (mm).

    Attributes
    ----------
    points : (n, 3) float
        The partial cloud.
    positions : (k, 3) float
        Camera positions in time order, caecum to rectum.
    observed : (f,) bool
        Per face of the colon's mesh: its centroid is outside every hole sphere.
    spheres : (h, 4) float
        Hole spheres: centre x, y, z and radius, mm.
    """

    points: np.ndarray
    positions: np.ndarray
    observed: np.ndarray
    spheres: np.ndarray


def whole_partial(colon, seed: int = 0, density: float = 2.0, holes_per_m: float = 25.0,
                  radius_mm=(4.0, 18.0)) -> WholePartial:
    """Sphere-cropped partial cloud of a whole colon, with a withdrawal trajectory.

    Parameters
    ----------
    colon : colonbench.datagen.colon.Colon
        Its centerline runs from the caecum (arc length 0) to the anus.
    seed : int
        Root seed; the draws descend from it (``seeding.rng(seed, "whole", ...)``).
    density : float
        Points per mm^2 of observed surface.
    holes_per_m : float
        Hole spheres per metre of centerline.
    radius_mm : (float, float)
        Range of sphere radii, mm (uniform).
    """
    rng = seeding.rng(seed, "whole", "holes")
    v, f = np.asarray(colon.mesh.vertices), np.asarray(colon.mesh.faces)
    count = max(int(round(holes_per_m * colon.centerline.length / 1000.0)), 1)
    centres = sample_surface(rng, v, f, count=count)
    radii = rng.uniform(radius_mm[0], radius_mm[1], count)
    pts = sample_surface(seeding.rng(seed, "whole", "points"), v, f, density=density)
    pts = pts[~inside_spheres(pts, centres, radii)]
    observed = ~inside_spheres(v[f].mean(axis=1), centres, radii)
    # withdrawal: caecum to rectum at 2 mm per pose, going back 10-30 mm now and then
    rng = seeding.rng(seed, "whole", "trajectory")
    s, path, length = 0.0, [], colon.centerline.length
    while s < length:
        path.append(s)
        s += 2.0
        if rng.random() < 0.02:
            back = rng.uniform(10.0, 30.0)
            path.extend(np.arange(s, max(s - back, 0.0), -2.0))
    positions = colon.centerline.point_at(np.clip(np.array(path), 0.0, length))
    return WholePartial(points=pts, positions=positions, observed=observed,
                        spheres=np.concatenate([centres, radii[:, None]], axis=1))
