"""Centerline from a (predicted) target heatmap, as the paper describes.

1. Candidate voxels: heatmap > 1 - delta (the target is 1 on the centerline),
   or > max - delta when the heatmap's maximum falls short of 1 (a network
   that has not learned the peak's full height still gives its ridge). If
   fewer than ``min_voxels`` pass, the threshold drops to the
   ``min_voxels``-th highest value.
2. End points: the two ends of the longest shortest path in the 26-neighbour
   graph of the candidates (edge length = voxel step), its 26-connected
   pieces joined by their shortest gaps (:func:`bridges`: a weak
   prediction's ridge comes in pieces, and keeping only the largest made the
   line too short). It is found by repeated double sweeps (Dijkstra from a
   node, then from the farthest node found, until the length stops growing):
   exact on trees and on the thin, tube-like sets a centerline gives, at the
   cost of a few Dijkstra runs instead of all pairs.
3. Fast marching from the start (scikit-fmm) with the heatmap to the power 8
   as speed (the power sharpens the preference for the ridge; on predictions
   early in training it doubles the centerline's precision and recall), over
   the voxels above 0.5 (the lumen side of the heatmap, which holds every
   candidate; a minimal path never leaves it, and the front then has a tenth
   of the grid to cover).
   The ends are first moved to the far ends of the lumen's core (the voxels
   at or above :data:`END_LEVEL`), where those lie farther along it than the
   candidates' ends: the candidates stop where the network's ridge fades, a
   median 9 mm short of a real colon's cut, and the mesh and the planes that
   follow the line stopped with them. Farther is measured along the core
   (shortest paths in its voxel graph), and each new end is re-centred in the
   core's last cross-section (:func:`_far_end`).
4. Back-propagation from the end point: steepest descent of the travel time
   (26-neighbourhood), then Gaussian smoothing, which gives a smooth sub-voxel
   polyline (:mod:`colonbench.paths`).
"""

from __future__ import annotations

import numpy as np
from scipy import sparse
from scipy.sparse.csgraph import connected_components, dijkstra

from colonbench import paths

#: The paper's delta: candidates are voxels above 1 - delta.
DELTA = 0.08
#: Fast-marching speed is heatmap ** SPEED_POWER: a sharper preference for the ridge.
SPEED_POWER = 8.0
#: Fast marching runs over the voxels above this heatmap value.
LUMEN = 0.5
#: ... or above this share of the lowest candidate's value, when that is lower (a weak prediction).
#: 0.8 (was 0.6) keeps fast marching off the plateau just under 0.5 that the 0.2 model predicts around
#: the lumen: the same centerlines on paper.yaml, a quarter of the time (0.11 -> 0.03 s per segment).
LUMEN_SHARE = 0.8
#: The line's ends are moved to the far ends of the voxels at or above this heatmap value (the lumen's core:
#: on a tube's exact heatmap within about 0.4 of the radius from the axis). Chosen among 0.6, 0.65 and 0.7
#: on validation data (docs/method.md step 3); None keeps the candidates' ends (steps before version 6).
END_LEVEL = 0.6
#: ... and re-centred in the lumen's cross-section there, square to the path between this many voxels (along
#: the path) from the far voxel.
END_TANGENT = (8, 16)
#: At most this many pieces of the candidates (the largest) are joined into one graph.
MAX_PIECES = 32
#: Fewest candidate voxels before the threshold is lowered.
MIN_VOXELS = 20
_NEIGHBOURS = np.array([(i, j, k) for i in (-1, 0, 1) for j in (-1, 0, 1) for k in (-1, 0, 1)
                        if (i, j, k) > (0, 0, 0)])


def candidates(heatmap: np.ndarray, delta: float = DELTA, min_voxels: int = MIN_VOXELS) -> np.ndarray:
    """(n, 3) int voxels above the threshold, every component (a weak prediction's ridge comes in pieces)."""
    h = np.asarray(heatmap, dtype=np.float32)
    thr = min(1.0 - delta, float(h.max()) - delta)
    if int((h > thr).sum()) < min_voxels:
        thr = float(np.partition(h.ravel(), -min_voxels)[-min_voxels]) - 1e-7
    return np.argwhere(h > thr)


