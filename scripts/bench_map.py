"""Speed of colonbench map on whole procedural colons: seconds per stage, per segment, peak memory.

Usage::

    python scripts/bench_map.py [--colons 2] [--segment-length 60] [--model small] [--context-model M] [--threads 2]

Each colon is a procedural colon of the default generator with sphere or
withdrawal-camera holes over its whole length at 2 points/mm^2
(``colonbench.datagen.wholecolon``),
mapped with the completion method and scored against its exact truth
(``colonbench.benchmark.colon_metrics``): whole-colon coverage beside the truth,
segment coverage MAE (points), centerline precision / recall at 2 mm.
"""

from __future__ import annotations

import argparse
import resource
import time

from colonbench.mapping import CONTEXT_MM


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--colons", type=int, default=2)
    parser.add_argument("--segment-length", type=float, default=60.0)
    parser.add_argument("--model", default=None)
    parser.add_argument("--context-model", default=None,
                        help="an in-context model for the margins above 0 (colonbench map --context-model)")
    parser.add_argument("--threads", type=int, default=2, help="torch threads (the CPU cores used)")
    parser.add_argument("--holes", default="spheres", choices=["spheres", "camera"],
                        help="whole-colon hole model (datagen.wholecolon)")
    parser.add_argument("--context-mm", type=float, nargs="+", default=[CONTEXT_MM],
                        help="context margins to compare on the same segments (0 = segment-only)")
    args = parser.parse_args()

    import torch

    from colonbench.benchmark.colon_metrics import map_metrics
    from colonbench.benchmark.registry import load_method
    from colonbench.datagen.colon import generate_colon
    from colonbench.datagen.wholecolon import whole_partial
    from colonbench.mapping.colonmap import map_colon
    from colonbench.mapping.segments import whole_coverage
    from colonbench.mapping.mapfiles import map_mesh, render_map

    torch.set_num_threads(args.threads)
    method = load_method("completion", model=args.model, context_model=args.context_model)
    print(f"{'colon':>5} {'context':>7} {'length mm':>9} {'points':>8} {'segs':>4} {'centerline s':>12} "
          f"{'cut s':>6} {'estimate s':>10} {'s/seg':>6} {'figure s':>8} {'total s':>7} {'coverage':>8} "
          f"{'truth':>6} {'seg MAE':>7} {'CL P/R @2mm':>11}")
    for colon_id in range(args.colons):
        colon = generate_colon(seed=0, colon_id=colon_id)
        partial = whole_partial(colon, seed=colon_id, holes=args.holes)
        for context in args.context_mm:
            t0 = time.perf_counter()
            result = map_colon(partial.points, method, segment_mm=args.segment_length,
                               positions=partial.positions, progress=False, context_mm=context)
            t1 = time.perf_counter()
            render_map(map_mesh(result["segments"]), f"bench_map_{colon_id}_context{context:g}.png")
            figure = time.perf_counter() - t1
            segments = result["segments"]
            score = map_metrics([s.row() for s in segments], whole_coverage(segments), result["centerline"],
                                colon.mesh.vertices, colon.mesh.faces, partial.observed, colon.centerline)
            sec = result["seconds"]
            n = len(segments)
            print(f"{colon_id:>5} {context:>7g} {colon.centerline.length:>9.0f} {len(partial.points):>8} {n:>4} "
                  f"{sec['centerline']:>12.2f} {sec['cut']:>6.2f} {sec['estimate']:>10.2f} "
                  f"{sec['estimate'] / n:>6.2f} {figure:>8.2f} {t1 - t0 + figure:>7.1f} "
                  f"{whole_coverage(segments):>8.3f} {score['whole_truth']:>6.3f} {score['segment_mae']:>7.2f} "
                  f"{score['centerline_precision']:>5.2f}/{score['centerline_recall']:.2f}")
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"peak memory {peak:.0f} MiB; pictures bench_map_*.png in the current folder")


if __name__ == "__main__":
    main()
