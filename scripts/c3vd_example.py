"""Write a small synthetic download in C3VD's layout, to try ``colonbench suites build c3vd`` without the dataset.

    python scripts/c3vd_example.py DIR [--frames 40] [--scale 0.1]
    colonbench suites build c3vd --from DIR --data c3vd-try

Writes ``DIR/camera_intrinsics.txt`` and one registered sequence, ``DIR/c1_synthetic_t1_v1/`` (``coverage_mesh.obj``,
``pose.txt``, ``depth/NNNN_depth.tiff``), as C3VD's renderer writes them: a bent 130 mm phantom tube with folds,
withdrawn through by C3VD's own fisheye lens on a smaller image (``--scale`` of its 1350 x 1080 pixels), every
pixel's ray cast against the tube (:mod:`colonbench.video.c3vd_synth`, what the importer's tests read), so its
coverage map and depth are exact. It takes seconds. The suite built from it is not C3VD's data: it shows what the
importer checks, prints and builds, and scores nothing real.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

NAME = "c1_synthetic_t1_v1"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", metavar="DIR", help="folder to write the download into (new or empty)")
    ap.add_argument("--frames", type=int, default=40, help="frames of the withdrawal (default 40; at least 2)")
    ap.add_argument("--scale", type=float, default=0.1,
                    help="image size as a share of C3VD's 1350 x 1080 (default 0.1: 135 x 108 pixels)")
    args = ap.parse_args(argv)
    out = Path(args.out)
    if args.frames < 2 or not 0.02 <= args.scale <= 1.0:
        print(f"c3vd_example: --frames must be >= 2 and --scale in [0.02, 1]; got {args.frames}, {args.scale:g}",
              file=sys.stderr)
        return 2
    if out.exists() and (not out.is_dir() or any(out.iterdir())):
        print(f"c3vd_example: {out}: {'not empty' if out.is_dir() else 'a file'}; give a new folder", file=sys.stderr)
        return 2
    from colonbench.video.c3vd_synth import C3VD_CAMERA, phantom_tube, withdrawal_poses, write_sequence

    mesh, line = phantom_tube()
    camera = C3VD_CAMERA.scaled(args.scale)
    seen = write_sequence(out / NAME, mesh, withdrawal_poses(line, args.frames), camera)
    print(f"wrote {out}: {NAME}, {args.frames} frames of {camera.width} x {camera.height} pixels, "
          f"{seen.mean():.0%} of its {len(seen)} faces observed, and camera_intrinsics.txt\n"
          f"try: colonbench suites build c3vd --from {out} --data DATA")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