def bridges(voxels: np.ndarray, graph: sparse.csr_matrix, max_pieces: int = MAX_PIECES) -> sparse.coo_matrix:
    """Edges joining the 26-connected components of ``voxels`` by their shortest gaps (the components' MST).

    Each component pair's gap is the distance between its two closest voxels;
    the minimum spanning tree over these gaps joins every piece of a broken
    ridge to the next one with the fewest and shortest jumps.

    Parameters
    ----------
    voxels : (n, 3) int
    graph : (n, n) sparse
        Their 26-neighbour graph (:func:`voxel_graph`).
    max_pieces : int
        Only the largest pieces are joined (a noisy prediction can scatter
        thousands of single voxels; the smallest stay unconnected and are
        ignored, and the cost stays bounded).
    """
    from scipy.sparse.csgraph import minimum_spanning_tree
    from scipy.spatial import cKDTree

    n = len(voxels)
    k, label = connected_components(graph, directed=False)
    if k < 2:
        return sparse.coo_matrix((n, n))
    sizes = np.bincount(label)
    members = [np.flatnonzero(label == c) for c in np.argsort(-sizes)[:max_pieces]]
    k = len(members)
    trees = [cKDTree(voxels[m]) for m in members]
    gap = np.zeros((k, k))
    pair = {}
    for i in range(k):
        for j in range(i + 1, k):
            d, nearest = trees[j].query(voxels[members[i]])
            a = int(np.argmin(d))
            gap[i, j] = max(float(d[a]), 1e-6)
            pair[i, j] = (int(members[i][a]), int(members[j][nearest[a]]))
    mst = minimum_spanning_tree(gap).tocoo()
    rows = [pair[min(i, j), max(i, j)] for i, j in zip(mst.row, mst.col)]
    r, c = np.array(rows).T
    return sparse.coo_matrix((mst.data, (r, c)), shape=(n, n))


def voxel_graph(voxels: np.ndarray) -> sparse.csr_matrix:
    """26-neighbour graph of voxels, weighted by step length."""
    n = len(voxels)
    lo = voxels.min(axis=0) - 1
    v = voxels - lo
    index = np.full(tuple(v.max(axis=0) + 2), -1, dtype=np.int64)
    index[v[:, 0], v[:, 1], v[:, 2]] = np.arange(n)
    rows, cols, w = [], [], []
    for off in _NEIGHBOURS:
        nb = v + off
        j = index[nb[:, 0], nb[:, 1], nb[:, 2]]
        ok = j >= 0
        rows.append(np.flatnonzero(ok))
        cols.append(j[ok])
        w.append(np.full(int(ok.sum()), np.linalg.norm(off)))
    g = sparse.coo_matrix((np.concatenate(w), (np.concatenate(rows), np.concatenate(cols))), shape=(n, n)).tocsr()
    return g + g.T


def graph_ends(graph: sparse.csr_matrix, max_sweeps: int = 4) -> tuple[int, int, float]:
    """End nodes and length of the longest shortest path, by repeated double sweeps."""
    a = 0
    best = (0, 0, 0.0)
    for _ in range(max_sweeps):
        d = dijkstra(graph, indices=a)
        d[~np.isfinite(d)] = -1
        b = int(np.argmax(d))
        if d[b] <= best[2] + 1e-9:
            break
        best = (a, b, float(d[b]))
        a = b
    return best


def _point_mask(shape, points) -> np.ndarray:
    """The 3x3x3 neighbourhoods of ``points`` (so the fast-marching front can leave them)."""
    m = np.zeros(shape, bool)
    for p in points:
        lo, hi = np.maximum(np.asarray(p) - 1, 0), np.asarray(p) + 2
        m[lo[0]:hi[0], lo[1]:hi[1], lo[2]:hi[2]] = True
    return m


