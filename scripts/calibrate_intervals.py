"""Calibrate the completion method's coverage intervals: split-conformal on data_manifests/calibration.yaml and
calibration-real.yaml.

    python scripts/calibrate_intervals.py [--data data] [--model small] [--level 0.9]

Generates the calibration set where missing, ``<data>/calibration`` and ``<data>/calibration-real`` (the two
manifests' validation splits: widened colons no manifest trains on with a tenth video partials, and the real
training colons, which make up about 43 % of the segments: decision record 0147), estimates every segment with the
completion method (its intervals off) at 0 and 0.5 mm noise (the suites' levels, the noise drawn as colonbench
evaluate draws it), and chooses the grouping by a rule fixed before the measurement (decision record 0144): each
candidate scheme is fitted on the colons of one half (the parity of a colon's rank among the colons sorted by id)
and measured on the other, both ways; of the schemes whose held-out coverage lies within 4 points of the level in
every group of at least 30 segments, the one with the smallest mean width wins (else the marginal one). It is then
fitted on all segments and written beside the model (``<model>.intervals.json``). Prints the held-out coverage and
width of every scheme.
"""

from __future__ import annotations

import argparse
import hashlib
import json
from pathlib import Path

import numpy as np
import pandas as pd
import yaml

from colonbench.benchmark.evaluate import noisy, select
from colonbench.completion import intervals
from colonbench.completion.method import CompletionMethod, model_path, steps_version
from colonbench.errors import ColonbenchError
from colonbench.shards.dataset import generate
from colonbench.shards.reader import Shard
from colonbench.shards.schema import sha256_file

ROOT = Path(__file__).resolve().parents[1]
MANIFESTS = tuple(ROOT / "data_manifests" / f"{name}.yaml"
                  for name in ("calibration", "calibration-real"))
SCHEMES = ("marginal", "rims", "length", "length+band", "length+rims")
NOISE_MM = (0.0, 0.5)
#: An interval wider than this flags its estimate for review: the truth may lie 20 points or more away (the
#: calibration groups of the shortest clouds, whose 90 % intervals span 47-51 points; the others span 12-35).
REVIEW_WIDTH = 0.4
#: The cross-fitted models (scripts/train_crossfit.sh): each has never seen the real colon it estimates.
CROSSFIT = {name: ROOT / "completion" / "models" / "crossfit" / f"crossfit-without-{name}.safetensors"
            for name in ("gca00080", "gca00090")}
#: Rule 0 of decision record 0152: a cross-fitted model's procedural MAE within this many points of the shipped one's.
CROSSFIT_MAE_TOLERANCE = 1.0


def calibration_data(root: Path, workers: int = 2) -> list[tuple[Path, Path]]:
    """(manifest, folder) of each calibration manifest, generated under ``root`` where missing (``<root>/<name>``)."""
    root = Path(root)
    if (root / "manifest.yaml").is_file():
        raise SystemExit(f"--data {root} is a single dataset: give the folder that holds (or is to hold) "
                         f"{' and '.join(m.stem + '/' for m in MANIFESTS)}, the calibration's datasets (default: data)")
    out = []
    for manifest in MANIFESTS:
        data = root / manifest.stem
        generate(manifest, data, workers=workers, splits=["validation"], progress=False)
        out.append((manifest, data))
    return out


