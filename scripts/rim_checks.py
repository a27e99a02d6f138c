"""Checks of the cut rims the completion method clips at, measured on the calibration set (decisions 0145, 0148-0149).

    python scripts/rim_checks.py [--data data] [--out rim_checks.csv]

For every segment of the calibration set (data_manifests/calibration.yaml and calibration-real.yaml, validation
splits, in ``<data>/calibration`` and ``<data>/calibration-real``; generated where missing) at 0 and 0.5 mm noise
(drawn as colonbench evaluate draws it), the rims the search finds (:func:`colonbench.completion.planes.rim_planes`)
and five features of each: (a) its centre's distance from the line over its radius, (b) how far inside the cloud's
span along the line its plane crosses the line (mm, :func:`colonbench.completion.planes.cuts_into_cloud`), (c) its
normal's angle to the line where it crosses, (d) the share of the sectors around the line, in its plane about the
crossing, that its points leave empty, (e) the same for the whole cloud's points near its plane and the crossing;
decision 0149's check, (e) where (b) exceeds 7 mm; and the coverage with each subset of the rims treated as none.
Then, for each feature, the threshold chosen on one half of the colons (the parity of a colon's rank) and measured on
the other, both ways, by the two rules of decision 0145: the lowest MAE (first rule), and the lowest MAE among
thresholds that raise no hole model's MAE by more than 0.5 points (second rule). Prints both tables; writes the
per-estimate features to ``--out``. Decision 0145 measured (a)-(c) on calibration.yaml alone with the colons halved
by their ids' parity (this script as of commit 5306dca); 0148 measures (a)-(d) on both manifests, 0149 (e).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import pandas as pd
from scipy.spatial import cKDTree

from colonbench.benchmark.evaluate import noisy, select
from colonbench.completion import planes as P
from colonbench.completion.method import CompletionMethod, method_cloud
from colonbench.completion.steps import complete
from colonbench.polyline import resample
from colonbench.shards.reader import Shard

from calibrate_intervals import NOISE_MM, calibration_data, even_half

FEATURES = {"centre_off": np.arange(0.3, 3.01, 0.1), "cut_in_mm": np.arange(4.0, 30.1, 1.0),
            "angle": np.arange(10.0, 60.1, 2.5), "empty": np.arange(0.0, 0.701, 0.05),
            "whole": np.arange(0.0, 0.701, 0.05), "cut_and_whole": np.arange(0.0, 0.701, 0.05)}

#: Decision 0149's check: (e) counts only where the plane crosses the line this far inside the cloud (b), mm.
CUT_IN_MM = 7.0
SUBSETS = ((), (0,), (1,), (0, 1))


def rim_features(plane, rim, end: int, dense: np.ndarray, nearest: np.ndarray, cloud: np.ndarray,
                 voxel_mm: float) -> dict:
    """The features of one end's rim (its plane, its touching points, the whole cloud; voxels)."""
    centre, normal = plane
    inside = np.flatnonzero((dense - centre) @ normal >= 0)
    if len(inside):
        j = inside[0] if end == 0 else inside[-1]
        t = dense[min(j + 1, len(dense) - 1)] - dense[max(j - 1, 0)]
        angle = float(np.degrees(np.arccos(min(1.0, abs(t @ normal) / np.linalg.norm(t)))))
        axis = normal / np.linalg.norm(normal)

        def empty_share(pts):   # the share of the sectors about the crossing, in the plane, that pts leave empty
            return 1.0 - P._sectors(pts - dense[j], axis[None], np.ones((1, len(pts)), bool))[0] / P.RIM_SECTORS

        empty = empty_share(rim)
        # (e): the whole cloud's points near the plane and near the crossing (decision 0149)
        reach = 2 * float(np.median(np.linalg.norm(rim - dense[j], axis=1)))
        near = (np.abs((cloud - centre) @ axis) <= P.RIM_BAND) & (np.linalg.norm(cloud - dense[j], axis=1) <= reach)
        whole = empty_share(cloud[near]) if near.any() else 1.0
    else:
        angle, empty, whole = 90.0, 1.0, 1.0
    radius = float(np.median(np.linalg.norm(rim - centre, axis=1)))
    return {"centre_off": cKDTree(dense).query(centre)[0] / radius, "angle": angle,
            "cut_in_mm": P.cuts_into_cloud(plane, end, dense, nearest) * voxel_mm, "empty": float(empty),
            "whole": float(whole)}


