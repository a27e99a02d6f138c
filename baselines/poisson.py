"""A training-free classical baseline: screened Poisson surface reconstruction in place of the network.

The ``poisson`` method completes the partial surface without learning, then runs the same steps after the
surface as the completion method (:func:`colonbench.completion.method.from_heatmap`: end planes at the cut
rims, holes by the steps' distance rule, wall gaps, coverage as observed over total area), so that its row
against ``completion`` measures what the network adds and nothing else. In voxel units of the cloud's own
fitted grid (the one the network would see):

1. normals from the 16 nearest points (open3d), oriented toward the tube's axis: the wall is seen from
   inside (:func:`oriented_normals`);
2. screened Poisson reconstruction (open3d, octree depth :data:`DEPTH`, one thread: it is deterministic
   only on one) (:func:`poisson_surface`);
3. what Poisson invents far from the data is dropped: faces with a vertex farther than :data:`FAR_VOXELS`
   from every point. The tube's wall is put back where it is then missing by the steps' wall gaps (hole
   patches at the wall distance of the station's other rays, on every ray that meets no kept surface:
   :data:`GAP_VALLEY`), which is the one tube prior;
4. the lumen: the voxels the whole reconstructed wall encloses in a cross-section along one of the grid's
   axes, less those nearer to the dropped surface than to the kept one (inside the caps over the tube's open
   ends), and its centerline by the paper's extractor on the lumen's normalised distance to the kept surface
   (:func:`lumen_centerline`); where the wall encloses no lumen (a wall seen from one side), the centres of
   circles fitted to the points across the tube (:func:`middle_line`);
5. the target heatmap of the kept surface and the centerline, and the steps after the network on it.

Choices and their measurements: docs/decisions/0139-poisson-reference.md.
"""

from __future__ import annotations

import time

import numpy as np
from scipy import ndimage
from scipy.spatial import cKDTree

from colonbench.completion.heatmap_centerline import END_LEVEL, extract_centerline
from colonbench.completion.method import from_heatmap, method_cloud
from colonbench.completion.steps import STEPS_VERSION
from colonbench.errors import InputError
from colonbench.estimate import Estimate
from colonbench.grid import Grid, fit_grid
from colonbench.heatmaps import distance_to, target_heatmap, voxelize_mesh, voxelize_polyline

#: Revision of this method's own steps (1-5 above), part of its version: 1 the first, 2 the lumen without the
#: caps, fitted circles' centres where the wall encloses no lumen (1 gave no estimate there) and hole wall on
#: every ray that meets no kept surface.
POISSON_VERSION = "2"
#: The grid the cloud is placed in: the shipped network's (``grid_options`` of its model), so that the
#: steps after the surface run at the same voxel size.
GRID_OPTIONS = {"size": 64, "margin": 4, "min_extent_mm": 70.0, "axes": "tube"}
#: Neighbours a point's normal is estimated from.
NORMAL_NEIGHBOURS = 16
#: Normals are oriented toward the middle of the points' cross-section in stations this long along the
#: grid's first axis (the tube's), voxels.
STATION_VOXELS = 4.0
#: Octree depth of the Poisson solve: 2^6 cells across the cloud's box are about a voxel each.
DEPTH = 6
#: The Poisson box is the points' box times this.
SCALE = 1.1
#: Faces of the Poisson surface with a vertex farther than this from every point are dropped, voxels.
FAR_VOXELS = 3.0
#: The steps' wall gaps (:func:`colonbench.completion.gaps.wall_gaps`) put hole wall on every ray across the line
#: that meets no kept surface: a reconstruction has no faint wall, so the network's valley test (a ray whose
#: heatmap falls below 0.4) does not apply, and with it a wall seen from one side got no wall put back at all.
GAP_VALLEY = np.inf
#: The lumen's distance to the wall is normalised by its largest value within a box this wide, voxels
#: (about a colon's diameter): 1 on the lumen's medial axis, 0 on the wall, as the target heatmap is.
LUMEN_WINDOW = 15


def _stations(points: np.ndarray, station: float) -> tuple[list, np.ndarray]:
    """Per station along the first axis, in order, the points within a station of it; and each point's station."""
    stations = np.round(points[:, 0] / station).astype(int)
    keys, of_point = np.unique(stations, return_inverse=True)
    return [points[np.abs(stations - s) <= 1] for s in keys], of_point


