"""``colonbench demo``: the main job on the demo-v1 suite (generate, evaluate every method, report) and a whole-colon map."""

from __future__ import annotations

import time
from pathlib import Path

from colonbench.commands.common import positive
from colonbench.errors import ColonbenchError


def cmd_demo(args):
    """The main job on demo.yaml: generate its test split, evaluate every method at both noise levels, report."""
    import shutil

    from colonbench.benchmark.evaluate import RunMismatch, evaluate
    from colonbench.benchmark.registry import DEFAULT_METHODS
    from colonbench.reports.leaderboard import write_leaderboard
    from colonbench.shards.dataset import generate

    manifest = Path(args.manifest)
    if not manifest.is_file():
        raise ColonbenchError(f"{manifest}: no such manifest; run the demo from a colonbench checkout (it uses "
                              "data_manifests/demo.yaml) or pass --manifest")
    out = Path(args.out)
    t0 = time.perf_counter()
    lock = generate(manifest, out / "data", workers=args.workers, splits=["test"], progress=not args.quiet)
    n = lock["splits"]["test"]["samples"]
    t1 = time.perf_counter()
    print(f"data: {n} test segments of {manifest.name} in {out / 'data'} ({t1 - t0:.0f} s)")
    kwargs = {"noise": (0.0, 0.5), "workers": args.workers, "model": args.model, "progress": not args.quiet}
    try:
        evaluate(out / "data", list(DEFAULT_METHODS), out / "run", **kwargs)
    except RunMismatch:  # the demo's own run, made with another model or version: make it again
        print(f"({out / 'run'} was made with another model or other settings; starting it again)")
        shutil.rmtree(out / "run")
        evaluate(out / "data", list(DEFAULT_METHODS), out / "run", **kwargs)
    t2 = time.perf_counter()
    print(f"evaluated {len(DEFAULT_METHODS)} methods at noise 0 and 0.5 mm ({t2 - t1:.0f} s)")
    result = write_leaderboard([out / "run"], out / "report")
    print(result["markdown"])
    print(f"report: {out / 'report'} ({', '.join(p.name for p in result['paths'])})")
    if not args.no_map:
        demo_map(out / "map", args.model, progress=not args.quiet)
    print(f"{time.perf_counter() - t0:.0f} s in all")


def demo_map(out: Path, model=None, progress: bool = True) -> None:
    """The demo's whole-colon map: a procedural colon with sphere holes, its withdrawal, colonbench map."""
    import numpy as np

    from colonbench.benchmark.colon_metrics import map_metrics
    from colonbench.benchmark.registry import load_method
    from colonbench.completion.method import DEFAULT_MODEL
    from colonbench.datagen.colon import generate_colon
    from colonbench.datagen.wholecolon import whole_partial
    from colonbench.mapping import CONTEXT_MM
    from colonbench.mapping.colonmap import map_colon
    from colonbench.mapping.mapfiles import write_map

    t0 = time.perf_counter()
    colon = generate_colon(seed=0, colon_id=0)
    partial = whole_partial(colon, seed=0)
    out.mkdir(parents=True, exist_ok=True)
    np.save(out / "reconstruction.npy", partial.points.astype(np.float32))
    np.save(out / "trajectory.npy", partial.positions)
    method = load_method("completion", model=model)
    result = map_colon(partial.points, method, positions=partial.positions, progress=progress, context_mm=CONTEXT_MM)
    _, summary = write_map(result, out, "completion", str(model or DEFAULT_MODEL), version=method.version)
    score = map_metrics([s.row() for s in result["segments"]], summary["coverage"], result["centerline"],
                        colon.mesh.vertices, colon.mesh.faces, partial.observed, colon.centerline)
    print(f"map: a {colon.centerline.length:.0f} mm colon with {len(partial.spheres)} sphere holes "
          f"({len(partial.points)} points): {summary['segments']} segments; whole-colon coverage "
          f"{summary['coverage']:.3f} (truth {score['whole_truth']:.3f}); segment coverage MAE "
          f"{score['segment_mae']:.1f} points; centerline P/R @2 mm {score['centerline_precision']:.2f} / "
          f"{score['centerline_recall']:.2f}; {out} ({time.perf_counter() - t0:.0f} s; the same as colonbench map "
          f"{out / 'reconstruction.npy'} --trajectory {out / 'trajectory.npy'} --out DIR)")


def add_parsers(sub) -> None:
    """Add ``demo`` to the ``colonbench`` subparsers."""
    p = sub.add_parser("demo", help="the main job on demo.yaml: generate, evaluate every method, leaderboard, figures")
    p.add_argument("--out", default="out/demo", help="output folder (default out/demo)")
    p.add_argument("--manifest", default="data_manifests/demo.yaml", help="manifest (default data_manifests/demo.yaml)")
    p.add_argument("--workers", type=positive(int), default=2, help="processes (default 2)")
    p.add_argument("--model", help="model .safetensors (default: the shipped one)")
    p.add_argument("--no-map", action="store_true", help="skip the whole-colon map (out/demo/map)")
    p.add_argument("--quiet", action="store_true", help="no progress bars")
    p.set_defaults(func=cmd_demo)
