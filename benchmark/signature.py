"""A suite's per-sample signature: what each sample must match, and within what tolerance, on any machine.

A suite is regenerated from its manifest on the user's machine. Another CPU or
another build of a library changes the last bits of floats (Embree's ray
casts differ in float32 between instruction sets), and where the generator
takes a discrete decision at a near-tie (a face seen or not, a face centre
inside a hole sphere or not) it can take it the other way. Because a sample's
points are drawn face by face from one random stream, a face that moved by a
hair can send a draw to another face, and a flipped face redraws every point
after it. The published content hash (:mod:`colonbench.benchmark.fingerprint`)
moves with any of this, so it says only whether data are *bit-identical* to
the published ones. Whether they are *the published suite* is this module's
question, answered sample by sample.

Every sample's signature holds its id, hole model and length, its truth
(coverage, observed face count, centerline), its point counts and, for every
point set (the input at each noise level, the hole points, the centerline), a
sketch: the sums over its points of ``K`` smooth random features,
``sum_i o_k(i) cos(w_k . p_i + b_k)``, wavelengths 3 to 30 mm; ``o_k(i)`` is 1,
except that four features weigh a point by ``(-1)^i`` (two neighbours swapped)
and two by ``1 + t_i`` (``t_i`` its place from -1 to 1: a block moved), since
the order of a cloud is part of the data (the noise is drawn point by point).
A sketch is linear and smooth: float noise moves it by a hair, one point moved
by a tenth of a millimetre moves it far beyond tolerance. It also records how
the input was made (``cloud``): drawn on the true ``surface``, ``flawed``
(outliers, a second layer) or a ``reconstruction`` (a video's fused surface).

A sample is, against its published signature:

``same``
    counts equal, coverage within :attr:`Tolerances.coverage_float`, every
    sketch within :attr:`Tolerances.points_mm` of displacement;
``redrawn``
    the truth the same, but the noiseless input or the holes drawn anew (a
    draw sent to another face): the redrawn set must be drawn from the same
    surface (counts within :attr:`Tolerances.count_share`, every feature's mean
    within :attr:`Tolerances.z` standard errors) and, where drawn on the true
    surface, lie on it (every point within :attr:`Tolerances.surface_mm` of the
    faces it is drawn on; the noisy input is redrawn only with the noiseless);
``tie``
    the truth moved (observed face count or coverage) by at most
    :attr:`Tolerances.coverage_tie`: decided otherwise at a near-tie; every set
    but the centerline may be redrawn, as above;
``diverged``
    a tie after which the generator's later draws went another way (a point
    count changed by the tie shifts the stream: a second layer of another size),
    so that the input is not drawn alike; at most
    :attr:`Tolerances.diverged_share` of a suite (at least one sample);
``differs``
    anything else: the suite is refused, naming the sample and the quantity.

The suite as a whole must also keep its manifest and configuration, its
samples and their order, move the mean |coverage difference| by at most
:attr:`Tolerances.coverage_mean` and hold at most :attr:`Tolerances.tie_share`
samples decided at a near-tie. Why each tolerance has its value, from
regenerations with perturbed floats: decision record 0320 (:mod:`.verification` checks a whole suite).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: The signature recipe; a change of features, fields or comparison is a new version.
VERSION = "cbs1"
#: Features per sketch.
K = 16
#: Seed of the features (fixed for ``cbs1``).
FEATURE_SEED = 20261126
#: Wavelengths of the features, mm: from a few point spacings to a fold.
WAVELENGTHS_MM = (3.0, 30.0)


def _features():
    rng = np.random.default_rng(FEATURE_SEED)
    d = rng.normal(size=(K, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    omega = 2 * np.pi / np.geomspace(*WAVELENGTHS_MM, K)
    phase = rng.uniform(0, 2 * np.pi, K)
    order = np.full(K, PLAIN)
    order[[0, 2, 4, 6]] = ALTERNATING       # the shortest waves: two neighbours swapped move them most
    order[[9, 13]] = RAMP
    return d * omega[:, None], phase, order


#: How a feature weighs a point by its place ``i`` of ``n`` in the array: not at all, by ``1 + t`` (``t`` from -1 to
#: 1: a block moved elsewhere), or by ``(-1)^i`` (two neighbours swapped).
PLAIN, RAMP, ALTERNATING = 0, 1, 2
#: ``(K, 3)`` wave vectors (rad/mm), ``(K,)`` phases, ``(K,)`` how each feature weighs array order.
W, PHASE, ORDER = _features()
OMEGA = np.linalg.norm(W, axis=1)
#: Bound on the mean square of each feature (cos^2 <= 1; (1 + t)^2 averages 4/3 over an array).
FEATURE_VAR = np.where(ORDER == RAMP, 4.0 / 3.0, 1.0)


def _order_weights(n: int) -> np.ndarray:
    """``(n, K)``: each point's weight in each feature by its place in the array."""
    t = np.linspace(-1.0, 1.0, n) if n > 1 else np.zeros(n)
    sign = np.where(np.arange(n) % 2 == 0, 1.0, -1.0)
    return np.select([ORDER == RAMP, ORDER == ALTERNATING], [1.0 + t[:, None], sign[:, None]], np.ones((n, 1)))