def _far_end(h: np.ndarray, core: np.ndarray, graph: sparse.csr_matrix, source: int) -> tuple[np.ndarray, np.ndarray]:
    """The lumen's far end from the core voxel ``source``: (3,) int, and every core voxel's distance from it.

    The core voxel farthest from ``source`` along the core (shortest paths in
    its 26-neighbour graph: distance along the lumen, not fast-marching time,
    which grows with every step off the ridge and so would pick a stray
    voxel beside it) lies on the rim of the core's last cross-section. The
    end is the voxel of highest value in that cross-section: the core voxels
    within 1 voxel of the plane through the far voxel perpendicular to the
    path's direction :data:`END_TANGENT` voxels before it.
    """
    dist, pred = dijkstra(graph, indices=source, return_predecessors=True)
    dist[~np.isfinite(dist)] = -1
    far = int(np.argmax(dist))
    chain = [far]
    while pred[chain[-1]] >= 0 and len(chain) <= END_TANGENT[1]:
        chain.append(int(pred[chain[-1]]))
    a, b = END_TANGENT
    if len(chain) <= b:
        return core[far], dist
    tangent = (core[chain[a]] - core[chain[b]]).astype(float)
    tangent /= max(np.linalg.norm(tangent), 1e-9)
    section = np.abs((core - core[far]) @ tangent) <= 1.0
    section &= (np.linalg.norm(core - core[far], axis=1) <= b) & (dist >= 0)
    best = np.flatnonzero(section)[int(np.argmax(h[tuple(core[section].T)]))]
    return core[best], dist


def _lumen_ends(h: np.ndarray, start: np.ndarray, end: np.ndarray, level: float) -> tuple[np.ndarray, np.ndarray]:
    """The line's ends moved to the far ends of the lumen's core (the voxels at or above ``level`` connected to
    the candidates' ends), where those lie farther along it; the candidates' ends otherwise."""
    core = np.argwhere(h >= level)
    if len(core) < 2:
        return start, end
    index = np.full(h.shape, -1, np.int64)
    index[tuple(core.T)] = np.arange(len(core))
    i, j = index[tuple(start)], index[tuple(end)]
    if i < 0 or j < 0:
        return start, end
    graph = voxel_graph(core)
    # the start: the core's far end from the candidates' end, if farther than their start; then the end from it
    new_start, d = _far_end(h, core, graph, j)
    if d[index[tuple(new_start)]] > d[i]:
        start, i = new_start, index[tuple(new_start)]
    new_end, d = _far_end(h, core, graph, i)
    if d[index[tuple(new_end)]] > d[j]:
        end = new_end
    return start, end


def extract_centerline(heatmap: np.ndarray, delta: float = DELTA, smooth_voxels: float = 2.0,
                       power: float = SPEED_POWER, end_level: float | None = END_LEVEL) -> np.ndarray:
    """The centerline of a target heatmap, in continuous voxel indices.

    Parameters
    ----------
    heatmap : (S, S, S) float
        Target-style heatmap (1 on the centerline, 0 on the wall).
    delta : float
        Candidates are voxels above ``1 - delta``.
    smooth_voxels : float
        Gaussian smoothing of the back-propagated path, voxels.
    power : float
        Speed = heatmap ** power.
    end_level : float or None
        The ends move to the farthest voxels at or above this value (step 3); None keeps the candidates'.

    Returns
    -------
    (m, 3) float
        Ordered polyline from one end to the other; empty if the heatmap has no line.
    """
    h = np.clip(np.asarray(heatmap, dtype=np.float64), 0.0, 1.0)
    vox = candidates(h, delta)
    if len(vox) < 2:
        return np.zeros((0, 3))
    graph = voxel_graph(vox)
    joins = bridges(vox, graph).tocsr()
    graph = (graph + joins + joins.T).tocsr()
    k, label = connected_components(graph, directed=False)
    if k > 1:  # the pieces left out of the bridges (specks of a noisy prediction)
        keep = label == int(np.argmax(np.bincount(label)))
        vox, graph = vox[keep], graph[keep][:, keep]
    a, b, _ = graph_ends(graph)
    start, end = vox[a], vox[b]
    # a weak prediction whose candidates sit below LUMEN still gets a connected domain
    lumen = min(LUMEN, LUMEN_SHARE * float(h[tuple(vox.T)].min()))
    speed = np.maximum(h, 1e-3) ** power
    if end_level is not None:
        start, end = _lumen_ends(h, start, end, end_level)
    mask = (h > lumen) | _point_mask(h.shape, (start, end))
    t = paths.travel_time(speed, start, mask=mask)
    if not np.isfinite(t[tuple(end)]):  # the two ends are not connected above `lumen`: march everywhere
        t = paths.travel_time(speed, start, mask=np.ones(h.shape, bool))
    path = paths.backtrack(t, end)
    return paths.smooth_path(path, smooth_voxels)


