"""What colonoscopy sees of a real colon mesh: its lumen surface, remeshed, and a centerline in the lumen's middle.

Real colon meshes (CT segmentations, anatomical atlases) come with flaws that a
segment cut from them must not carry into the ground truth:

- the wall drawn as a shell (an inner, lumen surface and an outer one that no
  camera sees);
- overlapping or duplicated pieces, which would count their area twice;
- coarse triangles (edges of several mm), far from the 1 mm the sampling and
  the hole masks assume;
- small gaps between pieces;
- a hand-guided midline that runs off-centre and jagged, and stretches where
  the lumen has collapsed.

:func:`extract_lumen` solves the first four at once with one volumetric step:
the mesh is rasterised as walls on a voxel grid, gaps narrower than
``close_mm`` are closed, the free space that holds the midline is the lumen
cavity (flood fill; the exterior, which reaches the grid border, is never
taken), and the cavity's boundary is the new surface (marching cubes on the
cavity, its facing wall voxels at one half, smoothed by a Gaussian of one
voxel, so it follows the wall to a fraction of a voxel). The result is one closed surface with faces of about
one voxel, whatever pieces, shells and duplicates the input had.

:func:`colonbench.datagen.lumen_midline.recentre` moves the midline to the centroids of the lumen's cross
sections and measures each cross-section's equivalent radius; stretches
narrower than ``min_radius_mm`` are collapsed and reported, so that no
segment is cut there.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import trimesh
from scipy import ndimage

from colonbench.datagen.lumen_midline import MAX_RADIUS_MM, MIN_RADIUS_MM, collapsed_intervals, recentre
from colonbench.errors import InputError
from colonbench.polyline import Centerline, perpendicular_basis

#: Voxel edge of the lumen grid, mm (the faces of the new surface are about this size).
LUMEN_VOXEL_MM = 1.0
#: Gaps in the wall narrower than this are closed before the flood fill, mm.
CLOSE_MM = 2.0
#: Where holes let the flood fill out, the lumen is sealed into chambers this long along the midline, mm...
CHAMBER_MM = 60.0
#: ... and this far from each end of the midline, mm.
END_SEAL_MM = 20.0


@dataclass
class Lumen:
    """The lumen of a real colon.

    Attributes
    ----------
    mesh : trimesh.Trimesh
        Closed lumen surface, mm, normals out of the lumen.
    centerline : Centerline
        Re-centred centerline, 0.5 mm spacing, mm.
    radius : (n,) float
        Equivalent radius sqrt(area / pi) of the cross-section at each
        centerline point, mm (0 where collapsed).
    collapsed : list of (float, float)
        Arc-length intervals (mm, along ``centerline``) where the lumen is
        narrower than the minimum radius or missing.
    info : dict
        What was done, JSON-friendly.
    """

    mesh: trimesh.Trimesh
    centerline: Centerline
    radius: np.ndarray
    collapsed: list
    info: dict


def _wall_voxels(mesh: trimesh.Trimesh, origin: np.ndarray, shape, voxel: float) -> np.ndarray:
    """Voxels the surface passes through (points on every triangle no farther apart than half a voxel)."""
    from colonbench.heatmaps import triangle_lattice

    v = (np.asarray(mesh.vertices, float) - origin) / voxel
    f = np.asarray(mesh.faces, np.int64)
    wall = np.zeros(shape, bool)
    for chunk in np.array_split(np.arange(len(f)), max(1, len(f) // 20000)):
        pts = triangle_lattice(v[f[chunk, 0]], v[f[chunk, 1]], v[f[chunk, 2]], 0.5)
        idx = np.clip(np.rint(pts).astype(np.int64), 0, np.array(shape) - 1)
        wall[idx[:, 0], idx[:, 1], idx[:, 2]] = True
    return wall


def extract_lumen(mesh: trimesh.Trimesh, midline, voxel_mm: float = LUMEN_VOXEL_MM, close_mm: float = CLOSE_MM,
                  max_radius_mm: float = MAX_RADIUS_MM) -> tuple[trimesh.Trimesh, np.ndarray, np.ndarray, float]:
    """The lumen surface a camera inside the colon sees, as one closed mesh with faces of about ``voxel_mm``.

    Parameters
    ----------
    mesh : trimesh.Trimesh
        The colon as drawn: any number of pieces, a shell, duplicates, mm.
    midline : (m, 3) float
        A path inside the lumen (an atlas midline; it may graze the wall), mm.
    voxel_mm : float
        Voxel edge of the rasterisation.
    close_mm : float
        Gaps in the wall narrower than about twice this are closed.
    max_radius_mm : float
        Cross-sections are searched this far from the midline. When the
        space around the midline is not enclosed (an open end, holes in the
        wall wider than the closing), the lumen is sealed by its own
        cross-sections every :data:`CHAMBER_MM` along the midline (and
        :data:`END_SEAL_MM` from its ends); the chambers that are enclosed
        are kept, with the seals between two kept chambers removed again,
        and the others are reported as open.

    Returns
    -------
    surface : trimesh.Trimesh
        Closed lumen surface, normals out of the lumen.
    cavity : (X, Y, Z) bool
        The lumen's voxels.
    origin : (3,) float
        Centre of voxel (0, 0, 0), mm.
    voxel : float
        Voxel edge, mm.
    open : ((m, 3) float, (m,) bool)
        The midline's points (resampled at ``voxel_mm``) and whether each
        lies outside the enclosed lumen (in a chamber open to the outside,
        or in the wall).

    Raises
    ------
    InputError
        When no part of the midline lies in an enclosed cavity (the wall is
        open wider than ``close_mm``, or the midline lies outside the mesh).
    """
    from skimage.measure import marching_cubes

    import edt

    mid = Centerline.from_points(np.asarray(midline, float)).resample(voxel_mm)
    pad = 3 + int(np.ceil(close_mm / voxel_mm))
    lo = np.minimum(mesh.bounds[0], mid.points.min(axis=0)) - pad * voxel_mm
    hi = np.maximum(mesh.bounds[1], mid.points.max(axis=0)) + pad * voxel_mm
    shape = tuple(np.ceil((hi - lo) / voxel_mm).astype(int) + 1)
    wall = _wall_voxels(mesh, lo, shape, voxel_mm)
    # close narrow gaps: the free space is taken at least close_mm away from any wall voxel
    dist_wall = edt.edt(~wall, anisotropy=(voxel_mm,) * 3, black_border=False, parallel=2)
    free = dist_wall > close_mm
    seeds = np.clip(np.rint((mid.points - lo) / voxel_mm).astype(int), 0, np.array(shape) - 1)
    keep, label, border = _enclosed(free, seeds)
    seed_labels = label[seeds[:, 0], seeds[:, 1], seeds[:, 2]]
    if np.isin(seed_labels, keep).mean() < 0.95:
        # holes in the wall let the fill out: seal the lumen with its own cross-sections into chambers along
        # the midline, keep the enclosed chambers, and put back the seals between two kept ones
        sealed = free.copy()
        cuts = np.unique(np.clip(np.concatenate([np.arange(END_SEAL_MM, mid.length - END_SEAL_MM, CHAMBER_MM),
                                                 [mid.length - END_SEAL_MM]]), 0.0, mid.length))
        for s_cap in cuts:
            _seal(sealed, free, lo, voxel_mm, mid, s_cap, max_radius_mm)
        keep, label, border = _enclosed(sealed, seeds)
        core = np.isin(label, keep)
        other = sealed & ~core
        seal = free & ~sealed
        core |= (seal & ndimage.binary_dilation(core, iterations=2)
                 & ~ndimage.binary_dilation(other, iterations=3))
    else:
        core = np.isin(label, keep)
    open_points = ~core[seeds[:, 0], seeds[:, 1], seeds[:, 2]]
    if open_points.all():
        leaked = np.isin(seed_labels, border[border > 0]).mean()
        raise InputError(
            "no enclosed lumen holds the midline: "
            + (f"{leaked:.0%} of the midline lies in space that reaches outside the mesh (is the wall open wider "
               f"than {2 * close_mm:g} mm? raise close_mm)" if leaked > 0 else
               "the midline lies in the wall or outside the mesh"))
    # grow the closed-off core back to the wall
    dist_core = edt.edt(~core, anisotropy=(voxel_mm,) * 3, black_border=False, parallel=2)
    cavity = (dist_core <= close_mm + 0.5 * voxel_mm) & ~wall
    # the wall voxels that face the cavity count half: the 0.5 level then runs through their centres, on the
    # wall, rather than half a voxel inside it
    facing = wall & ndimage.binary_dilation(cavity)
    field = ndimage.gaussian_filter(cavity.astype(np.float32) + 0.5 * facing, 1.0)
    verts, faces, _, _ = marching_cubes(field, level=0.5, allow_degenerate=False)
    surface = trimesh.Trimesh(verts * voxel_mm + lo, faces, process=False)
    if surface.volume < 0:  # normals out of the lumen
        surface.invert()
    return surface, cavity, lo, voxel_mm, (mid.points, open_points)


def _enclosed(free: np.ndarray, seeds: np.ndarray):
    """Labels of the pieces of free space that hold at least 1 % of the seeds and do not reach the border."""
    label, n = ndimage.label(free)
    if n == 0 or len(seeds) == 0:
        return np.zeros(0, int), label, np.zeros(0, int)
    seed_labels = label[seeds[:, 0], seeds[:, 1], seeds[:, 2]]
    border = np.unique(np.concatenate([label[0].ravel(), label[-1].ravel(), label[:, 0].ravel(),
                                       label[:, -1].ravel(), label[:, :, 0].ravel(), label[:, :, -1].ravel()]))
    counts = np.bincount(seed_labels, minlength=n + 1)
    counts[0] = 0
    counts[border] = 0
    return np.flatnonzero(counts >= max(5, 0.01 * len(seeds))), label, border


def _seal(sealed: np.ndarray, free: np.ndarray, origin, voxel: float, line: Centerline, s: float,
          max_radius_mm: float) -> None:
    """Block, in ``sealed``, the lumen's cross-section (the piece of ``free`` around the line) at arc length ``s``."""
    if s <= 0 or s >= line.length:
        return
    u, v = perpendicular_basis(line.tangent_at([s]))
    r = np.arange(-max_radius_mm, max_radius_mm + voxel / 4, voxel / 2)
    U, V = np.meshgrid(r, r, indexing="ij")
    plane = line.point_at([s])[0] + U[..., None] * u[0] + V[..., None] * v[0]
    limit = np.array(free.shape) - 1
    idx = np.clip(np.rint((plane - origin) / voxel).astype(int), 0, limit)
    inside = free[idx[..., 0], idx[..., 1], idx[..., 2]]
    lab, _ = ndimage.label(inside)
    mid = len(r) // 2
    if not lab[mid, mid]:
        return
    sel = idx[lab == lab[mid, mid]]
    for off in ((0, 0, 0), (1, 0, 0), (-1, 0, 0), (0, 1, 0), (0, -1, 0), (0, 0, 1), (0, 0, -1)):
        q = np.clip(sel + off, 0, limit)
        sealed[q[:, 0], q[:, 1], q[:, 2]] = False


