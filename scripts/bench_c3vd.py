"""Speed of ``colonbench suites build c3vd`` on a 1,000-frame sequence at C3VD's resolution (1350 x 1080).

    python scripts/bench_c3vd.py [--work DIR] [--frames 1000] [--frames-every K] [--workers 1] [--write-only]

Writes (once; kept in ``--work`` and reused) a synthetic registered sequence in C3VD's layout
(:mod:`colonbench.video.c3vd_synth`: a folded, bent 200 mm phantom tube of 104k faces, C3VD's own lens, every
pixel's ray cast; about 10 minutes on two cores), then builds its suite into an empty data root and prints the
wall time with its stages: reading the layout and hashing every file, reading the mesh and poses, the convention
check, the fusion of every K-th frame (default: the importer's), the centerline, cutting and writing the segments
(with the video check, whose figure it prints), and the signature.
"""

from __future__ import annotations

import argparse
import json
import logging
import shutil
import tempfile
import time
from pathlib import Path


def write(folder: Path, frames: int) -> None:
    from colonbench.progress import bar
    from colonbench.video.c3vd_synth import C3VD_CAMERA, phantom_tube, withdrawal_poses, write_sequence

    mesh, line = phantom_tube(length_mm=200.0, ring_mm=0.5, around=128)
    tmp = folder.with_name(folder.name + ".writing")
    shutil.rmtree(tmp, ignore_errors=True)
    with bar(total=frames, unit="frame", desc="write") as progress:    # a bar on a terminal, log lines in a log
        write_sequence(tmp / "c1_synthetic_t1_v1", mesh, withdrawal_poses(line, frames), C3VD_CAMERA,
                       progress=progress.update)
    tmp.rename(folder)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--work", default=str(Path(tempfile.gettempdir()) / "colonbench-c3vd-bench"))
    ap.add_argument("--frames", type=int, default=1000)
    ap.add_argument("--frames-every", type=int, default=None)
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument("--write-only", action="store_true", help="write the sequence (if missing), do not build")
    args = ap.parse_args()
    logging.basicConfig(level=logging.INFO, format="%(message)s")   # the progress lines where stderr is no terminal
    from colonbench.benchmark.c3vd_suite import build

    download = Path(args.work) / f"download-{args.frames}"
    if not download.is_dir():
        write(download, args.frames)
    if args.write_only:
        return
    data = Path(args.work) / "suites"
    shutil.rmtree(data, ignore_errors=True)
    t = time.perf_counter()
    suite, _ = build(download, data, frames_every=args.frames_every, workers=args.workers, progress=False)
    wall = time.perf_counter() - t
    from colonbench.benchmark import local_suites

    entry = json.loads((Path(suite.folder) / local_suites.FILE).read_text())
    (seq,) = entry["source"]["sequences"].values()
    stages = ", ".join(f"{k} {v:.1f} s" for k, v in seq["seconds"].items())
    check = seq["video_check"]
    print(f"{suite.id}: {suite.samples} samples from {seq['depth_frames']} frames of {seq['faces']} faces, "
          f"{seq['fused_frames']} fused (video check: {check['reach']:.1%} reached, "
          f"{'passed' if check['passed'] else 'refused'}); {wall:.1f} s wall: layout and hashes "
          f"{entry['digest_seconds']:.1f} s, {stages}, "
          f"lock and signature {wall - entry['digest_seconds'] - sum(seq['seconds'].values()):.1f} s")


if __name__ == "__main__":
    main()
