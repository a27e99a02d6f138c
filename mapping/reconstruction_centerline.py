"""The centerline of a whole colon reconstruction: a point cloud with holes and missing stretches.

A reconstruction is an open surface: holes let the inside meet the outside,
so the lumen cannot be flood-filled as for a closed mesh
(:func:`colonbench.datagen.mesh_centerline.compute_centerline`). Instead:

1. The points are rasterised at ``voxel_mm`` and dilated by ``close_mm``
   (the wall, with gaps of a sparse cloud closed).
2. A free voxel is *enclosed* when a ray from it meets the wall in at least
   ``enclosed_share`` of 26 directions (the 26-neighbourhood's): inside a tube
   nearly all rays meet the wall, holes included; outside, between limbs or in
   a bend, at most about two thirds do. The rays are cast on the grid by
   doubling: a voxel sees the wall within ``2k`` steps when it, or the voxel
   ``k`` steps ahead, sees it within ``k``.
3. The enclosed voxels, opened (no sheets or threads), split into pieces
   (6-connected, at least ``min_piece_mm`` across): where the colon has no
   wall at all for a stretch, nothing is enclosed and the colon is
   *interrupted*. Pieces whose median depth is under half the longest one's
   are channels, not lumen (inside a wall drawn as a shell), and dropped,
   unless they are at least 100 mm long and lie apart from the wider ones
   (a narrower stretch of the colon).
4. In each piece, the minimal path between its two geodesic extremities with
   a speed that grows with the distance to the wall (fast marching, the
   recipe of :mod:`colonbench.paths`), smoothed, its last two sigmas (bent by
   the smoothing) cut; then continued straight past its ends over the points
   beyond them (the rays near an open end
   of the colon escape through it, so the enclosed lumen stops short of the end
   by about a radius). With the camera trajectory, a path that leaves out part
   of it (a shortcut through a hole where two limbs touch) is sought again
   along it (:func:`_piece_path`).
5. The pieces are chained end to nearest end into one order, and joined
   where the wall lines the gap between them (a hole on one side of the
   colon, large enough to let the rays out, is no interruption): the colon
   is interrupted only where no wall lines the gap.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from colonbench import paths
from colonbench.errors import InputError
from colonbench.mapping.lumen_paths import (DIRECTIONS, MIN_PIECE_MM, Piece, piece_paths, rasterise, ray_hits,
                                            trajectory_distance)
from colonbench.mapping.scope_route import bridge_pieces
from colonbench.polyline import resample

#: Raster of the wall, mm.
VOXEL_MM = 2.0
#: Gaps in the wall closed by dilation, mm (a cloud of 0.5 points/mm^2 leaves about 1.4 mm).
CLOSE_MM = 4.0
#: Share of the 26 ray directions that must meet the wall for a free voxel to be inside.
ENCLOSED_SHARE = 0.8
#: Gaussian smoothing of the voxel path, mm.
SMOOTH_MM = 6.0


def _extend(line: np.ndarray, cloud: np.ndarray, radius: float, reach_mm: float = 10.0) -> np.ndarray:
    """``line`` continued straight past each end (its tangent over the last ``reach_mm``) over the points beyond.

    It goes as far as the cloud's points ahead of the end (those within
    ``2 * radius`` of its axis, so another limb beyond the end does not pull
    it on; their 99.5th percentile), and at most ``2 * radius``: the enclosed
    lumen stops short of an open end by about a radius (and the smoothed
    path's ends were cut by two sigmas), a closed pole (the caecum) ends the
    points anyway, and further out the straight line leaves a bending colon. (Continuing with the end's curvature was
    no better on a helical tube: the last centimetre's turning is mostly noise.)
    """
    out = np.asarray(line, float)
    for end in (0, 1):
        pts = out if end == 1 else out[::-1]
        if len(pts) < 2:
            continue
        t = pts[-1] - pts[max(len(pts) - 1 - int(reach_mm), 0)]
        if np.linalg.norm(t) < 1e-9:
            continue
        t = t / np.linalg.norm(t)
        rel = cloud - pts[-1]
        along = rel @ t
        across = np.linalg.norm(rel - along[:, None] * t, axis=1)
        ahead = along[(along > 0) & (across < 2.0 * radius)]
        if len(ahead) == 0:
            continue
        extra = int(round(min(float(np.percentile(ahead, 99.5)), 2.0 * radius)))
        if extra < 1:
            continue
        new = pts[-1] + np.arange(1.0, extra + 1.0)[:, None] * t
        out = np.concatenate([out, new]) if end == 1 else np.concatenate([new[::-1], out])
    return out


def _chain(pieces: list[Piece]) -> list[Piece]:
    """Pieces ordered end to nearest end, each oriented to continue the previous one."""
    if len(pieces) <= 1:
        return pieces
    ends = [(p.points[0], p.points[-1]) for p in pieces]

    def gap(i, j):  # shortest distance between an end of i and an end of j
        return min(np.linalg.norm(a - b) for a in ends[i] for b in ends[j])

    n = len(pieces)
    # start with the piece whose nearest neighbour is farthest: an end of the chain
    first = max(range(n), key=lambda i: min(gap(i, j) for j in range(n) if j != i))
    left = set(range(n)) - {first}
    line = pieces[first].points
    # orient the first piece so that its far end (from the rest) comes first
    rest = np.concatenate([pieces[j].points[[0, -1]] for j in left])
    if np.linalg.norm(rest - line[0], axis=1).min() < np.linalg.norm(rest - line[-1], axis=1).min():
        pieces[first] = Piece(line[::-1].copy(), pieces[first].radius)
    out = [pieces[first]]
    while left:
        tip = out[-1].points[-1]
        j = min(left, key=lambda i: min(np.linalg.norm(ends[i][0] - tip), np.linalg.norm(ends[i][1] - tip)))
        p = pieces[j].points
        if np.linalg.norm(p[-1] - tip) < np.linalg.norm(p[0] - tip):
            p = p[::-1].copy()
        out.append(Piece(p, pieces[j].radius))
        left.remove(j)
    return out


def _drop_channels(pieces: list[tuple[Piece, float]], long_mm: float = 100.0, apart: float = 1.5) -> list[Piece]:
    """The pieces that are stretches of the colon's lumen, not channels beside it.

    A piece far narrower than the longest one (under half its median depth)
    is a channel (the gap inside a wall drawn as a shell, a pocket between
    folds) unless it is at least ``long_mm`` long and lies apart from the
    wider pieces (at least ``apart`` of their radius from their centerlines
    over 80 % of its length): then it is a narrower stretch of the colon (a
    narrow limb of a real colon, a noisy reconstruction's thin lumen).
    """
    from scipy.spatial import cKDTree

    longest = max(pieces, key=lambda p: p[0].length)[1]
    wide = [p for p, depth in pieces if depth >= 0.5 * longest]
    tree = cKDTree(np.concatenate([p.points for p in wide]))
    radius = max(p.radius for p in wide)
    kept = []
    for p, depth in pieces:
        if depth >= 0.5 * longest:
            kept.append(p)
        elif p.length >= long_mm:
            d, _ = tree.query(p.points)
            if np.mean(d > apart * radius) >= 0.8:
                kept.append(p)
    return kept


def colon_centerline(points, voxel_mm: float = VOXEL_MM, close_mm: float = CLOSE_MM,
                     enclosed_share: float = ENCLOSED_SHARE, min_piece_mm: float = MIN_PIECE_MM,
                     smooth_mm: float = SMOOTH_MM, positions: np.ndarray | None = None) -> list[Piece]:
    """The centerline of a colon reconstruction, in uninterrupted pieces, chained in order.

    Parameters
    ----------
    points : (n, 3) float
        The reconstruction's points, mm.
    voxel_mm, close_mm, enclosed_share, min_piece_mm, smooth_mm : float
        See the module's description.
    positions : (k, 3) float, optional
        Camera positions in time order, mm, the points' frame. Each piece's path then keeps to
        the lumen the scope went through (:func:`_piece_path`); without them it is the lumen's
        longest path, which can cut through a hole where two limbs of the colon touch.

    Returns
    -------
    list of Piece
        Ordered along the colon (the direction is arbitrary: the first piece's
        first point is one end of the chain); more than one where the colon is
        interrupted.

    Raises
    ------
    InputError
        When nothing is enclosed: not a tube, or far too sparse.
    """
    import edt

    pts = np.asarray(points, float)
    close = max(int(round(close_mm / voxel_mm)), 0)
    occupied, origin = rasterise(pts, voxel_mm, pad=close + 2)
    wall = ndimage.binary_dilation(occupied, iterations=close) if close else occupied
    hits = ray_hits(wall)
    inside = ~wall & (hits >= int(np.ceil(enclosed_share * len(DIRECTIONS))))
    # thin sheets and threads between dilated walls are no lumen (and fast marching needs faces)
    inside = ndimage.binary_opening(inside)
    # the wall was dilated by `close`: the lumen's distance to the true wall is `close` voxels more
    dist = edt.edt(inside, anisotropy=(voxel_mm,) * 3)
    guide = None
    if positions is not None and len(positions):
        guide = trajectory_distance(positions, origin, inside.shape, voxel_mm)
    label, n = ndimage.label(inside)
    if n == 0:
        raise InputError("no lumen found: the points do not enclose a tube (is this a colon reconstruction "
                         "in mm?)")
    pieces = []
    extents = ndimage.find_objects(label)
    for lab, box in enumerate(extents, start=1):
        span = np.linalg.norm([(s.stop - s.start) * voxel_mm for s in box])
        if span < min_piece_mm:
            continue
        # one empty voxel around the piece (the grid's padding holds it): fast marching needs a border
        box = tuple(slice(s.start - 1, s.stop + 1) for s in box)
        part = label[box] == lab
        for vox in piece_paths(part, dist[box], voxel_mm, None if guide is None else guide[box], min_piece_mm):
            # geodesic extremities lie at the rim of the enclosed lumen, off its axis: keep the path from where
            # it is at least 0.7 of its median depth (as for closed meshes, datagen.realmesh.compute_centerline)
            depth = dist[box][tuple(vox.T)]
            deep = np.flatnonzero(depth >= 0.7 * np.median(depth))
            vox, depth = vox[deep[0]: deep[-1] + 1], depth[deep[0]: deep[-1] + 1]
            if len(vox) < 4:
                continue
            line = origin + (paths.smooth_path(vox, smooth_mm / voxel_mm) + [s.start for s in box]) * voxel_mm
            line = resample(line, 1.0)
            # smoothing bends the last sigma or two of a path's ends: they are grown again from the points
            trim = int(round(2 * smooth_mm))
            if len(line) < 2 * trim + 4:
                continue
            line = line[trim: len(line) - trim]
            depth = float(np.median(depth))
            pieces.append((Piece(line, depth + close * voxel_mm), depth))
    if pieces:
        pieces = _drop_channels(pieces)
    if not pieces:
        raise InputError("no stretch of lumen longer than "
                         f"{min_piece_mm:g} mm found: the points do not enclose a tube")
    # the pieces' ends, extended over the points beyond them (open ends lose about a radius);
    # each piece's points: those nearest to it
    from scipy.spatial import cKDTree

    owner = np.concatenate([np.full(len(p.points), i) for i, p in enumerate(pieces)])
    _, near = cKDTree(np.concatenate([p.points for p in pieces])).query(pts)
    for i, p in enumerate(pieces):
        mine = pts[owner[near] == i]
        if len(mine):
            pieces[i] = Piece(resample(_extend(p.points, mine, p.radius), 1.0), p.radius)
    return bridge_pieces(_chain(pieces), pts, positions=positions)


