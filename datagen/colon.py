"""Procedural colons: an anatomical centerline, a lumen with haustral folds, taeniae and polyps.

The frame of a procedural colon is the patient's: ``x`` towards the patient's
left, ``y`` anterior, ``z`` superior, millimetres. The colon runs from the
caecum (lower right) up the ascending colon, across the sagging transverse colon
between the hepatic and splenic flexures, down the descending colon, through the
sigmoid loop to the rectum.

Algorithm (all random draws from one seeded generator):

1. jitter a template of anatomical control points, bend the transverse colon
   down by the drawn sag and lift the sigmoid loop;
2. interpolate a cubic spline and scale it to the drawn length; where
   ``tortuosity_mm`` is set, bend it by a smooth random displacement across
   itself (:func:`bend_randomly`);
3. limit the curvature where a bend would be tighter than the local radius
   (local Gaussian smoothing, repeated), rescale to the drawn length;
4. check, exactly, that no two cross-sections of the tube intersect (with the
   configured clearance); if they do, redraw (up to ``max_attempts``);
5. sweep rings along rotation-minimising frames with a radius field
   ``rho(s, theta)``: base radius by region, three taeniae coli, haustral folds
   between the taeniae, sessile polyps and smooth roughness.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import trimesh
from scipy.interpolate import CubicSpline, PchipInterpolator
from scipy.ndimage import gaussian_filter, gaussian_filter1d

from colonbench import seeding
from colonbench.datagen.config import ColonConfig, validate
from colonbench.datagen.tube import ring_angles, self_intersections, sweep
from colonbench.errors import ColonbenchError
from colonbench.params import draw
from colonbench.polyline import Centerline

#: Anatomical template (mm, patient frame), before jitter and scaling. Each row
#: is ``(x, y, z, region)``; region codes index :data:`REGIONS`.
_TEMPLATE = np.array([
    (-100, 0, -80, 0), (-105, -10, -30, 1), (-102, -15, 30, 1), (-92, -5, 90, 2), (-60, 20, 110, 2),
    (-25, 45, 75, 3), (20, 50, 65, 3), (60, 35, 95, 3), (100, 5, 135, 4), (118, -20, 110, 4),
    (120, -30, 50, 5), (116, -30, -10, 5), (105, -20, -70, 5), (72, 8, -98, 6), (38, 48, -72, 6),
    (8, 62, -42, 6), (-28, 42, -52, 6), (-24, 8, -92, 6), (0, -24, -112, 7), (4, -44, -150, 7),
    (0, -36, -192, 7),
], dtype=float)
REGIONS = ("caecum", "ascending", "hepatic_flexure", "transverse", "splenic_flexure", "descending",
           "sigmoid", "rectum")
#: Haustral fold strength per region (the rectum has few folds).
_FOLD_WEIGHT = np.array([0.7, 1.0, 1.0, 1.0, 1.0, 0.85, 0.7, 0.25])


@dataclass
class Colon:
    """A colon surface with its ground-truth centerline.

    Attributes
    ----------
    mesh : trimesh.Trimesh
        Lumen surface, mm, normals out of the lumen.
    centerline : Centerline
        GT centerline, 0.5 mm spacing for procedural colons.
    radius : (n,) float
        Largest wall distance from the centerline at each centerline sample, mm
        (NaN for imported colons).
    ring_arclength : (K,) float or None
        For swept tubes: ring ``k`` of the mesh holds vertices
        ``k * n_around ... (k + 1) * n_around - 1`` and lies at this arc length, mm.
    n_around : int or None
        For swept tubes: vertices per ring.
    info : dict
        What was drawn (region boundaries, polyps, ...), JSON-friendly.
    """

    mesh: trimesh.Trimesh
    centerline: Centerline
    radius: np.ndarray
    ring_arclength: np.ndarray | None = None
    n_around: int | None = None
    info: dict = field(default_factory=dict)


def generate_colon(config: ColonConfig | None = None, seed: int = 0, colon_id: int = 0,
                   lumen_centerline: bool = False) -> Colon:
    """Generate one procedural colon.

    Parameters
    ----------
    config : ColonConfig, optional
        Shape parameters (defaults: :class:`ColonConfig`).
    seed : int
        Root seed of the dataset.
    colon_id : int
        Index of the colon under the root seed; colon ``i`` is the same whatever
        else is generated.
    lumen_centerline : bool
        Record as the colon's centerline the centre of its lumen
        (:func:`lumen_centred_line`) instead of the axis the tube was swept
        around (``truth.lumen_centerline``). The surface is the same either way.

    Returns
    -------
    Colon

    Raises
    ------
    ColonbenchError
        When no layout free of self-intersection was found in ``max_attempts``.
    """
    config = validate(config or ColonConfig())
    last = None
    for attempt in range(config.max_attempts):
        rng = seeding.rng(seed, "colon", colon_id, attempt)
        centerline, params = _centerline(config, rng)
        base = _base_radius(config, params, centerline.arclength)
        max_radius = base * (1.0 + params.get("ellipticity", 0.0)) + 3.0 * params["roughness_mm"] + _pouch_reach(config)
        clash = self_intersections(centerline, max_radius, config.clearance_mm)
        if len(clash) == 0:
            params["attempt"] = attempt
            return _build(config, rng, centerline, base, params, lumen_centerline)
        last = clash
    raise ColonbenchError(
        f"no self-intersection-free colon in {config.max_attempts} attempts (colon {colon_id}, seed {seed}); "
        f"last clash between arc lengths {last[0].round(1).tolist()} mm. Lower the radii or the jitter, "
        "or raise max_attempts.")


# --------------------------------------------------------------------------- centerline
def _centerline(config: ColonConfig, rng: np.random.Generator) -> tuple[Centerline, dict]:
    params = {
        "length_mm": draw(rng, config.length_mm),
        "sag_mm": draw(rng, config.transverse_sag_mm),
        "loop_mm": draw(rng, config.sigmoid_loop_mm),
    }
    for name in ("caecum", "transverse", "sigmoid", "rectum"):
        params[f"radius_{name}_mm"] = draw(rng, getattr(config, f"radius_{name}_mm"))
    params["roughness_mm"] = draw(rng, config.roughness_mm)
    # ranges added in 0.2 draw only when set, so that colons without them stay as they were
    if config.fold_free_share > 0:
        params["fold_free"] = bool(rng.random() < config.fold_free_share)
    if config.ellipticity[1] > 0:
        params["ellipticity"] = draw(rng, config.ellipticity)
    if config.flattening[1] > 0:
        params["flattening"] = draw(rng, config.flattening)

    pts = _TEMPLATE[:, :3].copy()
    region = _TEMPLATE[:, 3].astype(int)
    pts += rng.normal(0.0, config.layout_jitter_mm, pts.shape) * np.array([1.0, 1.0, 0.6])
    # transverse colon hangs down, most in its middle
    tr = np.flatnonzero(region == 3)
    pts[tr, 2] -= params["sag_mm"] * np.sin(np.linspace(0.35, np.pi - 0.35, len(tr)))
    # the sigmoid loop reaches forward and up
    sg = np.flatnonzero(region == 6)
    lift = np.sin(np.linspace(0.0, np.pi, len(sg)))
    pts[sg, 1] += 0.6 * params["loop_mm"] * lift - 20.0 * lift
    pts[sg, 2] += params["loop_mm"] * lift - 40.0 * lift

    chord = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(pts, axis=0), axis=1))])
    spline = CubicSpline(chord, pts, axis=0, bc_type="natural")
    raw = Centerline.from_function(spline, 0.0, chord[-1], spacing=1.0)
    # region of each template point, carried as arc-length fractions
    t = np.linspace(0.0, chord[-1], 20001)
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(spline(t), axis=0), axis=1))])
    knot_frac = np.interp(chord, t, arc) / arc[-1]
    params["region_knots"] = [(float(knot_frac[i]), int(region[i])) for i in range(len(region))]

    target = params["length_mm"]
    points = raw.points * (target / raw.length)
    if config.tortuosity_mm[1] > 0:  # drawn only when set (0.2's colons stay as they were)
        params["tortuosity_mm"] = draw(rng, config.tortuosity_mm)
        params["tortuosity_scale_mm"] = draw(rng, config.tortuosity_scale_mm)
        points = bend_randomly(points, rng, params["tortuosity_mm"], params["tortuosity_scale_mm"])
    for _ in range(4):
        cl = Centerline.from_points(points)
        r = _base_radius(config, params, cl.arclength, length=cl.length)
        r = r * (1.0 + params.get("ellipticity", 0.0)) + _pouch_reach(config)
        points = _limit_curvature(cl, r + 3.0 * params["roughness_mm"] + config.clearance_mm, max_iter=60)
        cl = Centerline.from_points(points)
        points = cl.points * (target / cl.length)
    centerline = Centerline.from_points(points).resample(0.5)
    return centerline, params


def bend_randomly(points: np.ndarray, rng: np.random.Generator, amplitude_mm: float, scale_mm: float) -> np.ndarray:
    """A polyline bent by a smooth random displacement across itself (tortuosity).

    Each coordinate of white noise along the line is Gaussian-filtered with sigma ``scale_mm`` of arc length,
    scaled to a standard deviation of ``amplitude_mm``, and the part along the local tangent is removed, so
    the line turns where the displacement changes and keeps its course on average. Bends tighter than the
    tube allows are smoothed afterwards (:func:`_limit_curvature`), and the self-intersection check applies
    as to any layout.

    Parameters
    ----------
    points : (n, 3) float
        Evenly spaced polyline, mm.
    rng : numpy.random.Generator
    amplitude_mm, scale_mm : float
        Standard deviation of the displacement and its correlation length along the line, mm.

    Returns
    -------
    (n, 3) float
        The bent polyline, mm (its length grows; the caller rescales it).
    """
    seg = np.linalg.norm(np.diff(points, axis=0), axis=1)
    spacing = float(seg.mean())
    noise = gaussian_filter1d(rng.normal(size=points.shape), scale_mm / spacing, axis=0, mode="reflect")
    noise *= amplitude_mm / np.maximum(noise.std(axis=0), 1e-12)
    tangent = np.gradient(points, axis=0)
    tangent /= np.maximum(np.linalg.norm(tangent, axis=1, keepdims=True), 1e-12)
    noise -= (noise * tangent).sum(axis=1, keepdims=True) * tangent
    return points + noise


def _limit_curvature(cl: Centerline, radius: np.ndarray, safety: float = 1.25, max_iter: int = 60):
    """Smooth the polyline locally until every bend radius exceeds ``safety * radius``."""
    pts = cl.points.copy()
    spacing = cl.length / (len(pts) - 1)
    for _ in range(max_iter):
        kappa = Centerline.from_points(pts).curvature()
        bad = kappa * radius * safety > 1.0
        if not bad.any():
            break
        weight = gaussian_filter1d(bad.astype(float), 8.0 / spacing, mode="nearest")
        weight = np.clip(weight / max(weight.max(), 1e-12) * 1.5, 0.0, 1.0)[:, None]
        smooth = gaussian_filter1d(pts, 4.0 / spacing, axis=0, mode="nearest")
        pts = (1.0 - weight) * pts + weight * smooth
    return pts


def _region_of(params: dict, frac: np.ndarray) -> np.ndarray:
    knots = np.array(params["region_knots"])
    idx = np.clip(np.searchsorted(knots[:, 0], frac, side="right") - 1, 0, len(knots) - 1)
    return knots[idx, 1].astype(int)


def _base_radius(config, params, s, length=None) -> np.ndarray:
    """Base lumen radius (mm) at arc lengths ``s`` by anatomical region."""
    length = length if length is not None else s[-1]
    r_c, r_t = params["radius_caecum_mm"], params["radius_transverse_mm"]
    r_s, r_r = params["radius_sigmoid_mm"], params["radius_rectum_mm"]
    # anchor fractions along the colon and their radii
    frac = np.array([0.0, 0.06, 0.16, 0.3, 0.5, 0.62, 0.72, 0.86, 0.93, 1.0])
    rad = np.array([r_c, r_c, 0.5 * (r_c + r_t), r_t, r_t, 0.5 * (r_t + r_s), r_s, r_s, r_r, 0.8 * r_r])
    return PchipInterpolator(frac, rad)(np.clip(np.asarray(s) / length, 0.0, 1.0))


# --------------------------------------------------------------------------- surface
def _build(config: ColonConfig, rng, centerline: Centerline, base: np.ndarray, params: dict,
           lumen_centerline: bool = False) -> Colon:
    L = centerline.length
    n_rings = int(np.ceil(L / config.ring_spacing_mm)) + 1
    s = np.linspace(0.0, L, n_rings)
    rings = Centerline(centerline.point_at(s), s)
    r0 = np.interp(s, centerline.arclength, base)
    n_around = int(np.ceil(2.0 * np.pi * r0.max() / config.edge_mm))
    n_around += n_around % 2
    theta = ring_angles(n_around)
    region = _region_of(params, s / L)

    # three taeniae coli, slowly twisting along the colon
    theta0 = rng.uniform(0, 2 * np.pi)
    twist = rng.uniform(-1.0, 1.0) * 2 * np.pi / 1000.0  # rad / mm
    taenia_angle = theta0 + twist * s                     # (K,) angle of taenia 0
    rel = np.mod(theta[None, :] - taenia_angle[:, None], 2 * np.pi)  # (K, n)
    sector = np.minimum((rel // (2 * np.pi / 3)).astype(int), 2)
    phase = (rel - sector * (2 * np.pi / 3)) / (2 * np.pi / 3)        # 0..1 inside the sector
    dist_taenia = np.minimum(phase, 1 - phase) * (2 * np.pi / 3)      # rad to nearest taenia

    depth_t = np.where(region == 3, draw(rng, config.taenia_depth_transverse), draw(rng, config.taenia_depth))
    depth_t = gaussian_filter1d(depth_t.astype(float), 30.0 / config.ring_spacing_mm, mode="nearest")
    rho = r0[:, None] * (1.0 - depth_t[:, None] * np.exp(-0.5 * (dist_taenia / 0.3) ** 2))

    # haustral folds: each sector has its own series of crescent folds
    fold_weight = gaussian_filter1d(_FOLD_WEIGHT[region], 15.0 / config.ring_spacing_mm, mode="nearest")
    fold_profile = np.zeros((3, n_rings))
    n_folds = 0
    for m in range(0 if params.get("fold_free") else 3):
        pos = rng.uniform(0.0, config.fold_spacing_mm[1])
        while pos < L:
            depth = draw(rng, config.fold_depth)
            width = draw(rng, config.fold_width_mm)
            lo, hi = np.searchsorted(s, [pos - 5 * width, pos + 5 * width])
            fold_profile[m, lo:hi] = np.maximum(
                fold_profile[m, lo:hi], depth * np.exp(-0.5 * ((s[lo:hi] - pos) / width) ** 2))
            n_folds += 1
            pos += draw(rng, config.fold_spacing_mm)
    crescent = np.sin(np.pi * phase) ** 0.6
    fold = np.take_along_axis(fold_profile.T, sector, axis=1) * crescent * fold_weight[:, None]
    rho -= r0[:, None] * fold

    # sessile polyps bulging into the lumen
    polyps = []
    margin = min(30.0, 0.1 * L)
    for _ in range(draw(rng, config.polyps, integer=True)):
        s_p = rng.uniform(margin, L - margin)
        th_p = rng.uniform(0, 2 * np.pi)
        size = draw(rng, config.polyp_size_mm)
        height = size * rng.uniform(0.35, 0.6)
        k = int(np.argmin(np.abs(s - s_p)))
        d_arc = np.mod(theta - th_p + np.pi, 2 * np.pi) - np.pi
        dist2 = (s[:, None] - s_p) ** 2 + (rho[k][None, :] * d_arc[None, :]) ** 2
        rho -= height * np.exp(-0.5 * dist2 / (size / 2.5) ** 2)
        polyps.append({"arclength_mm": float(s_p), "angle_rad": float(th_p), "diameter_mm": float(size),
                       "height_mm": float(height)})

    # elliptic and flattened cross-sections, turning slowly along the colon
    if params.get("ellipticity", 0.0) > 0 or params.get("flattening", 0.0) > 0:
        rho *= cross_section_shape(rng, theta, s, params.get("ellipticity", 0.0), params.get("flattening", 0.0))

    # smooth roughness
    if params["roughness_mm"] > 0:
        noise = rng.standard_normal(rho.shape)
        sigma = (2.5 / config.ring_spacing_mm, 2.5 / (2 * np.pi * r0.mean() / n_around))
        noise = gaussian_filter(noise, sigma, mode=("nearest", "wrap"))
        rho += params["roughness_mm"] * noise / max(noise.std(), 1e-12)
    rho = np.maximum(rho, 0.3 * r0[:, None])

    frames = rings.frames()
    mesh = sweep(rings, rho, frames)
    for p in polyps:
        k = int(np.argmin(np.abs(s - p["arclength_mm"])))
        j = int(np.round(p["angle_rad"] / (2 * np.pi) * n_around)) % n_around
        p["position_mm"] = mesh.vertices[k * n_around + j].tolist()
    max_radius = np.interp(centerline.arclength, s, rho.max(axis=1))
    irregular = {}
    if config.diverticula[1] > 0 or config.pedunculated_polyps[1] > 0:
        # drawn from a stream split off only here, so colons without them stay as they were
        extra = np.random.default_rng(rng.integers(2**63))
        mesh, irregular = _irregularities(config, extra, mesh, rings, n_around, margin)
        max_radius = max_radius + _pouch_reach(config)

    region_bounds = {}
    for code, name in enumerate(REGIONS):
        where = s[region == code]
        if len(where):
            region_bounds[name] = [float(where.min()), float(where.max())]
    info = {k: v for k, v in params.items() if k != "region_knots"}
    info.update(n_folds=n_folds, polyps=polyps, regions=region_bounds, n_around=n_around,
                ring_spacing_mm=float(s[1] - s[0]), **irregular)
    if lumen_centerline:
        ring_points = lumen_centred_line(rings, frames, rho, theta)
        offset = np.linalg.norm(ring_points - rings.points, axis=1)
        raw = Centerline.from_points(ring_points)
        centerline = raw.resample(0.5)
        max_radius = np.interp(centerline.arclength, raw.arclength, rho.max(axis=1) + offset)
        if irregular:
            max_radius = max_radius + _pouch_reach(config)
        info.update(centerline="lumen-centred", centerline_offset_median_mm=float(np.median(offset)),
                    centerline_offset_max_mm=float(offset.max()))
    swept = not irregular  # after CSG the vertices no longer lie on rings
    return Colon(mesh=mesh, centerline=centerline, radius=max_radius, ring_arclength=s if swept else None,
                 n_around=n_around if swept else None, info=info)


def lumen_centred_line(rings: Centerline, frames, rho: np.ndarray, theta: np.ndarray,
                       every_mm: float = 2.0) -> np.ndarray:
    """The centre of the lumen at each ring of a swept tube, mm; (K, 3).

    Each ring is the tube's cross-section square to its axis; its centre is the
    centroid of its core (:func:`colonbench.datagen.lumen_midline.outline_core_centre`),
    the definition imported colons are re-centred by. Sections are taken every
    ``every_mm``, interpolated between, and their offsets from the axis are
    median-filtered and smoothed along it as in
    :func:`colonbench.datagen.lumen_midline.recentre` (a fold or a polyp moves one
    section's core, not the line), and kept within half the ring's smallest radius.

    Parameters
    ----------
    rings : Centerline
        The K ring centres (the axis), mm.
    frames : tuple of (K, 3) arrays
        ``(tangent, normal, binormal)`` the tube was swept with.
    rho : (K, n) float
        Distance of each ring vertex from its centre, mm.
    theta : (n,) float
        The ring vertices' angles, rad.
    every_mm : float
        Spacing of the sections, mm.
    """
    from colonbench.datagen.lumen_midline import SMOOTH_MM, outline_core_centre, smooth_along

    s = rings.arclength
    spacing = s[1] - s[0]
    step = max(1, int(round(every_mm / max(spacing, 1e-9))))
    picks = np.unique(np.r_[np.arange(0, len(s), step), len(s) - 1])
    cos, sin = np.cos(theta), np.sin(theta)
    centres = np.array([outline_core_centre(np.c_[rho[k] * cos, rho[k] * sin]) for k in picks])
    offset = np.stack([np.interp(s, s[picks], centres[:, i]) for i in range(2)], axis=1)
    offset = smooth_along(offset, spacing, 5 * every_mm, SMOOTH_MM)
    norm = np.linalg.norm(offset, axis=1)
    offset *= np.minimum(1.0, 0.5 * rho.min(axis=1) / np.maximum(norm, 1e-12))[:, None]
    _, nrm, bnm = frames
    return rings.points + offset[:, :1] * nrm + offset[:, 1:] * bnm


def _pouch_reach(config: ColonConfig) -> float:
    """How far a diverticulum can reach beyond the wall, mm (0 without diverticula)."""
    if config.diverticula[1] == 0:
        return 0.0
    return config.diverticulum_radius_mm[1] * (1.0 + config.diverticulum_neck[1])


def _irregularities(config: ColonConfig, rng, mesh, rings: Centerline, n_around: int, margin: float):
    """Diverticula and pedunculated polyps at random places of the wall (:mod:`colonbench.datagen.irregular`)."""
    from colonbench.datagen import irregular

    s = rings.arclength
    V = mesh.vertices

    def wall_point():
        k = int(np.clip(np.searchsorted(s, rng.uniform(margin, s[-1] - margin)), 0, len(s) - 1))
        j = int(rng.integers(n_around))
        p = V[k * n_around + j]
        normal = p - rings.points[k]
        return p, normal / np.linalg.norm(normal), float(s[k])

    pouches, stalked, info = [], [], {"diverticula": [], "pedunculated_polyps": []}
    for _ in range(draw(rng, config.diverticula, integer=True)):
        p, n, at = wall_point()
        r, neck = draw(rng, config.diverticulum_radius_mm), draw(rng, config.diverticulum_neck)
        pouches.append((p, n, r, neck))
        info["diverticula"].append({"arclength_mm": at, "radius_mm": r, "neck": neck, "position_mm": p.tolist()})
    for _ in range(draw(rng, config.pedunculated_polyps, integer=True)):
        p, n, at = wall_point()
        head, stalk = draw(rng, config.polyp_head_mm), draw(rng, config.polyp_stalk_mm)
        stalk_radius = max(0.5, rng.uniform(0.15, 0.3) * head)
        stalked.append((p, n, head / 2.0, stalk, stalk_radius))
        info["pedunculated_polyps"].append({"arclength_mm": at, "head_mm": head, "stalk_mm": stalk,
                                            "stalk_radius_mm": stalk_radius, "position_mm": p.tolist()})
    if not pouches and not stalked:
        return mesh, info
    ends = rings.point_at([0.0, rings.length])
    tangents = rings.tangent_at([0.0, rings.length])
    return irregular.apply(V, mesh.faces, n_around, ends, tangents, pouches, stalked), info


def cross_section_shape(rng, theta: np.ndarray, s: np.ndarray, ellipticity: float, flattening: float) -> np.ndarray:
    """Radius factors of an elliptic, partly flattened cross-section; (K, n).

    The ellipse has semi-axes ``1 + e`` and ``1 - e`` (times the local radius);
    flattening presses one side onto the chord at ``1 - f`` from the axis. Both
    orientations turn by a drawn rate of up to one turn per metre.

    Parameters
    ----------
    rng : numpy.random.Generator
    theta : (n,) float
        Ring angles, rad.
    s : (K,) float
        Ring arc lengths, mm.
    ellipticity, flattening : float
    """
    phase = rng.uniform(0, 2 * np.pi) + rng.uniform(-1.0, 1.0) * 2 * np.pi / 1000.0 * s[:, None]
    rel = theta[None, :] - phase
    a, b = 1.0 + ellipticity, 1.0 - ellipticity
    factor = a * b / np.sqrt((b * np.cos(rel)) ** 2 + (a * np.sin(rel)) ** 2)
    if flattening > 0:
        c = np.cos(rel - rng.uniform(0, 2 * np.pi))
        with np.errstate(divide="ignore"):
            chord = np.where(c > 1e-9, (1.0 - flattening) / np.maximum(c, 1e-9), np.inf)
        factor = np.minimum(factor, chord)
    return factor


def tube_colon(centerline: Centerline, radius, ring_spacing_mm: float = 0.5, n_around: int = 256) -> Colon:
    """A simple tube around any centerline, for shapes with known answers.

    Parameters
    ----------
    centerline : Centerline
    radius : float or callable
        Constant radius (mm), or ``radius(s, theta)`` taking (K, 1) arc lengths
        and (1, n) angles and returning (K, n) radii in mm.
    ring_spacing_mm : float
        Distance between rings along the centerline.
    n_around : int
        Vertices per ring.

    Returns
    -------
    Colon
        Vertex ``k * n_around + j`` lies at arc length ``ring_arclength[k]`` and
        angle ``2 pi j / n_around`` from the rotation-minimising normal.
    """
    n_rings = int(np.ceil(centerline.length / ring_spacing_mm)) + 1
    s = np.linspace(0.0, centerline.length, n_rings)
    rings = Centerline(centerline.point_at(s), s)
    theta = ring_angles(n_around)
    if callable(radius):
        rho = np.broadcast_to(np.asarray(radius(s[:, None], theta[None, :]), float), (n_rings, n_around))
    else:
        rho = np.full((n_rings, n_around), float(radius))
    mesh = sweep(rings, rho)
    return Colon(mesh=mesh, centerline=centerline, radius=np.interp(centerline.arclength, s, rho.max(axis=1)),
                 ring_arclength=s, n_around=n_around, info={"kind": "tube"})