def sketch(points, weights=None) -> np.ndarray:
    """The ``(K,)`` feature sums of a point set.

    Parameters
    ----------
    points : (n, 3) float
        mm; n may be 0.
    weights : (n,) float, optional
        Per-point weights (face areas, mm^2, for a sketch of a surface).

    Returns
    -------
    (K,) float64
    """
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if len(p) == 0:
        return np.zeros(K)
    g = np.cos(p @ W.T + PHASE) * _order_weights(len(p))
    if weights is not None:
        g *= np.asarray(weights, dtype=np.float64)[:, None]
    return g.sum(axis=0)


def points_entry(points) -> dict:
    """``{"n": count, "s": sketch}`` of a point set, as a signature stores it (sums to 1e-6, far below every
    tolerance)."""
    p = np.asarray(points).reshape(-1, 3)
    return {"n": int(len(p)), "s": rounded(sketch(p))}


def rounded(values) -> list[float]:
    """Sketch sums as stored: rounded to 1e-6."""
    return [round(float(x), 6) for x in values]


@dataclass(frozen=True)
class Tolerances:
    """How far a regenerated sample may be from its published signature (decision record 0320).

    Attributes
    ----------
    coverage_float : float
        ``same``: |coverage difference| (fraction) that float noise in face areas makes.
    points_mm : float
        ``same``: largest displacement, mm, that the sketch difference of a point set may amount to
        (``max_k |ds_k| / |w_k|``: one point moved by this much, or many by a share of it), for up to 20 000
        points; beyond, it grows as the square root of the count (:func:`same_limit_mm`).
    coverage_tie : float
        ``tie``: |coverage difference| a near-tie may make in one sample.
    count_share : float
        ``tie``: |count difference| / count of a redrawn point set (plus 3 points).
    z : float
        ``tie``: standard errors the mean of a feature over a redrawn point set may move.
    surface_mm : float
        A redrawn set drawn on the true surface: largest distance, mm, of one of its points from the surface it is
        drawn on (observed faces for the input, unobserved for the holes).
    coverage_mean : float
        Suite: mean |coverage difference| over its samples (moves any method's MAE by at most 100 times this,
        in points).
    tie_share : float
        Suite: largest share of samples decided otherwise at a near-tie (``tie`` and ``diverged``).
    diverged_share : float
        Suite: largest share of ``diverged`` samples (at least one sample may be).
    """

    coverage_float: float = 1e-6
    points_mm: float = 0.02
    coverage_tie: float = 5e-3
    count_share: float = 0.02
    z: float = 6.0
    surface_mm: float = 0.01
    coverage_mean: float = 1e-4
    tie_share: float = 0.5
    diverged_share: float = 0.01


TOLERANCES = Tolerances()
#: Points up to which :attr:`Tolerances.points_mm` holds as it is (:func:`same_limit_mm`).
NOISE_POINTS = 20000


def displacement_mm(a, b) -> float:
    """The displacement, mm, that the difference of two sketches amounts to at least: ``max_k |a_k - b_k| / |w_k|``."""
    return float(np.max(np.abs(np.asarray(a, float) - np.asarray(b, float)) / OMEGA))


def z_score(a: dict, b: dict) -> float:
    """How many standard errors apart the feature means of two independently drawn point sets are (the largest)."""
    na, nb = a["n"], b["n"]
    if na == 0 or nb == 0:
        return 0.0 if na == nb else float("inf")
    diff = np.abs(np.asarray(a["s"]) / na - np.asarray(b["s"]) / nb)
    return float(np.max(diff / np.sqrt(FEATURE_VAR * (1.0 / na + 1.0 / nb))))


# ---------------------------------------------------------------------------------------------- comparison


@dataclass
class SampleCheck:
    """One sample against its published signature.

    Attributes
    ----------
    sample : str
        Its id.
    level : {"same", "tie", "redrawn", "diverged", "differs"}
    what : str
        For ``differs``: the quantity and by how much; for ``tie`` and ``redrawn``: what changed.
    coverage_diff : float
        Found minus published coverage.
    """

    sample: str
    level: str
    what: str = ""
    coverage_diff: float = 0.0


def _same_points(name: str, found: dict, pub: dict, tol: Tolerances) -> str:
    if found["n"] != pub["n"]:
        return f"{name}: {found['n']} points, published {pub['n']}"
    d, limit = displacement_mm(found["s"], pub["s"]), same_limit_mm(pub["n"], tol)
    if not d <= limit:
        return f"{name}: points moved by {d:.3g} mm (tolerance {limit:.3g} mm)"
    return ""


def same_limit_mm(n: int, tol: Tolerances = TOLERANCES) -> float:
    """The displacement, mm, float noise may make in the sketch of ``n`` points: :attr:`Tolerances.points_mm`, growing
    as the square root of ``n`` beyond :data:`NOISE_POINTS` points (independent roundings add up as a random walk)."""
    return tol.points_mm * max(1.0, float(np.sqrt(n / NOISE_POINTS)))


