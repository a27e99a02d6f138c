"""Which calibration ships: decision record 0172's rule over the held-out cells of every (scheme, known extent) pair,
with 0174's scheme in use kept where no pair holds.

``scripts/calibrate_intervals.py`` measures each candidate leave-one-colon-out and summarises it per cell (a
calibration set or a real colon on its own, at a noise level): ``{"cells": {name: {"n", "inside", "width"}},
"real_width", "shortfall"}``, shares inside in % (to 0.1), widths in points. A cell holds within 85-95 % inside, each
edge moved out by the binomial standard error of a share at it over the cell's estimates (:func:`band`); a pair holds
where all sixteen of its cells do, the scheme's eight and its known-length interval's eight.
"""

from __future__ import annotations

import math

#: The shares inside (%) a held-out cell holds within, each moved out by its standard error (:func:`band`).
EDGES = (85.0, 95.0)


def band(n: int) -> tuple[float, float]:
    """The band a cell's share inside holds within.

    Parameters
    ----------
    n : int
        The cell's estimates.

    Returns
    -------
    low, high : float
        :data:`EDGES` (%), each moved out by ``100 sqrt(p (1 - p) / n)``, the binomial standard error of a share
        ``p`` at that edge over ``n``: 83.2 and 96.1 % for 400 estimates.
    """
    lo, hi = (p / 100.0 for p in EDGES)
    return EDGES[0] - 100 * math.sqrt(lo * (1 - lo) / n), EDGES[1] + 100 * math.sqrt(hi * (1 - hi) / n)


def outside(cell: dict) -> float:
    """The points by which a cell's share inside (``{"n", "inside"}``, %) lies outside its :func:`band`; 0 within."""
    lo, hi = band(cell["n"])
    return max(lo - cell["inside"], 0.0) + max(cell["inside"] - hi, 0.0)


def shortfall(summary: dict) -> float:
    """The points by which a candidate's cells lie outside their bands, summed (:func:`outside`), to 2 decimals.

    Parameters
    ----------
    summary : dict
        A candidate's summary, its ``cells`` (name -> ``{"n", "inside", ...}``).

    Returns
    -------
    float
        Points; 0 where every cell holds, or where they lie outside by under 0.005 points in all (:func:`holds`
        tells those apart).
    """
    return round(sum(outside(c) for c in summary["cells"].values()), 2)


def holds(summary: dict) -> bool:
    """Whether every cell of a candidate's summary lies within its :func:`band`."""
    return all(outside(c) == 0.0 for c in summary["cells"].values())


def choose_pair(schemes: dict, known: dict, keep: str | None = None) -> tuple[str, str, list]:
    """Decision record 0172's rule: every (scheme, known extent) pair is a candidate, judged on its sixteen held-out
    cells. Of the pairs whose cells all hold (:func:`holds`), the scheme narrowest over the real colons, with its
    known extent narrowest over them among its pairs that hold; if none holds, the pair with the smallest
    :func:`shortfall`, then the narrowest scheme, then the narrowest known extent, among the pairs of the scheme
    ``keep`` where it is given (decision record 0174: the scheme in use stays unless a pair holds), else among all.
    Equals keep the first in ``schemes``' and ``known``'s order.

    Parameters
    ----------
    schemes : dict
        Scheme -> its summary (``cells``, ``real_width``: the real colons' mean held-out width, points,
        ``shortfall``).
    known : dict
        Scheme -> known-extent candidate (``K0``-``K3``) -> its summary, of the scheme's known-length intervals.
    keep : str, optional
        The scheme in use, kept where no pair holds; one of ``schemes``.

    Returns
    -------
    scheme, known extent : str
    pairs : list of dict
        Every pair's ``scheme``, ``known``, ``holds``, ``shortfall`` (points, both parts) and the two real widths
        (``width``, ``known_width``, points), in the order tried.
    """
    if keep is not None and keep not in schemes:
        raise ValueError(f"the scheme to keep, {keep!r}, is not a candidate")
    pairs = [{"scheme": s, "known": k, "holds": holds(schemes[s]) and holds(known[s][k]),
              "shortfall": round(schemes[s]["shortfall"] + known[s][k]["shortfall"], 2),
              "width": schemes[s]["real_width"], "known_width": known[s][k]["real_width"]}
             for s in schemes for k in known[s]]
    holding = [p for p in pairs if p["holds"]]
    if holding:
        scheme = min(holding, key=lambda p: p["width"])["scheme"]
        pick = min((p for p in holding if p["scheme"] == scheme), key=lambda p: p["known_width"])
    else:
        pick = min((p for p in pairs if keep in (None, p["scheme"])),
                   key=lambda p: (p["shortfall"], p["width"], p["known_width"]))
    return pick["scheme"], pick["known"], pairs