def _merge(intervals: list) -> list:
    """Overlapping intervals joined, sorted."""
    out = []
    for a, b in sorted(intervals):
        if out and a <= out[-1][1]:
            out[-1] = (out[-1][0], max(out[-1][1], b))
        else:
            out.append((a, b))
    return out


def import_lumen(mesh: trimesh.Trimesh, midline, voxel_mm: float = LUMEN_VOXEL_MM, close_mm: float = CLOSE_MM,
                 min_radius_mm: float = MIN_RADIUS_MM, max_radius_mm: float = MAX_RADIUS_MM) -> Lumen:
    """The lumen surface and a re-centred centerline of a real colon mesh (see the module's description).

    Parameters
    ----------
    mesh : trimesh.Trimesh
        The colon as drawn, mm.
    midline : (m, 3) float
        A rough path through the lumen, caecum to rectum, mm.
    voxel_mm, close_mm, max_radius_mm
        See :func:`extract_lumen`.
    min_radius_mm : float
        Narrower cross-sections are collapsed.
    """
    surface, cavity, origin, voxel, (mid_points, open_points) = extract_lumen(mesh, midline, voxel_mm, close_mm,
                                                                             max_radius_mm)
    line, radius, collapsed = recentre(cavity, origin, voxel, midline, min_radius_mm=min_radius_mm,
                                       max_radius_mm=max_radius_mm)
    # stretches open to the outside (holes in the wall, open ends) are never cut into segments
    from scipy.spatial import cKDTree

    _, nearest = cKDTree(mid_points).query(line.points)
    collapsed = _merge(collapsed + collapsed_intervals(line.arclength, open_points[nearest]))
    info = {"input_faces": int(len(mesh.faces)), "input_area_mm2": float(mesh.area),
            "lumen_faces": int(len(surface.faces)), "lumen_area_mm2": float(surface.area),
            "voxel_mm": float(voxel), "close_mm": float(close_mm), "min_radius_mm": float(min_radius_mm),
            "open_share": float(open_points.mean()),
            "centerline_mm": float(line.length), "median_radius_mm": float(np.median(radius[radius > 0]))
            if (radius > 0).any() else 0.0,
            "collapsed_mm": [list(c) for c in collapsed],
            "collapsed_length_mm": float(sum(b - a for a, b in collapsed))}
    return Lumen(surface, line, radius, collapsed, info)