def _drawn_alike(name: str, found: dict, pub: dict, tol: Tolerances) -> str:
    dn = abs(found["n"] - pub["n"])
    if dn > 3 + tol.count_share * pub["n"]:
        return f"{name}: {found['n']} points, published {pub['n']} (redrawn at a tie: tolerance " \
               f"{tol.count_share:.0%} + 3)"
    z = z_score(found, pub)
    if not z <= tol.z:
        return f"{name}: not drawn from the same surface ({z:.1f} standard errors, tolerance {tol.z:g})"
    return ""


#: The noiseless input of a sample, by its signature entry's name.
NOISELESS = "input@0"


def _may_redraw(name: str, tie: bool, redrawn: set) -> bool:
    """Whether the generator can have drawn point set ``name`` anew from float noise alone (module docstring): a
    noisy input only with the noiseless one, tie or not (it is that one plus the suite's fixed noise draw, point by
    point); the noiseless input and the holes always (a face's area moved by a hair moves which face a draw lands
    on); any other set at a tie."""
    if name.startswith("input@") and name != NOISELESS:
        return NOISELESS in redrawn
    return tie or name in ("holes", NOISELESS)


def check_sample(found: dict, pub: dict, tol: Tolerances = TOLERANCES, surface=None) -> SampleCheck:
    """Compare one sample's signature with the published one (levels as in the module docstring).

    Parameters
    ----------
    found, pub : dict
        The sample's signature here and as published.
    tol : Tolerances
    surface : callable, optional
        ``surface()`` -> ``{"input": mm, "holes": mm}``: the largest distance of a noiseless input point from the
        sample's observed surface, and of a hole point from its unobserved surface (asked only for a redrawn
        set; without it a set drawn on the surface may not be redrawn).
    """
    sid = pub["sample"]
    dc = float(found["coverage"]) - float(pub["coverage"])
    out = SampleCheck(sid, "differs", coverage_diff=dc)
    for key in ("sample", "hole_model"):
        if found[key] != pub[key]:
            out.what = f"{key} is {found[key]!r}, published {pub[key]!r}"
            return out
    if abs(found["length_mm"] - pub["length_mm"]) > 1e-6:
        out.what = f"length {found['length_mm']:g} mm, published {pub['length_mm']:g} mm"
        return out
    if set(found["points"]) != set(pub["points"]):
        out.what = (f"point sets {', '.join(sorted(found['points']))}, published {', '.join(sorted(pub['points']))} "
                    "(another noise protocol)")
        return out
    exact = set(pub.get("exact", ()))
    for name in sorted(exact):       # truth that no tie moves (a centerline, a whole colon's surface)
        why = _same_points(name, found["points"][name], pub["points"][name], tol)
        if why:
            out.what = why
            return out
    tie = found["observed_faces"] != pub["observed_faces"] or not abs(dc) <= tol.coverage_float
    if tie and not abs(dc) <= tol.coverage_tie:   # a NaN coverage too
        out.what = f"coverage {found['coverage']:.6f}, published {pub['coverage']:.6f} (differs by {dc:+.2e}, " \
                   f"more than a near-tie makes: {tol.coverage_tie:g})"
        return out
    cloud, redrawn, far, diverged = pub.get("cloud", "surface"), set(), None, []
    for name in sorted(set(pub["points"]) - exact):
        why = _same_points(name, found["points"][name], pub["points"][name], tol)
        if not why:
            continue
        if not _may_redraw(name, tie, redrawn):
            out.what = why
            return out
        if name == "holes" or (name == NOISELESS and cloud == "surface"):
            far = far if far is not None else (surface() if surface is not None else {})
            d = far.get("input" if name == NOISELESS else "holes", float("inf"))
            if not d <= tol.surface_mm:
                out.what = f"{why}, and a point lies {d:.3g} mm off the surface it is drawn on"
                return out
        why = _drawn_alike(name, found["points"][name], pub["points"][name], tol)
        if why and not tie:
            out.what = why
            return out
        if why:                     # after the tie the generator's draws went another way (module docstring)
            diverged.append(why)
        redrawn.add(name)
    if diverged:
        out.level = "diverged"
        out.what = (f"{found['observed_faces'] - pub['observed_faces']:+d} observed faces, coverage {dc:+.1e} at a "
                    f"near-tie, and the draws after it went another way: {diverged[0]}")
        return out
    out.level = "tie" if tie else "redrawn" if redrawn else "same"
    if tie:
        out.what = (f"{found['observed_faces'] - pub['observed_faces']:+d} observed faces, coverage {dc:+.1e}: decided "
                    "otherwise at a near-tie" + (f"; {', '.join(sorted(redrawn))} redrawn" if redrawn else ""))
    elif redrawn:
        out.what = f"{', '.join(sorted(redrawn))} redrawn on the same surface"
    return out
