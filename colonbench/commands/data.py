"""``colonbench colon``, ``segments``, ``picture``, ``generate``, ``verify`` and ``pack``: colons, samples and datasets."""

from __future__ import annotations

import json
import time
from pathlib import Path

from colonbench.commands.common import (add_colon_source, add_segment_args, colon_from_args, finite, generator_config,
                                        positive)
from colonbench.errors import ColonbenchError


def cmd_colon(args):
    """Write a procedural (or imported) colon: mesh, centerline and what was drawn."""
    config = generator_config(args)
    t = time.perf_counter()
    colon = colon_from_args(args, config)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    stem = f"colon_{args.colon_id:04d}" if not args.mesh else Path(args.mesh).stem
    colon.mesh.export(out / f"{stem}.ply")
    import numpy as np

    np.save(out / f"{stem}_centerline.npy", colon.centerline.points)
    (out / f"{stem}.json").write_text(json.dumps(
        {"seed": args.seed, "colon_id": args.colon_id, "length_mm": colon.centerline.length,
         "faces": int(len(colon.mesh.faces)), "area_mm2": float(colon.mesh.area), **colon.info}, indent=1))
    if args.picture:
        from colonbench.reports.pictures import colon_picture

        colon_picture(colon, out / f"{stem}.png", title=f"{stem}: {colon.centerline.length:.0f} mm")
    print(f"{stem}: {colon.centerline.length:.0f} mm, {len(colon.mesh.faces)} faces, "
          f"{time.perf_counter() - t:.1f} s -> {out}")


def cmd_segments(args):
    """Cut a colon into segments, draw hole permutations and write one folder per sample."""
    import colonbench.video  # noqa: F401 - registers the video hole model
    from colonbench.datagen.generate import colon_samples, write_sample_folder

    config = generator_config(args)
    if args.noise is not None:
        import dataclasses

        from colonbench.datagen.config import validate

        config = dataclasses.replace(config, segments=validate(
            dataclasses.replace(config.segments, noise_mm=args.noise)))
    colon = colon_from_args(args, config)
    segments = None if args.segment is None else [args.segment]
    out = Path(args.out)
    name = f"colon{args.colon_id:04d}" if not args.mesh else Path(args.mesh).stem
    written = 0
    for k, p, sample in colon_samples(colon, config, args.seed, args.colon_id, args.length, args.permutations,
                                      args.hole_model, segments):
        folder = out / f"{name}_l{args.length:g}_s{k:03d}_p{p:02d}"
        write_sample_folder(sample, folder, {"seed": args.seed, "colon_id": args.colon_id, "segment_id": k,
                                             "permutation": p, "length_mm": args.length})
        if args.picture:
            from colonbench.reports.pictures import segment_picture

            segment_picture(sample, folder / "picture.png")
        written += 1
        print(f"{folder.name}: coverage {sample.coverage:.3f}, {len(sample.hole_areas)} holes")
    if not written:
        raise ColonbenchError(f"the colon is too short for one segment of {args.length} mm")


def cmd_picture(args):
    """Write a picture of a colon, or of one of its segments (holes in red)."""
    config = generator_config(args)
    colon = colon_from_args(args, config)
    if args.segment is None:
        from colonbench.reports.pictures import colon_picture
        from colonbench.datagen.segments import windows

        wins = windows(colon.centerline.length, args.length, config.segments.end_margin_mm)
        colon_picture(colon, args.out, segments=wins)
    else:
        from colonbench.datagen.generate import colon_samples
        from colonbench.reports.pictures import segment_picture

        _, _, sample = next(colon_samples(colon, config, args.seed, args.colon_id, args.length, 1,
                                          args.hole_model, [args.segment]))
        segment_picture(sample, args.out)
    print(f"wrote {args.out}")


def cmd_generate(args):
    """Generate (or finish) the HDF5 shards of a manifest, then write the lock and statistics."""
    from colonbench.shards.dataset import LOCK_NAME, generate

    t = time.perf_counter()
    splits = None if args.splits is None else [s.strip() for s in args.splits.split(",") if s.strip()]
    lock = generate(args.manifest, args.out, workers=args.workers, scheduler=args.scheduler, splits=splits,
                    progress=not args.quiet, allow_version_mismatch=args.allow_version_mismatch)
    for split, info in lock["splits"].items():
        cov = info["statistics"]["coverage"]
        what = (f"{info['samples']} samples of {info['segments']} segments" if info["segments"] else
                f"{info['samples']} whole-colon reconstructions")
        print(f"{split}: {what} from {info['colons']} colons, {info['bytes'] / 2**20:.1f} MiB, "
              f"coverage mean {cov['mean']:.3f}")
    if lock["missing"]:
        print(f"{len(lock['missing'])} shard(s) of the manifest not generated (splits left out)")
    print(f"wrote {Path(args.out) / LOCK_NAME} in {time.perf_counter() - t:.1f} s")


