# Decision record 0173's one-off look (Afterwards: a correction), run from the repository root; removed after.
import numpy as np
from scipy.spatial import cKDTree

def run_on(line, planes, verts, step=2.0, half=1.0, max_steps=200):
    """Run the line on from each end along the tube to its plane, following the centroids of the surface's
    vertices in thin slabs. Returns (added length at start, added length at end) in voxels and the points."""
    c = np.asarray(line, float); v = np.asarray(verts, float)
    if len(c) < 2 or len(planes) != 2 or len(v) == 0:
        return 0.0, []
    s = np.r_[0, np.cumsum(np.linalg.norm(np.diff(c, axis=0), axis=1))]
    d, idx = cKDTree(c).query(v)
    interior = (s[idx] > 3) & (s[idx] < s[-1] - 3)
    r = np.median(d[interior]) if interior.sum() > 20 else np.median(d)
    total = 0.0; paths = []
    for k, (point, inward) in enumerate(planes):
        point = np.asarray(point, float); inward = np.asarray(inward, float)
        end = c[0] if k == 0 else c[-1]
        near = c[s <= 5] if k == 0 else c[s >= s[-1] - 5]
        t = (near[0] - near[-1]) if k == 0 else (near[-1] - near[0])
        t = t / np.linalg.norm(t) if np.linalg.norm(t) > 0 else -inward
        p = end.copy(); path = [p.copy()]
        beyond = (p - point) @ inward
        if beyond <= 1.0:
            paths.append(np.array(path)); continue
        added = 0.0
        vin = v[((v - point) @ inward) >= 0]
        for _ in range(max_steps):
            left = (p - point) @ inward          # how far p lies inside the plane
            if left <= 1e-6:
                break
            rel = vin - p
            along = rel @ t
            perp = np.linalg.norm(rel - along[:, None] * t, axis=1)
            sel = (np.abs(along - step) <= half) & (perp <= 2.0 * r)
            if sel.sum() < 10:
                break
            q = vin[sel].mean(axis=0)
            dq = q - p
            # stop at the plane: the part of the step inside it
            inside_q = (q - point) @ inward
            if inside_q < 0:
                frac = left / (left - inside_q)
                q = p + frac * dq
                total += np.linalg.norm(q - p); added += np.linalg.norm(q - p); p = q; path.append(q); break
            if added + np.linalg.norm(dq) > np.pi / 2 * beyond:
                break
            total += np.linalg.norm(dq); added += np.linalg.norm(dq)
            t = dq / np.linalg.norm(dq); p = q; path.append(p.copy())
        # the rest straight to the plane along the plane's normal (as before)
        left = (p - point) @ inward
        if left > 0:
            total += left
        paths.append(np.array(path))
    return total, paths