def _box_middles(groups: list) -> np.ndarray:
    """(k, 3) centres of the boxes of k groups of points."""
    return np.array([(g.min(axis=0) + g.max(axis=0)) / 2 for g in groups])


def station_middles(points: np.ndarray, station: float = STATION_VOXELS) -> tuple[np.ndarray, np.ndarray]:
    """The middle of a partial tube's cross-section in stations along the grid's first axis.

    Parameters
    ----------
    points : (n, 3) float
        The cloud in voxels of its grid, the tube along the first axis.
    station : float
        Station length along the first axis, voxels.

    Returns
    -------
    middles : (k, 3) float
        Per station, in order along the first axis, the centre of the box of the points within a station of
        it, voxels. A wall seen from one side keeps that centre on its inner side, where a centroid or a fitted
        circle could fall outside it. On a segment bent back on itself (a U-turn across the first axis) a
        station holds both arms and its middle lies between them, outside both lumens.
    of_point : (n,) int
        The station (row of ``middles``) of each point.
    """
    groups, of_point = _stations(points, station)
    return _box_middles(groups), of_point


def oriented_normals(points: np.ndarray, neighbours: int = NORMAL_NEIGHBOURS,
                     station: float = STATION_VOXELS) -> np.ndarray:
    """Unit normals of a partial tube's points, pointing into the lumen.

    Parameters
    ----------
    points : (n, 3) float
        The cloud in voxels of its grid, the tube along the first axis.
    neighbours : int
        Points each normal is fitted to (open3d's PCA normal).
    station : float
        The normals point toward the :func:`station_middles` of stations this long, across the first axis,
        voxels.

    Returns
    -------
    (n, 3) float
    """
    import open3d as o3d

    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
    pcd.estimate_normals(o3d.geometry.KDTreeSearchParamKNN(int(neighbours)))
    normals = np.asarray(pcd.normals).copy()
    middles, of_point = station_middles(points, station)
    inward = middles[of_point] - points
    inward[:, 0] = 0.0
    normals[(normals * inward).sum(axis=1) < 0] *= -1.0
    return normals


def poisson_surface(points: np.ndarray, normals: np.ndarray, depth: int = DEPTH,
                    scale: float = SCALE) -> tuple[np.ndarray, np.ndarray]:
    """Screened Poisson reconstruction of oriented points (open3d, one thread); (vertices, faces).

    Parameters
    ----------
    points, normals : (n, 3) float
        Points (voxels) and their unit normals.
    depth : int
        Octree depth.
    scale : float
        The reconstruction's box over the points' box.

    Returns
    -------
    vertices : (v, 3) float
        In the points' unit.
    faces : (f, 3) int
    """
    import open3d as o3d

    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
    pcd.normals = o3d.utility.Vector3dVector(normals)
    mesh, _ = o3d.geometry.TriangleMesh.create_from_point_cloud_poisson(pcd, depth=int(depth), scale=float(scale),
                                                                       n_threads=1)
    return np.asarray(mesh.vertices, dtype=float), np.asarray(mesh.triangles, dtype=np.int64)


def enclosed(wall: np.ndarray) -> np.ndarray:
    """(S, S, S) bool: voxels off ``wall`` that it encloses in a cross-section along one of the grid's axes.

    A tube's open ends leave its lumen connected to the outside in 3-D; a section across the tube is a
    closed loop whichever way the tube bends, while a section along it is open at the ends.
    """
    inside = np.zeros_like(wall)
    for axis in range(3):
        w = np.moveaxis(wall, axis, 0)
        filled = np.stack([ndimage.binary_fill_holes(s) for s in w])
        inside |= np.moveaxis(filled, 0, axis)
    return inside & ~wall


