"""``colonbench video``: a rendered colonoscopy withdrawal as a frame dataset."""

from __future__ import annotations

from pathlib import Path

from colonbench.commands.common import add_colon_source, colon_from_args, finite, generator_config, non_negative, positive
from colonbench.errors import ColonbenchError


def _video_colon(args):
    """The colon of ``colonbench video``, its generator config, the seed, and where it came from."""
    if not args.manifest:
        if args.colon is not None:
            raise ColonbenchError("--colon picks a colon of a manifest; give the manifest first, or use --seed, "
                                  "--colon-id or --mesh")
        config = generator_config(args)
        source = ({"mesh": str(args.mesh), "centerline": args.centerline, "lumen": args.lumen} if args.mesh
                  else {"seed": args.seed, "colon_id": args.colon_id, "config": args.config})
        return colon_from_args(args, config), config, args.seed, source
    if args.mesh or args.config or args.centerline or args.lumen:
        raise ColonbenchError("a manifest names its colons and config; --mesh, --centerline, --lumen and --config go "
                              "without one")
    from colonbench.datagen.generate import GeneratorConfig, procedural_colon
    from colonbench.shards.build import check_mesh_files, mesh_colon
    from colonbench.shards.manifest import load, units

    resolved = load(args.manifest)
    config = GeneratorConfig.from_dict(resolved["config"])
    seed = resolved["seed"]
    names = {u.mesh: u for u in units(resolved, base=Path(args.manifest).parent) if u.mesh is not None}
    choice = args.colon
    if choice is None:
        first = next(iter(resolved["splits"].values()))
        choice = first.get("meshes", [None])[0] if first["colons"]["count"] == 0 else str(first["colons"]["first"])
    source = {"manifest": str(args.manifest), "colon": choice}
    if choice in names:
        check_mesh_files(names[choice])
        return mesh_colon(names[choice]), config, seed, source
    try:
        colon_id = int(choice)
    except ValueError:
        raise ColonbenchError(f"--colon {choice!r} is neither a procedural colon id nor one of the manifest's meshes "
                              f"({', '.join(sorted(names)) or 'it has none'})") from None
    return procedural_colon(config, seed, colon_id), config, seed, source


def cmd_video(args):
    """Render a colonoscopy withdrawal through a colon into a frame dataset."""
    from colonbench.video.framedata import write_video

    colon, config, seed, source = _video_colon(args)
    meta = write_video(colon, args.out, seed=seed, start_mm=args.start_mm, end_mm=args.end_mm, config=config.video,
                       size=args.size, fps=args.fps, face_ids=args.face_ids, max_frames=args.max_frames,
                       gif_seconds=args.gif_seconds, source=source, progress=not args.quiet)
    ms = {k: 1000 * v / max(meta["frames"], 1) for k, v in meta["seconds"].items()}
    print(f"{meta['frames']} frames ({meta['duration_s']:.1f} s of withdrawal over {meta['stretch_mm'][0]:.0f}-"
          f"{meta['stretch_mm'][1]:.0f} mm at {meta['fps']:g} frames/s, {meta['size_px']} px) -> {args.out}: "
          f"{meta['frames_per_second']:.1f} frames/s; per frame depth {ms['depth']:.0f} ms, visibility "
          f"{ms['visibility']:.0f} ms, RGB {ms['rgb']:.0f} ms, writing {ms['write']:.0f} ms")


def add_parsers(sub) -> None:
    """Add ``video`` to the ``colonbench`` subparsers."""
    p = sub.add_parser("video", help="render a colonoscopy withdrawal through a colon into a frame dataset: RGB, "
                                     "depth, TUM poses, intrinsics, per-frame visibility, the mesh, a GIF preview")
    p.add_argument("manifest", nargs="?", help="take the colon, its config and seed from this manifest (--colon picks "
                                               "which; default its first split's first colon)")
    p.add_argument("--colon", help="with a manifest: a procedural colon id or the name of one of its meshes")
    add_colon_source(p)
    p.add_argument("--out", required=True, help="dataset folder (docs/video.md: layout and conventions)")
    p.add_argument("--start-mm", type=finite, help="withdraw from this arc length (mm from the caecum; default 0)")
    p.add_argument("--end-mm", type=finite, help="to this arc length (default the colon's end)")
    p.add_argument("--fps", type=positive(float), default=15.0, help="frames per second of examination (default 15)")
    p.add_argument("--size", type=positive(int), default=256, help="frame side, px (default 256)")
    p.add_argument("--face-ids", action="store_true", help="also write the face under every pixel (faces/*.npz)")
    p.add_argument("--max-frames", type=positive(int), help="stop after this many frames")
    p.add_argument("--gif-seconds", type=non_negative, default=10.0,
                   help="length of preview.gif, s (0: none; default 10)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=cmd_video)
