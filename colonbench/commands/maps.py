"""``colonbench map``: the coverage map of a whole colon reconstruction."""

from __future__ import annotations

import sys
import time

from colonbench.commands.common import add_model_args, finite, note_dropped, positive
from colonbench.errors import ColonbenchError
from colonbench.mapping import CONTEXT_MM, SEGMENT_MM


def cmd_map(args):
    """A whole reconstruction's coverage map: centerline, segments, each segment's coverage, map files."""
    from colonbench.benchmark.registry import load_method
    from colonbench.completion.method import DEFAULT_MODEL
    from colonbench.mapping.colonmap import map_colon
    from colonbench.mapping.mapfiles import write_map
    from colonbench.mapping.inputs import check_trajectory, read_reconstruction, read_trajectory
    from colonbench.mapping.reach import partial_warning

    t0 = time.perf_counter()
    points, dropped = read_reconstruction(args.reconstruction)
    note_dropped(args.reconstruction, dropped)
    positions = None
    if args.trajectory:
        positions = read_trajectory(args.trajectory)
        check_trajectory(positions, points, str(args.trajectory))
    method = load_method(args.method, model=args.model, device=args.device, context_model=args.context_model,
                         tta=args.tta)
    if getattr(method, "uses_truth", False):
        raise ColonbenchError(f"method {method.name!r} is a reference that needs ground truth; it runs only in "
                              "colonbench evaluate")
    t1 = time.perf_counter()
    result = map_colon(points, method, segment_mm=args.segment_length, positions=positions,
                       progress=not args.quiet, context_mm=args.context_mm)
    result["seconds"] = {"read": t1 - t0, **result["seconds"]}
    # the methods built on the network share a predictor: they record the model they ran
    model = str(args.model or DEFAULT_MODEL) if hasattr(method, "predictor") else None
    paths, summary = write_map(result, args.out, method.name, model, figure=not args.no_figure,
                               version=str(getattr(method, "version", "")))
    segs = result["segments"]
    done = [s for s in segs if s.coverage is not None]
    print(f"{len(segs)} segments of {args.segment_length:g} mm over {summary['centerline_mm']:.0f} mm of centerline "
          f"({len(result['interruptions'])} interruption(s)); {len(done)} estimated; whole-colon coverage "
          f"{summary['coverage']}; orientation {result['orientation']}")
    for s in segs:
        cov = f"{s.coverage:.3f}" if s.coverage is not None else f"- ({s.error})"
        if s.coverage_interval is not None:
            cov += f" [{s.coverage_interval[0]:.3f}, {s.coverage_interval[1]:.3f}]"
        look = f"  REVIEW: {'; '.join(s.review)}" if s.review else ""
        print(f"  {s.index:3d}  {s.start_mm:7.1f}-{s.end_mm:7.1f} mm  {s.points:7d} points  coverage {cov}{look}")
    print(f"wrote {', '.join(p.name for p in paths)} to {args.out} ({time.perf_counter() - t0:.1f} s)")
    partial = partial_warning(summary, positions is not None)
    if partial:
        print(f"colonbench: warning: {partial}", file=sys.stderr)


def add_parsers(sub) -> None:
    """Add ``map`` to the ``colonbench`` subparsers."""
    p = sub.add_parser("map", help="coverage map of a whole colon reconstruction: segments, their coverage, a "
                                   "coloured mesh and picture")
    p.add_argument("reconstruction",
                   help="the reconstruction, mm: points or a mesh (.ply, .obj, .stl, .off, .npy, .xyz, .txt, .csv)")
    p.add_argument("--out", required=True, help="output folder: segments.json/.csv, centerline.npy, summary.json, "
                                                "map.ply, map.glb, map.png")
    p.add_argument("--segment-length", type=positive(float), default=SEGMENT_MM,
                   help=f"segment arc length, mm (default {SEGMENT_MM:g})")
    p.add_argument("--trajectory", help="camera positions of the run that made it, same frame and unit: a TUM "
                                        "trajectory (timestamp tx ty tz qx qy qz qw) or (k, 3) positions (.npy, "
                                        ".txt); the map is then numbered from the rectum (where it ends)")
    p.add_argument("--method", default="completion", help="method (default completion: the paper's)")
    p.add_argument("--context-mm", type=finite, default=CONTEXT_MM,
                   help="give the method the neighbours' points up to this far beyond each plane and count "
                        f"coverage on its completed surface between the planes only (default {CONTEXT_MM:g}; 0: "
                        "each segment alone, the paper's segment-only protocol)")
    add_model_args(p, "model .safetensors, or a shipped model by name (default: small)")
    p.add_argument("--context-model", help="an in-context model (.safetensors, or a shipped one by name) for "
                                           "the segments given context (--context-mm above 0): it sees the "
                                           "segment's planes; trained with colonbench pack --context "
                                           "(docs/mapping.md)")
    p.add_argument("--no-figure", action="store_true", help="skip map.png (the headless rendering)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=cmd_map)
