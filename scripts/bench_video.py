"""Speed of the rendered colonoscopy: frames/s of ``colonbench video`` by stage, and seconds per ``video`` partial.

Usage::

    python scripts/bench_video.py [--frames 60] [--size 256] [--segments 6]

1. Frames: a withdrawal through the default generator's colon 0 (seed 0), 300 mm
   onwards, written as a frame dataset (``colonbench.video.framedata``) into a
   temporary folder; prints frames/s and milliseconds per frame for depth and
   face ids (Embree), visibility, RGB (pyrender) and writing the PNGs.
2. Partials: ``--segments`` 60 mm segments of the same colon made with the
   ``video`` hole model (render, degrade, fuse, cut; ``colonbench.video.fusion``)
   and with the ``camera`` hole model; prints seconds per segment, frames fused,
   coverage, and the fused points' distance to the true surface.

Peak resident memory is printed at the end.
"""

from __future__ import annotations

import argparse
import resource
import tempfile
import time


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=60)
    parser.add_argument("--size", type=int, default=256)
    parser.add_argument("--segments", type=int, default=6)
    args = parser.parse_args()

    import numpy as np

    from colonbench import seeding
    from colonbench.datagen.camera import SurfaceScene
    from colonbench.video.framedata import write_video
    from colonbench.datagen.generate import GeneratorConfig, PreparedColon, procedural_colon
    from colonbench.datagen.sample import make_sample

    config = GeneratorConfig()
    t = time.perf_counter()
    colon = procedural_colon(config, 0, 0)
    print(f"colon: {colon.centerline.length:.0f} mm, {len(colon.mesh.faces)} faces ({time.perf_counter() - t:.1f} s)")
    with tempfile.TemporaryDirectory() as tmp:
        meta = write_video(colon, tmp, seed=0, start_mm=300.0, config=config.video, size=args.size, fps=15.0,
                           max_frames=args.frames, gif_seconds=0, progress=False)
    n, s = meta["frames"], meta["seconds"]
    print(f"frames: {n} at {args.size} px: {meta['frames_per_second']:.2f} frames/s in all ({s['total']:.1f} s, "
          f"set-up included); per frame: depth + face ids {1000 * s['depth'] / n:.0f} ms, visibility "
          f"{1000 * s['visibility'] / n:.0f} ms, RGB {1000 * s['rgb'] / n:.0f} ms, PNG writing "
          f"{1000 * s['write'] / n:.0f} ms")

    prepared = PreparedColon(colon)
    wins = prepared.windows(60.0, config.segments.end_margin_mm)
    picks = np.linspace(1, len(wins) - 2, args.segments).round().astype(int)
    rows = []
    for k in picks:
        surface = prepared.segment(*wins[k])
        truth = SurfaceScene(surface.mesh.vertices, surface.mesh.faces)
        row = {}
        for model in ("camera", "video"):
            t = time.perf_counter()
            sample = make_sample(seeding.rng(0, "bench-video", int(k)), prepared.scene, colon.centerline, surface,
                                 model, config.camera, config.spheres, config.segments, video=config.video)
            row[model] = (time.perf_counter() - t, sample)
        sec, v = row["video"]
        d = truth.distance(v.partial_points)
        info = v.info["video"]
        rows.append((sec, row["camera"][0]))
        print(f"segment {k:3d}: video {sec:5.1f} s ({info['frames_fused']}/{info['frames']} frames fused, coverage "
              f"{v.coverage:.3f}, fused points to the true wall: median {np.median(d):.2f} mm, 95 % "
              f"{np.percentile(d, 95):.2f} mm); camera {row['camera'][0]:.2f} s (coverage "
              f"{row['camera'][1].coverage:.3f})")
    sec = np.array(rows)
    print(f"video partials: {sec[:, 0].mean():.1f} s per segment (camera: {sec[:, 1].mean():.2f} s)")
    print(f"peak resident memory: {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MiB")


if __name__ == "__main__":
    main()