def estimates(data: Path, method, cache: Path, which: str = "all") -> pd.DataFrame:
    """Completion's estimate of every validation segment at every noise level (cached in ``cache``).

    ``method`` is a :class:`CompletionMethod`, or a dict from a real colon's id to the method that estimates its
    segments (a cross-fitted model that has not seen that colon: decision record 0152); ``which`` is ``all``,
    ``real`` (the real colons' shards, ``mesh-*``) or ``procedural`` (the others).
    """
    if cache.is_file():
        return pd.read_csv(cache)
    _, picks = select(data, "validation")
    rows = []
    for name, indices in picks:
        if which != "all" and Path(name).name.startswith("mesh-") != (which == "real"):
            continue
        with Shard(data / name) as shard:
            for i in indices:
                geo = shard.geometry(i)
                by = method.get(int(geo["colon_id"])) if isinstance(method, dict) else method
                if by is None:
                    raise SystemExit(f"{data / name}: no cross-fitted model for colon {geo['colon_id']}")
                for sigma in NOISE_MM:
                    try:
                        est = by.estimate(noisy(geo["partial_points"], sigma, 0, name, i))
                    except ColonbenchError as exc:     # counted, not calibrated on
                        print(f"{name} {i} at {sigma:g} mm: no estimate ({exc})", flush=True)
                        continue
                    rows.append({"shard": name, "index": i, "colon_id": geo["colon_id"], "noise_mm": sigma,
                                 "hole_model": geo["hole_model"], "segment_mm": geo["length_mm"],
                                 "true": geo["coverage"], "estimate": est.coverage,
                                 "rims": est.signals.get("rims", 0), "length_mm": est.signals.get("length_mm")})
        print(f"{name}: {len(rows)} estimates", flush=True)
    out = pd.DataFrame(rows)
    out = out[np.isfinite(out["estimate"])]             # an empty completed surface gives no estimate
    out.to_csv(cache, index=False)
    return out


def signals_of(row) -> dict:
    return {"rims": int(row["rims"]), "length_mm": float(row["length_mm"])}


def signals(df: pd.DataFrame) -> list[dict]:
    return [signals_of(r) for _, r in df.iterrows()]


def even_half(colon_ids: pd.Series) -> pd.Series:
    """Whether each row's colon is in the first of the two halves the schemes are measured on: the parity of the
    colon's rank among the distinct ids sorted (not of the id itself, which puts both real colons, 900080 and
    900090, in one half; decision record 0147)."""
    rank = {c: k for k, c in enumerate(sorted(colon_ids.unique()))}
    return colon_ids.map(rank) % 2 == 0


def held_out(df: pd.DataFrame, scheme: str, level: float) -> pd.DataFrame:
    """Coverage and width per group of a scheme fitted on one half of the colons and measured on the other."""
    half = even_half(df["colon_id"])
    rows = []
    for fit_on, test_on in ((half, ~half), (~half, half)):
        a, b = df[fit_on], df[test_on]
        cal = intervals.fit(a["true"], a["estimate"], signals(a), scheme, REVIEW_WIDTH, level)
        for _, r in b.iterrows():
            lo, hi = cal.interval(r["estimate"], signals_of(r))
            rows.append({"group": intervals.group_key(r["estimate"], signals_of(r), scheme),
                         "inside": lo - 1e-12 <= r["true"] <= hi + 1e-12, "width": hi - lo})
    return pd.DataFrame(rows)


def choose(name: str, held: dict, level: float) -> tuple[str | None, dict]:
    """0144's rule on held-out tables (:func:`held_out`'s) of several schemes: of those whose coverage lies within 4
    points of ``level`` in every group of at least :data:`intervals.MIN_GROUP` rows, the narrowest (None if none
    does); prints each scheme's table. Also the summary per scheme: ``covered``, ``width`` (fractions), ``ok``."""
    best, best_width, summary = None, np.inf, {}
    for scheme, h in held.items():
        per = h.groupby("group").agg(n=("inside", "size"), covered=("inside", "mean"), width=("width", "mean"))
        big = per[per["n"] >= intervals.MIN_GROUP]
        ok = bool((abs(big["covered"] - level) <= 0.04).all())
        summary[scheme] = {"covered": float(h["inside"].mean()), "width": float(h["width"].mean()), "ok": ok}
        print(f"\n{name} {scheme}: held-out coverage {100 * h['inside'].mean():.1f} %, mean width "
              f"{100 * h['width'].mean():.1f} points, every group within 4 points of {level:.0%}: {ok}")
        print(per.assign(covered=lambda d: (100 * d["covered"]).round(1), width=lambda d: (100 * d["width"]).round(1))
              .to_string())
        if ok and h["width"].mean() < best_width:
            best, best_width = scheme, h["width"].mean()
    return best, summary