def lumen_centerline(wall: np.ndarray, kept_distance: np.ndarray | None = None, window: int = LUMEN_WINDOW,
                     end_level: float | None = END_LEVEL, dropped: np.ndarray | None = None) -> np.ndarray:
    """The centerline of the lumen a reconstructed wall encloses, voxels.

    Parameters
    ----------
    wall : (S, S, S) bool
        Voxels the whole reconstructed surface passes through: it bounds the lumen.
    kept_distance : (S, S, S) float, optional
        Distance to the voxels of the surface kept near the data (:func:`colonbench.heatmaps.distance_to`;
        default: to ``wall``), voxels: the lumen's distance is measured to that surface, so that the caps
        Poisson closes a tube's open ends with, far from any point, do not pull the line's ends in.
    window : int
        :data:`LUMEN_WINDOW`.
    end_level : float or None
        The extractor's end level (its ends moved to the far ends of the lumen's core); None keeps the ends of
        its ridge.
    dropped : (S, S, S) bool, optional
        Voxels of the surface dropped as invented: lumen voxels nearer to it than to the kept surface (inside
        the caps over a tube's open ends) are left out.

    Returns
    -------
    (m, 3) float
        :func:`colonbench.completion.heatmap_centerline.extract_centerline` of the lumen's distance to the
        kept surface divided by its largest value nearby; empty when the wall encloses nothing.
    """
    lumen = enclosed(ndimage.binary_closing(wall) | wall)
    if not lumen.any():
        return np.zeros((0, 3))
    d_kept = distance_to(wall) if kept_distance is None else kept_distance
    if dropped is not None and dropped.any():
        lumen &= d_kept <= distance_to(dropped)
    d = np.where(lumen, d_kept, 0.0)
    h = np.where(lumen, d / np.maximum(ndimage.maximum_filter(d, size=window), 1e-6), 0.0)
    return extract_centerline(h.astype(np.float32), end_level=end_level)


def middle_line(points: np.ndarray, station: float = STATION_VOXELS) -> np.ndarray:
    """A line for a partial tube whose wall encloses no lumen: the centres of circles fitted across it, voxels.

    Per station along the grid's first axis, a least-squares circle (Kasa's algebraic fit) through the points
    within a station of it, projected across the axis: on a wall seen from one side, an arc, its centre is the
    tube's axis, where the middle of the points' box (:func:`station_middles`) lies on the arc's chord and
    makes the completed tube too small. A fit whose radius exceeds the grid, or that has too few points, gives
    way to that middle. The centres are smoothed over three stations.

    Parameters
    ----------
    points : (n, 3) float
        The cloud in voxels of its grid, the tube along the first axis.
    station : float
        Station length, voxels.

    Returns
    -------
    (k, 3) float
        One point per station, in order along the first axis; fewer than two when the cloud spans one station.
    """
    groups, _ = _stations(points, station)
    limit = np.ptp(points, axis=0).max() + 1.0
    centres = _box_middles(groups)
    for row, near in enumerate(groups):
        across = near[:, 1:]
        if len(across) < 10:
            continue
        a = np.c_[2.0 * across, np.ones(len(across))]
        (cy, cz, c), *_ = np.linalg.lstsq(a, (across ** 2).sum(axis=1), rcond=None)
        radius = np.sqrt(max(c + cy ** 2 + cz ** 2, 0.0))
        if 0 < radius < limit:
            centres[row, 1:] = (cy, cz)
    if len(centres) < 3:
        return centres
    return ndimage.uniform_filter1d(centres, size=3, axis=0, mode="nearest")


def poisson_heatmap(points_vox: np.ndarray, size: int, depth: int = DEPTH, far: float = FAR_VOXELS,
                    end_level: float | None = END_LEVEL, line: str = "lumen") -> tuple[np.ndarray, np.ndarray]:
    """The target heatmap of a cloud's Poisson surface and its lumen's centerline (steps 1-5 above).

    Parameters
    ----------
    points_vox : (n, 3) float
        The partial cloud in voxels of its grid.
    size : int
        The grid's side, voxels.
    depth : int
        :data:`DEPTH`.
    far : float
        :data:`FAR_VOXELS`.
    end_level : float or None
        :func:`lumen_centerline`'s.
    line : {"lumen", "circles"}
        :class:`PoissonMethod`'s.

    Returns
    -------
    heatmap : (S, S, S) float32
        ``t_S / (t_S + t_C)`` of the kept surface and the centerline (:func:`colonbench.heatmaps.target_heatmap`).
    centerline : (m, 3) float
        The lumen's (:func:`lumen_centerline`), or where the surface encloses none the centres of circles
        fitted across the tube (:func:`middle_line`), voxels; empty when Poisson kept no surface near the data.
    """
    vertices, faces = poisson_surface(points_vox, oriented_normals(points_vox), depth)
    box = Grid(np.eye(4), size)     # voxel indices are the coordinates
    wall, _ = voxelize_mesh(box, vertices, faces)
    near, _ = cKDTree(points_vox).query(vertices, distance_upper_bound=far * 1.0001)
    close = (near[faces] <= far).all(axis=1)
    kept, _ = voxelize_mesh(box, vertices, faces[close])
    if not kept.any():
        return np.full(kept.shape, 0.5, np.float32), np.zeros((0, 3))
    d_kept = distance_to(kept)
    dropped, _ = voxelize_mesh(box, vertices, faces[~close])
    centerline = lumen_centerline(wall, d_kept, end_level=end_level, dropped=dropped) if line == "lumen" else []
    if len(centerline) < 2:      # the wall encloses no lumen (a wall seen from one side): fitted circles' centres
        centerline = middle_line(points_vox)
    if len(centerline) < 2:
        return np.full(kept.shape, 0.5, np.float32), np.zeros((0, 3))
    line, _ = voxelize_polyline(box, centerline)
    return target_heatmap(d_kept, distance_to(line)).astype(np.float32), centerline


