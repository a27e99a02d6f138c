"""How much of a reconstruction the map's centerline reaches, and what a map of part of it says.

Every point of the reconstruction goes to the segment of its nearest centerline point. Where the
centerline follows only part of the reconstruction (a trajectory of another run, or of part of this
one, keeps it to where that scope went), the points it does not reach all go to the segments at its
ends, whose clouds then hold far more than one segment. A point is *reached* when it lies within
:data:`REACH_RADII` lumen radii (plus :data:`REACH_PLUS_MM`) of the centerline: on the whole-colon
suite's reconstructions, with their own trajectories, every point lies within 3.6 radii + 5 mm. A
segment whose cloud is more than :data:`UNREACHED_SHARE` unreached points is not estimated, with the
reason, and the map's summary records the share of points reached and of the mapped length estimated
(:func:`partial_warning` says so when the whole-colon coverage is of part of the colon).
"""

from __future__ import annotations

import numpy as np

#: A point farther from its nearest centerline point than this many radii of that piece, plus
#: :data:`REACH_PLUS_MM`, is beyond the centerline's reach.
REACH_RADII = 5.0
REACH_PLUS_MM = 5.0
#: A segment whose points are more than this share beyond reach is not estimated.
UNREACHED_SHARE = 0.1
#: Under this share of the points reached, the map is of part of the reconstruction.
REACHED_MIN = 0.99


def beyond_reach(joined, radii, points: np.ndarray) -> np.ndarray:
    """(n,) bool: the points that lie beyond the reach of the map's centerline.

    Parameters
    ----------
    joined : colonbench.mapping.colonmap.JoinedLine
    radii : sequence of float
        Each piece's lumen radius, mm, in the order of ``joined``.
    points : (n, 3) float
    """
    from scipy.spatial import cKDTree

    dist, nearest = cKDTree(joined.line).query(points)
    reach = REACH_RADII * np.asarray(radii, float)[joined.owner[nearest]] + REACH_PLUS_MM
    return dist > reach


def unreached_error(far: np.ndarray, reached: float, trajectory: bool) -> str:
    """Why a segment is not estimated when its cloud is mostly points beyond the centerline's reach, else "".

    Parameters
    ----------
    far : (k,) bool
        :func:`beyond_reach` of the segment's points.
    reached : float
        The share of the whole reconstruction's points within reach.
    trajectory : bool
        Whether the map was given a trajectory (then it is the likely cause).
    """
    if not len(far) or far.mean() <= UNREACHED_SHARE:
        return ""
    cause = ("the trajectory is the likely cause: the centerline keeps to where the scope went, so poses of "
             "another run, or of part of this one, map only that part (is --trajectory this reconstruction's?)"
             if trajectory else "the rest holds no lumen the centerline could follow (too sparse, or another "
             "object in the file?)")
    return (f"{int(far.sum())} of its {len(far)} points lie beyond the reach of the map's centerline, which "
            f"follows only part of the reconstruction (it reaches {100 * reached:.0f} % of the reconstruction's "
            f"points): {cause}; "
            "not estimated")


def partial_warning(summary: dict, trajectory: bool) -> str:
    """A sentence saying that the whole-colon coverage of a map's ``summary.json`` is of part of the colon, or
    "" when its estimated segments cover every mapped millimetre and its centerline reaches the reconstruction.
    """
    share, reached = summary["estimated_share"], summary["reached"]
    if share >= 1.0 and reached >= REACHED_MIN:
        return ""
    mapped = summary["estimated_mm"] / share if share > 0 else float("nan")
    figure = (f"the whole-colon coverage {summary['coverage']} is of part of the colon only"
              if summary["coverage"] is not None else "there is no whole-colon coverage")
    text = (f"{figure}: the segments estimated ({summary['estimated']} of {summary['segments']}) cover "
            f"{summary['estimated_mm']:.0f} of the {mapped:.0f} mm mapped ({100 * share:.0f} %), and the map's "
            f"centerline reaches {100 * reached:.0f} % of the reconstruction's points")
    if reached < REACHED_MIN and trajectory:
        text += "; the trajectory is the likely cause (is it this reconstruction's?)"
    return text + "; segments.json gives each segment's reason"
