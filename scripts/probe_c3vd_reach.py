"""What a C3VD suite's fused video partials reach of their truth (decision 0323): the build's video check on
synthetic sequences in C3VD's layout.

    python scripts/probe_c3vd_reach.py [--case tests|long|look] [--every 2 5] [--width-px 128] [--work DIR]
                                       [--fusion-at REV]

Writes (once, kept in ``--work``) a sequence with :mod:`colonbench.video.c3vd_synth`, builds its segment suite at
each ``--every`` and prints the video check ``built-suite.json`` records: the share of the video samples' observed
area within 1.5 mm of their fused surface, pooled, and the smallest sample's. ``--fusion-at REV`` fuses with
``video/c3vd_fusion.py`` as it was at git revision REV (importer version 1's one pinhole: the commit before
decision 0323's), the check unchanged. The cases:

- ``tests``: tests/test_c3vd.py's, a 130 mm phantom, 24 frames, C3VD's lens at 135 x 108;
- ``long``: a 420 mm phantom, 120 frames, 675 x 540 (the issue's sizes), the synthetic withdrawal as in the tests;
- ``look``: as ``long``, looking around more (tilt 60 degrees, not 25) past deeper folds (0.45 of the radius).
"""

from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

CASES = {"tests": {"length": 130.0, "frames": 24, "scale": 0.1},
         "long": {"length": 420.0, "frames": 120, "scale": 0.5},
         "look": {"length": 420.0, "frames": 120, "scale": 0.5, "tilt": 60.0, "fold": 0.45}}


def download(work: Path, case: str) -> Path:
    from colonbench.video.c3vd_synth import C3VD_CAMERA, phantom_tube, withdrawal_poses, write_sequence

    c = CASES[case]
    root = work / f"download-{case}"
    if not root.is_dir():
        mesh, line = phantom_tube(length_mm=c["length"], fold_depth=c.get("fold", 0.3))
        tmp = work / f"download-{case}.writing"
        shutil.rmtree(tmp, ignore_errors=True)
        write_sequence(tmp / "c1_cecum_t1_v1", mesh, withdrawal_poses(line, c["frames"], tilt_deg=c.get("tilt", 25.0)),
                       C3VD_CAMERA.scaled(c["scale"]))
        tmp.rename(root)
    return root


def fusion_at(rev: str, work: Path):
    """``fuse_sequence`` of ``video/c3vd_fusion.py`` at git revision ``rev``, at that revision's defaults."""
    import importlib.util

    text = subprocess.run(["git", "show", f"{rev}:video/c3vd_fusion.py"], capture_output=True, text=True, check=True,
                          cwd=Path(__file__).resolve().parents[1]).stdout
    path = work / f"c3vd_fusion_{rev}.py"
    path.write_text(text)
    spec = importlib.util.spec_from_file_location(f"c3vd_fusion_{rev}", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return lambda *a, **k: module.fuse_sequence(*a, **{**k, "width_px": module.WIDTH_PX})


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--case", choices=sorted(CASES), default="tests")
    ap.add_argument("--every", type=int, nargs="+", default=[2])
    ap.add_argument("--width-px", type=int, default=None)
    ap.add_argument("--work", default=str(Path(tempfile.gettempdir()) / "colonbench-c3vd-reach"))
    ap.add_argument("--fusion-at", metavar="REV", help="fuse as video/c3vd_fusion.py did at this git revision")
    args = ap.parse_args()
    from colonbench.benchmark.c3vd_suite import build

    work = Path(args.work)
    work.mkdir(parents=True, exist_ok=True)
    if args.fusion_at:
        import colonbench.video.c3vd_fusion as fusion

        fusion.fuse_sequence = fusion_at(args.fusion_at, work)
    root = download(work, args.case)
    for every in args.every:
        data = work / "suites"
        shutil.rmtree(data, ignore_errors=True)
        t = time.perf_counter()
        suite, _ = build(root, data, frames_every=every, width_px=args.width_px, progress=False)
        wall = time.perf_counter() - t
        (seq,) = json.loads((Path(suite.folder) / "built-suite.json").read_text())["source"]["sequences"].values()
        c = seq["video_check"]
        print(f"{args.case}, every {every}{', fusion at ' + args.fusion_at if args.fusion_at else ''}: reach "
              f"{c['reach']:.3f} (smallest sample {c['min_sample']:.3f}, {c['samples']} video samples; "
              f"{'passed' if c['passed'] else 'refused'}); the phantom's observed share {seq['observed_share']:.3f}; "
              f"{seq['fused_frames']} frames fused in {seq['seconds']['fuse']:.1f} s, build {wall:.1f} s", flush=True)
    sys.stdout.flush()


if __name__ == "__main__":
    main()
