"""Benchmark of the data generator: throughput, time per stage, peak memory, coverage distribution.

Usage::

    python scripts/bench_datagen.py [--colons 3] [--length 60] [--permutations 3] [--seed 0]

Prints colons/s, segments/s and samples/s, the time per stage (colon
generation, Embree scene, segment extraction, holes by camera and by spheres,
point sampling), peak resident memory, and the coverage distribution that the
default camera and sphere models produce (the distribution is set by the number
of poses, their spread and reach: see ``CameraConfig``).
"""

from __future__ import annotations

import argparse
import resource
import time
from collections import defaultdict

import numpy as np

from colonbench import seeding
from colonbench.datagen.camera import SurfaceScene
from colonbench.datagen.generate import GeneratorConfig, procedural_colon
from colonbench.datagen.sample import hole_areas, observe_covered
from colonbench.datagen.segments import segment_surface, windows
from colonbench.meshes import sample_surface


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--colons", type=int, default=3)
    ap.add_argument("--length", type=float, default=60.0)
    ap.add_argument("--permutations", type=int, default=3)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--config", help="generator config YAML")
    args = ap.parse_args()
    config = GeneratorConfig.from_yaml(args.config) if args.config else GeneratorConfig()

    stage = defaultdict(float)
    cover = defaultdict(list)
    n_holes = defaultdict(list)
    n_seg = n_samples = 0
    faces = []
    t_all = time.perf_counter()
    for i in range(args.colons):
        t = time.perf_counter()
        colon = procedural_colon(config, args.seed, i)
        stage["colon"] += time.perf_counter() - t
        faces.append(len(colon.mesh.faces))
        t = time.perf_counter()
        scene = SurfaceScene(colon.mesh.vertices, colon.mesh.faces)
        stage["scene"] += time.perf_counter() - t
        for k, (s0, s1) in enumerate(windows(colon.centerline.length, args.length, config.segments.end_margin_mm)):
            t = time.perf_counter()
            surf = segment_surface(scene, colon.centerline, s0, s1)
            stage["segment"] += time.perf_counter() - t
            n_seg += 1
            for p in range(args.permutations):
                for model in ("camera", "spheres"):
                    rng = seeding.rng(args.seed, "sample", i, k, p, model)
                    t = time.perf_counter()
                    obs, coverage, _ = observe_covered(rng, scene, colon.centerline, surf, model, config.camera,
                                                       config.spheres, config.segments.min_coverage)
                    stage[f"holes:{model}"] += time.perf_counter() - t
                    area = surf.mesh.area_faces
                    cover[model].append(coverage)
                    n_holes[model].append(len(hole_areas(surf.mesh, obs)))
                    t = time.perf_counter()
                    sample_surface(rng, surf.mesh.vertices, surf.mesh.faces[obs], config.segments.point_density,
                                   areas=area[obs])
                    sample_surface(rng, surf.mesh.vertices, surf.mesh.faces[~obs],
                                   config.segments.hole_point_density, areas=area[~obs])
                    stage["points"] += time.perf_counter() - t
                    n_samples += 1
    wall = time.perf_counter() - t_all
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024

    print(f"colons {args.colons}, segments {n_seg} of {args.length:g} mm, samples {n_samples} "
          f"({args.permutations} permutations x 2 hole models), mean faces/colon {np.mean(faces):.0f}")
    print(f"wall {wall:.1f} s on 1 process: {args.colons / wall:.3f} colons/s (whole pipeline), "
          f"{n_seg / wall:.2f} segments/s, {n_samples / wall:.2f} samples/s")
    print("time per stage:")
    per = {"colon": args.colons, "scene": args.colons, "segment": n_seg, "holes:camera": n_samples / 2,
           "holes:spheres": n_samples / 2, "points": n_samples}
    for name, sec in stage.items():
        print(f"  {name:14s} {sec:7.2f} s total  {1000 * sec / per[name]:8.1f} ms each")
    print(f"peak resident memory {peak:.0f} MiB")
    for model, values in cover.items():
        v = np.array(values)
        q = np.percentile(v, [5, 25, 50, 75, 95])
        hist, edges = np.histogram(v, bins=10, range=(0, 1))
        print(f"coverage [{model}]: mean {v.mean():.3f}, q5/25/50/75/95 {np.round(q, 3).tolist()}, "
              f"holes per sample median {np.median(n_holes[model]):.0f}")
        print("   histogram 0..1 by 0.1: " + " ".join(str(h) for h in hist))


if __name__ == "__main__":
    main()