def cmd_verify(args):
    """Check a dataset folder or shard: files present, checksums, schema; exit 1 naming each fault."""
    from colonbench.shards.verify import verify

    faults = verify(args.path, deep=not args.quick)
    if faults:
        for f in faults:
            print(f"FAULT {f}")
        print(f"{len(faults)} fault(s) in {args.path}")
        return 1
    print(f"{args.path}: OK")
    return 0


def cmd_pack(args):
    """Write a dataset's samples as compact voxel occupancies (a pack) for training on another machine."""
    from colonbench.mapping.contextpack import write_context_pack
    from colonbench.shards.pack import write_pack

    splits = [s.strip() for s in args.splits.split(",") if s.strip()]
    if args.context_line != "truth" and not args.context:
        raise ColonbenchError("--context-line is for context packs (--context)")
    if args.context:
        info = write_context_pack(args.data, args.out, splits, workers=args.workers, progress=not args.quiet,
                                  line=args.context_line)
    else:
        info = write_pack(args.data, args.out, splits, workers=args.workers, progress=not args.quiet)
    for split, meta in info["splits"].items():
        print(f"{split}: {meta['samples']} samples, {meta['bytes'] / 2**20:.1f} MiB "
              f"({meta['bytes'] / meta['samples'] / 1024:.1f} KiB/sample)"
              + ("" if args.context else ", the shards' grids copied" if meta.get("shard_format", 1) > 1
                 else ", heatmaps remade from the occupancies within "
                 f"{meta['max_heatmap_difference']:.1e} of the stored ones"))
    print(f"wrote {Path(args.out)}; train on it with colonbench train {args.out} --augment-prob 0 --flips ...")


def add_parsers(sub) -> None:
    """Add ``colon``, ``segments``, ``picture``, ``generate``, ``verify``, ``pack`` to the ``colonbench`` subparsers."""
    p = sub.add_parser("colon", help="write one colon (mesh PLY, centerline NPY, parameters JSON)")
    add_colon_source(p)
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("--picture", action="store_true", help="also write a PNG preview")
    p.set_defaults(func=cmd_colon)

    p = sub.add_parser("segments", help="cut a colon into segments with holes; one folder per sample")
    add_colon_source(p)
    p.add_argument("--out", required=True, help="output folder")
    add_segment_args(p, "only this segment index")
    p.add_argument("--permutations", type=positive(int), default=1, help="hole permutations per segment (default 1)")
    p.add_argument("--noise", type=finite, help="Gaussian noise sigma on the partial points, mm "
                   "(0.5 = the paper's noisy condition; default from the config, 0)")
    p.add_argument("--picture", action="store_true", help="also write a PNG per sample")
    p.set_defaults(func=cmd_segments)

    p = sub.add_parser("picture", help="write a picture of a colon or of one segment")
    add_colon_source(p)
    p.add_argument("--out", required=True, help="PNG file to write")
    add_segment_args(p, "show this segment with its holes instead of the whole colon")
    p.set_defaults(func=cmd_picture)

    p = sub.add_parser("generate", help="generate a dataset of HDF5 shards from a manifest (resumable)")
    p.add_argument("manifest", help="manifest YAML (see data_manifests/)")
    p.add_argument("--out", required=True, help="dataset folder (created; a rerun finishes what is missing)")
    p.add_argument("--workers", type=positive(int), default=1, help="local processes (default 1)")
    p.add_argument("--scheduler", help="Dask scheduler address (tcp://host:8786): make the shards on its workers, "
                   "which must see --out at the same path")
    p.add_argument("--splits", help="only these splits, comma-separated (e.g. test)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.add_argument("--allow-version-mismatch", action="store_true",
                   help="generate even if the manifest names another colonbench version")
    p.set_defaults(func=cmd_generate)

    p = sub.add_parser("verify", help="check a dataset folder (or one shard): checksums, schema, completeness")
    p.add_argument("path", help="dataset folder or .h5 shard")
    p.add_argument("--quick", action="store_true", help="checksums and counts only, skip reading every occupancy grid (format 1: heatmap)")
    p.set_defaults(func=cmd_verify)

    p = sub.add_parser("pack", help="write a dataset's samples as compact voxel occupancies (~5 KiB/sample) "
                                    "to train elsewhere")
    p.add_argument("data", help="dataset folder (colonbench generate)")
    p.add_argument("--out", required=True, help="pack folder to write")
    p.add_argument("--splits", default="train,validation", help="splits to pack (default train,validation)")
    p.add_argument("--workers", type=int, default=1, help="processes reading and checking shards (default 1)")
    p.add_argument("--context", action="store_true",
                   help="a whole-colon dataset (task: colon): cut its reconstructions into segments in context, "
                        "each with its slab, to train the in-context model (docs/mapping.md)")
    p.add_argument("--context-line", choices=("truth", "map"), default="truth",
                   help="--context: cut along the true centerline (default) or along the one colonbench map finds "
                        "in each noisy reconstruction, as inference sees it (docs/mapping.md)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=cmd_pack)