class PoissonMethod:
    """The ``poisson`` method: screened Poisson reconstruction and the completion method's later steps.

    A method row of the benchmark, not a reference row: it is given nothing but the cloud.

    Parameters
    ----------
    depth : int
        Octree depth of the Poisson solve (:data:`DEPTH`).
    far : float
        Poisson surface farther than this from the data is dropped, voxels (:data:`FAR_VOXELS`).
    cut_rims : bool
        Clip at the cloud's cut rims where found, as the completion method does (``colonbench map`` turns it
        off, :func:`colonbench.mapping.colonmap.for_mapping`).
    end_level : float or None
        The centerline's end level, as the completion method's.
    valley : float
        The wall gaps' valley level (:data:`GAP_VALLEY`).
    line : {"lumen", "circles"}
        The centerline: the lumen's (:func:`lumen_centerline`, the fitted circles' where no lumen is enclosed)
        or the fitted circles' always (:func:`middle_line`).
    """

    name = "poisson"

    def __init__(self, depth: int = DEPTH, far: float = FAR_VOXELS, cut_rims: bool = True,
                 end_level: float | None = END_LEVEL, valley: float = GAP_VALLEY, line: str = "lumen"):
        if line not in ("lumen", "circles"):
            raise InputError(f"poisson: line must be 'lumen' or 'circles', got {line!r}")
        self.line = line
        self.depth = int(depth)
        self.far = float(far)
        self.cut_rims = cut_rims
        self.end_level = end_level
        self.valley = float(valley)
        self.version = (f"poisson-{POISSON_VERSION},depth={self.depth},far={self.far:g},steps={STEPS_VERSION}"
                        + ("" if self.valley == GAP_VALLEY else f",valley={self.valley:g}")
                        + ("" if self.line == "lumen" else f",line={self.line}"))

    def estimate(self, points) -> Estimate:
        """Coverage, holes and centerline of one partial segment.

        Parameters
        ----------
        points : (n, 3) float
            The partial cloud, mm, in its own frame (checked and, above 3 points/mm^2, thinned as for the
            completion method: :func:`colonbench.completion.method.method_cloud`).

        Returns
        -------
        Estimate
            Coverage NaN (and no holes, no line) only when Poisson kept no surface near the points.
        """
        t0 = time.perf_counter()
        pts = method_cloud(points)
        grid = fit_grid(pts, **GRID_OPTIONS)
        t1 = time.perf_counter()
        heatmap, centerline = poisson_heatmap(grid.to_voxel(pts), grid.size, self.depth, self.far, self.end_level,
                                              self.line)
        t2 = time.perf_counter()
        if len(centerline) == 0:
            return Estimate(float("nan"), np.zeros((0, 3)), np.zeros((0, 3)), self.name,
                            seconds={"check": t1 - t0, "poisson": t2 - t1})
        est = from_heatmap(heatmap, grid, pts, self.name, centerline_vox=centerline, cut_rims=self.cut_rims,
                           valley=self.valley)
        est.seconds = {"check": t1 - t0, "poisson": t2 - t1, "mesh_holes": est.seconds["mesh_holes"]}
        return est