def crossfit_models(specs: list[str]) -> dict[str, Path]:
    """The cross-fitted models by real colon name, from ``COLON=MODEL`` arguments (refused where a colon is not one of
    the calibration's real colons, or a file is missing)."""
    real = {n for m in MANIFESTS for n in (yaml.safe_load(m.read_text()).get("meshes") or {})}
    out = {}
    for spec in specs:
        name, sep, model = spec.partition("=")
        if not sep or name not in real:
            raise SystemExit(f"--crossfit {spec}: give COLON=MODEL, COLON one of {', '.join(sorted(real))}")
        if not Path(model).is_file():
            raise SystemExit(f"--crossfit {spec}: no such model file")
        out[name] = Path(model)
    if set(out) != real:
        raise SystemExit(f"--crossfit: a model for each real colon of the calibration ({', '.join(sorted(real))})")
    return out


def colon_ids() -> dict[str, int]:
    """The calibration's real colons' ids by name (from the manifests)."""
    return {n: int(e["id"]) for m in MANIFESTS for n, e in (yaml.safe_load(m.read_text()).get("meshes") or {}).items()}


def crossfitted(df: pd.DataFrame, datasets, models: dict[str, Path]) -> tuple[pd.DataFrame, dict]:
    """``df`` with the real colons' estimates made again by the cross-fitted models (decision record 0152), after
    the check that each errs like the shipped model on calibration.yaml's procedural segments (rule 0: MAE within
    :data:`CROSSFIT_MAE_TOLERANCE`; refused otherwise). Also what the calibration's source records of them."""
    ids = colon_ids()
    methods = {}
    for name, path in models.items():
        methods[ids[name]] = CompletionMethod(str(path))
        methods[ids[name]].intervals = None
    (first, first_data), = [(m, d) for m, d in datasets if m == MANIFESTS[0]]
    procedural = df[(df["manifest"] == first.stem) & ~df["shard"].str.contains("mesh-")]
    shipped_mae = 100 * (procedural["estimate"] - procedural["true"]).abs().mean()
    record, failed = {}, []
    for name, path in models.items():
        digest = sha256_file(path)
        cache = first_data / f"completion-estimates-{digest[:12]}-{steps_version()}-procedural.csv"
        own = estimates(first_data, methods[ids[name]], cache, which="procedural")
        both = procedural.merge(own, on=["shard", "index", "noise_mm"], suffixes=("", "_own"))
        mae = 100 * (both["estimate_own"] - both["true"]).abs().mean()
        ship = 100 * (both["estimate"] - both["true"]).abs().mean()
        print(f"cross-fitted model without {name}: procedural MAE {mae:.2f} points on {len(both)} estimates "
              f"(shipped model {ship:.2f} on the same; all {shipped_mae:.2f})")
        record[name] = {"model": path.name, "model_sha256": digest, "procedural_mae": round(float(mae), 3),
                        "shipped_procedural_mae": round(float(ship), 3)}
        if abs(mae - ship) > CROSSFIT_MAE_TOLERANCE:
            failed.append(name)
    if failed:
        raise SystemExit(f"the cross-fitted models without {', '.join(failed)} do not err like the shipped model on "
                         f"the procedural segments (MAE more than {CROSSFIT_MAE_TOLERANCE} points apart): nothing "
                         "written (decision record 0152, rule 0)")
    parts = [df[~df["shard"].str.contains("mesh-")]]
    for manifest, data in datasets:
        key = hashlib.sha256("".join(sorted(sha256_file(p) for p in models.values())).encode()).hexdigest()[:12]
        cache = data / f"completion-estimates-crossfit-{key}-{steps_version()}.csv"
        parts.append(estimates(data, methods, cache, which="real").assign(manifest=manifest.stem))
    out = pd.concat(parts, ignore_index=True)
    for label, d in (("cross-fitted", out), ("by the shipped model", df)):
        real = d[d["shard"].str.contains("mesh-")]
        print(f"real colons' estimates {label}: MAE {100 * (real['estimate'] - real['true']).abs().mean():.2f} points, "
              f"bias {100 * (real['estimate'] - real['true']).mean():+.2f}")
    return out, record


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default="data", help="folder of the calibration's datasets (default: data)")
    ap.add_argument("--model", default=None, help="model (default: the shipped one)")
    ap.add_argument("--level", type=float, default=intervals.LEVEL)
    ap.add_argument("--workers", type=int, default=2, help="processes generating the data")
    ap.add_argument("--crossfit", nargs="+", metavar="COLON=MODEL", default=None,
                    help="the real colons' segments estimated by models that have not seen them (decision record 0152; "
                         "default: the committed ones, " + ", ".join(f"{n}={p.relative_to(ROOT)}" for n, p in
                                                                    CROSSFIT.items()) + ")")
    ap.add_argument("--no-crossfit", action="store_true", help="the shipped model estimates the real colons too")
    args = ap.parse_args()
    method = CompletionMethod(args.model)
    method.intervals = None
    path = model_path(args.model)
    parts = []
    datasets = calibration_data(Path(args.data), args.workers)
    for manifest, data in datasets:
        cache = data / f"completion-estimates-{sha256_file(path)[:12]}-{steps_version()}.csv"   # per model and steps
        parts.append(estimates(data, method, cache).assign(manifest=manifest.stem))
    shipped = pd.concat(parts, ignore_index=True)
    df, crossfit = shipped, None
    if not args.no_crossfit:
        df, crossfit = crossfitted(shipped, datasets, crossfit_models(args.crossfit or
                                                                      [f"{n}={p}" for n, p in CROSSFIT.items()]))
    print("segments per manifest:", df.drop_duplicates(["manifest", "shard", "index"])["manifest"].value_counts()
          .to_dict())
    print(f"{len(df)} estimates of {df[['manifest', 'shard', 'index']].drop_duplicates().shape[0]} segments; MAE "
          f"{100 * (df['estimate'] - df['true']).abs().mean():.2f} points")
    best, summary = choose("segments", {scheme: held_out(df, scheme, args.level) for scheme in SCHEMES}, args.level)
    best = best or "marginal"
    source = {"model": path.name, "model_sha256": sha256_file(path), "steps": steps_version(),
              "manifests": {m.name: sha256_file(m) for m in MANIFESTS}, "noise_mm": list(NOISE_MM),
              "segments": int(df[["manifest", "shard", "index"]].drop_duplicates().shape[0]), "estimates": len(df),
              "held_out": summary, **({"crossfit": crossfit} if crossfit else {})}
    cal = intervals.fit(df["true"], df["estimate"], signals(df), best, REVIEW_WIDTH, args.level, source)
    # segments whose length is known (colonbench estimate --length-mm, the map's segments): the estimate scaled where
    # the line stops short, as intervals.known_length does, and their own interval, on calibration.yaml's segments
    # only: on the extra real segments the scaling misfires (the line spans a median 70 % of a complete 70 mm real
    # segment), which says nothing of the map's segments this group also serves (decision record 0147)
    share = shipped["length_mm"] / shipped["segment_mm"]
    known = np.where(share < intervals.SHORT_SHARE, shipped["estimate"] * share, shipped["estimate"])
    first = (shipped["manifest"] == MANIFESTS[0].stem).to_numpy()
    for name, sel in ((MANIFESTS[0].name, first), ("all", np.ones(len(shipped), bool))):
        print(f"\nknown length, {name}: MAE {100 * np.abs(known[sel] - shipped['true'][sel]).mean():.2f} points "
              f"(unknown {100 * (shipped['estimate'][sel] - shipped['true'][sel]).abs().mean():.2f})")
    if not first.any():
        raise SystemExit(f"no estimates of {MANIFESTS[0].name} to fit the known-length interval on")
    intervals.fit_known(cal, shipped["true"][first], known[first])
    cal.source["known_manifests"] = [MANIFESTS[0].name]
    print(f"known-length interval width {100 * (cal.known['high'] - cal.known['low']):.1f} points")
    digest = hashlib.sha256(json.dumps(cal.to_json(), sort_keys=True).encode()).hexdigest()[:8]
    cal.source["id"] = f"{best}-{digest}"
    out = intervals.path_for(path)
    out.write_text(json.dumps(cal.to_json(), indent=1) + "\n")
    print(f"\nchosen: {best}; wrote {out} (id {cal.source['id']})")


if __name__ == "__main__":
    main()