def one(method: CompletionMethod, points: np.ndarray) -> dict | None:
    """Features of a cloud's rims and its coverage with each subset of them treated as none."""
    p = method.predictor(points)
    cl, grid = p.centerline_vox, p.grid
    vox = grid.to_voxel(points)
    ends = P.end_planes(cl)
    if len(ends) != 2 or len(vox) < P.RIM_MIN_POINTS:
        return None
    dense = resample(np.asarray(cl, float), 0.25)
    _, nearest = cKDTree(dense).query(vox)
    found, fallback, feats = [], [], []
    for k, (point, normal) in enumerate(ends):
        near = nearest <= P.RIM_END_SHARE * len(dense) if k == 0 else nearest >= (1 - P.RIM_END_SHARE) * len(dense)
        x = vox[near]
        rim, _ = P._rim_plane(point, normal, x, P.RIM_BAND, P.RIM_CAP_DEG, P.RIM_MIN_SHARE)
        fallback.append(P.pushed_out(point, normal, x))
        found.append(fallback[-1] if rim is None else rim)
        checked = rim is not None and rim[0] is not point          # a rim at the line's end keeps its plane
        feats.append(rim_features(rim, P._touching(x, -rim[1], P.RIM_BAND), k, dense, nearest, vox,
                                   grid.voxel_size)
                     if checked else None)
    out = {}
    for rejected in SUBSETS:
        if all(feats[k] is not None for k in rejected):
            planes = P.Planes([fallback[k] if k in rejected else found[k] for k in (0, 1)])
            out["cov" + "".join(map(str, rejected))] = complete(p.heatmap, cl, vox, planes=planes).coverage
    for k in (0, 1):
        for key in FEATURES:
            if key != "cut_and_whole":
                out[f"{key}{k}"] = feats[k][key] if feats[k] is not None else np.nan
        # 0149's check: (e) where (b) exceeds CUT_IN_MM, -1 (never over a threshold) elsewhere
        out[f"cut_and_whole{k}"] = np.nan if feats[k] is None else \
            feats[k]["whole"] if feats[k]["cut_in_mm"] > CUT_IN_MM else -1.0
    return out


def with_threshold(df: pd.DataFrame, key: str, t: float) -> np.ndarray:
    """Each estimate's coverage with the rims whose feature ``key`` exceeds ``t`` treated as none."""
    r0, r1 = (df[f"{key}0"] > t).to_numpy(), (df[f"{key}1"] > t).to_numpy()
    c = df["cov"].to_numpy().copy()
    c = np.where(r0 & ~r1, df["cov0"], c)
    c = np.where(r1 & ~r0, df["cov1"], c)
    return np.where(r0 & r1, df["cov01"], c)


def mae(df: pd.DataFrame, c: np.ndarray) -> float:
    return 100 * float(np.abs(c - df["true"].to_numpy()).mean())


def worst_rise(df: pd.DataFrame, c: np.ndarray) -> float:
    g = df.assign(new=c).groupby("hole_model")
    return max(mae(x, x["new"].to_numpy()) - mae(x, x["cov"].to_numpy()) for _, x in g)


def choose(df: pd.DataFrame, key: str, constrained: bool) -> float:
    grid = [t for t in FEATURES[key] if not constrained or worst_rise(df, with_threshold(df, key, t)) <= 0.5]
    return min(grid, key=lambda t: (mae(df, with_threshold(df, key, t)), -t)) if grid else np.inf


def report(df: pd.DataFrame, constrained: bool) -> None:
    half = even_half(df["colon_id"]).to_numpy()
    print(f"\n{'second' if constrained else 'first'} rule; MAE with every rim as found {mae(df, df['cov']):.2f}")
    for key in FEATURES:
        held, chosen = np.zeros(len(df)), []
        for a, b in ((half, ~half), (~half, half)):
            t = choose(df[a], key, constrained)
            chosen.append(t)
            held[b] = with_threshold(df[b], key, t)
        per = df.assign(new=held).groupby("hole_model").apply(
            lambda g: pd.Series({"before": mae(g, g["cov"].to_numpy()), "after": mae(g, g["new"].to_numpy())}))
        whole = choose(df, key, constrained)
        print(f"{key}: thresholds {chosen[0]:g} / {chosen[1]:g}, held-out MAE {mae(df, held):.2f}, worst rise of "
              f"a hole model {(per['after'] - per['before']).max():+.2f}; on the whole set {whole:g}")
        print(per.round(2).T.to_string())


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default="data", help="folder of the calibration's datasets (default: data)")
    ap.add_argument("--out", default="rim_checks.csv")
    ap.add_argument("--workers", type=int, default=2, help="processes generating the data")
    args = ap.parse_args()
    method = CompletionMethod()
    rows = []
    for manifest, data in calibration_data(Path(args.data), args.workers):
        _, picks = select(data, "validation")
        for name, indices in picks:
            with Shard(data / name) as shard:
                for i in indices:
                    geo = shard.geometry(i)
                    for sigma in NOISE_MM:
                        r = one(method, method_cloud(noisy(geo["partial_points"], sigma, 0, name, i)))
                        if r is not None:
                            rows.append({"manifest": manifest.stem, "shard": name, "index": i,
                                         "colon_id": geo["colon_id"], "noise_mm": sigma,
                                         "hole_model": geo["hole_model"], "true": geo["coverage"], **r})
    df = pd.DataFrame(rows)
    df.to_csv(args.out, index=False)
    print(f"{len(df)} estimates; rims checked: {int(df[['cut_in_mm0', 'cut_in_mm1']].notna().sum().sum())}")
    for constrained in (False, True):
        report(df, constrained)


if __name__ == "__main__":
    main()
