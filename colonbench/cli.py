"""The ``colonbench`` command line.

Errors in user input are printed as one line naming the problem
(``colonbench: error: ...``) with exit status 2; a traceback means a bug.
"""

from __future__ import annotations

import argparse
import json
import math
import shlex
import sys
import time
from pathlib import Path

from colonbench import __version__
from colonbench.errors import ColonbenchError
from colonbench.pointio import MESH_DENSITY


def _generator_config(args):
    from colonbench.datagen.generate import GeneratorConfig

    return GeneratorConfig.from_yaml(args.config) if args.config else GeneratorConfig()


def _colon_from_args(args, config):
    """A Colon: imported from ``--mesh`` or procedural from ``--seed/--colon-id``."""
    if args.mesh:
        from colonbench.datagen.realmesh import import_colon

        return import_colon(args.mesh, args.centerline, lumen=args.lumen)
    if args.centerline or args.lumen:
        raise ColonbenchError("--centerline and --lumen go with --mesh")
    from colonbench.datagen.generate import procedural_colon

    return procedural_colon(config, args.seed, args.colon_id)


def _add_colon_source(p):
    p.add_argument("--seed", type=int, default=0, help="root seed (default 0)")
    p.add_argument("--colon-id", type=int, default=0, help="which colon under the seed (default 0)")
    p.add_argument("--mesh", help="use a real colon surface (PLY/STL/OBJ/OFF, mm) instead of a procedural one")
    p.add_argument("--centerline", help="centerline of --mesh (.npy or text, (n, 3) mm); computed if omitted")
    p.add_argument("--lumen", action="store_true",
                   help="keep only what colonoscopy sees of --mesh: its lumen surface, remeshed at 1 mm, shells and "
                        "duplicates resolved, the --centerline (needed) re-centred; collapsed stretches are reported")
    p.add_argument("--config", help="generator config YAML (sections colon, camera, spheres, segments)")


def _finite(text: str) -> float:
    """A float argument that is a finite number (``nan`` and ``inf`` parse as floats and are refused here)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"must be a finite number, got {text}")
    return value


def _non_negative(text: str) -> float:
    """A finite float argument that is 0 or more."""
    value = _finite(text)
    if value < 0:
        raise argparse.ArgumentTypeError(f"must be 0 or more, got {text}")
    return value


def _positive(kind):
    def parse(text):
        try:
            value = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
        if not math.isfinite(value) or value <= 0:
            raise argparse.ArgumentTypeError(f"must be a positive number, got {text}")
        return value
    return parse


def _add_model_args(p, model_help):
    p.add_argument("--model", help=model_help)
    p.add_argument("--device", default="cpu", help="cpu, cuda, auto (default cpu)")


def _add_segment_args(p, segment_help):
    from colonbench.datagen.holes import HOLE_MODELS

    p.add_argument("--length", type=_positive(float), default=60.0, help="segment arc length, mm (default 60)")
    p.add_argument("--segment", type=int, help=segment_help)
    p.add_argument("--hole-model", default="camera", choices=HOLE_MODELS, help="how holes are made (default camera)")


def cmd_colon(args):
    """Write a procedural (or imported) colon: mesh, centerline and what was drawn."""
    config = _generator_config(args)
    t = time.perf_counter()
    colon = _colon_from_args(args, config)
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
        from colonbench.datagen.render import colon_picture

        colon_picture(colon, out / f"{stem}.png", title=f"{stem}: {colon.centerline.length:.0f} mm")
    print(f"{stem}: {colon.centerline.length:.0f} mm, {len(colon.mesh.faces)} faces, "
          f"{time.perf_counter() - t:.1f} s -> {out}")


def cmd_segments(args):
    """Cut a colon into segments, draw hole permutations and write one folder per sample."""
    from colonbench.datagen.generate import colon_samples, write_sample_folder

    config = _generator_config(args)
    if args.noise is not None:
        import dataclasses

        from colonbench.datagen.config import validate

        config = dataclasses.replace(config, segments=validate(
            dataclasses.replace(config.segments, noise_mm=args.noise)))
    colon = _colon_from_args(args, config)
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
            from colonbench.datagen.render import segment_picture

            segment_picture(sample, folder / "picture.png")
        written += 1
        print(f"{folder.name}: coverage {sample.coverage:.3f}, {len(sample.hole_areas)} holes")
    if not written:
        raise ColonbenchError(f"the colon is too short for one segment of {args.length} mm")


def cmd_picture(args):
    """Write a picture of a colon, or of one of its segments (holes in red)."""
    config = _generator_config(args)
    colon = _colon_from_args(args, config)
    if args.segment is None:
        from colonbench.datagen.render import colon_picture
        from colonbench.datagen.segments import windows

        wins = windows(colon.centerline.length, args.length, config.segments.end_margin_mm)
        colon_picture(colon, args.out, segments=wins)
    else:
        from colonbench.datagen.generate import colon_samples
        from colonbench.datagen.render import segment_picture

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


def cmd_train(args):
    """Train (or resume) the completion network on a generated dataset."""
    from colonbench.completion.train import TrainConfig, train

    cfg = TrainConfig(network=args.network, batch_size=args.batch_size, lr=args.lr, epochs=args.epochs,
                      augment_prob=args.augment_prob, seed=args.seed, workers=args.workers, flips=args.flips,
                      transposes=args.transposes, erase=args.erase, repeat=tuple(args.repeat or ()),
                      precision=args.precision,
                      checkpoint_minutes=args.checkpoint_minutes, max_minutes=args.max_minutes,
                      keep_epochs=args.keep_epochs, init=args.init, init_sha256=_model_sha256(args.init))
    command = "colonbench train " + " ".join(sys.argv[2:]) if len(sys.argv) > 2 else ""
    result = train(args.data, args.out, cfg, device=args.device, progress=not args.quiet, command=command)
    how = {"time": "time budget reached; run the same command to resume",
           "signal": "stopped on request; run the same command to resume"}.get(result["stopped"], "done")
    best = Path(args.out) / "best.safetensors"
    model = f"Model: {best}" if best.exists() else "No model yet: none is written before the first epoch ends"
    l2 = (f"best validation L2 {result['best_val_l2']:.5f}" if math.isfinite(result["best_val_l2"])
          else "not validated yet")
    print(f"{result['epochs']} epochs, {result['steps']} steps, {l2}, {result['seconds'] / 60:.1f} min in all: {how}. "
          f"{model}")


def cmd_average(args):
    """Average saved models' weights and recompute their batch-norm statistics (a model soup)."""
    from colonbench.completion.average import average_models, describe
    from colonbench.completion.method import model_path
    from colonbench.completion.network import load_model

    command = shlex.join(["colonbench", "average", *args.models, "--out", str(args.out), "--bn-data", *args.bn_data,
                          *(["--repeat", ",".join(map(str, args.repeat))] if args.repeat else []),
                          "--bn-samples", str(args.bn_samples), "--seed", str(args.seed)])  # whoever calls main()
    out = average_models([model_path(m) for m in args.models], args.out, args.bn_data, tuple(args.repeat or ()),
                         args.bn_samples, args.seed, command=command)
    print(f"{out}: {describe(load_model(out)[2])}")


def _repeats(text: str) -> tuple:
    """--repeat's comma-separated whole numbers >= 1."""
    try:
        values = tuple(int(v) for v in text.split(","))
    except ValueError:
        values = ()
    if not values or min(values) < 1:
        raise argparse.ArgumentTypeError(f"{text!r}: whole numbers >= 1, comma-separated, one per dataset")
    return values


def _note_dropped(path, dropped: int) -> None:
    """Say on stderr how many rows of a user's file were left out for not being finite (nothing for none)."""
    if dropped:
        print(f"colonbench: note: {path}: {dropped} point(s) that are NaN or infinite left out", file=sys.stderr)


def _model_sha256(model):
    """sha256 of a model file or shipped model's, None for None; a missing one is left for the command to report."""
    from colonbench.completion.method import model_path
    from colonbench.shards.schema import sha256_file

    path = model_path(model) if model is not None else None
    return sha256_file(path) if path is not None and path.is_file() else None


def cmd_pack(args):
    """Write a dataset's samples as compact voxel occupancies (a pack) for training on another machine."""
    from colonbench.shards.contextpack import write_context_pack
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
              + ("" if args.context else ", heatmaps remade from the occupancies within "
                 f"{meta['max_heatmap_difference']:.1e} of the stored ones"))
    print(f"wrote {Path(args.out)}; train on it with colonbench train {args.out} --augment-prob 0 --flips ...")


def estimate_name(path: Path) -> str:
    """Output name of an input: its folder's name for ``partial.ply``, else its stem."""
    return path.parent.resolve().name if path.name == "partial.ply" else path.stem


def write_estimate(out_dir: Path, name: str, est, model: str, **extra) -> Path:
    """Write ``<out_dir>/<name>.json`` (the estimate contract plus ``model`` and ``extra``) atomically."""
    path = Path(out_dir) / f"{name}.json"
    tmp = path.with_name(f".{path.name}.tmp")
    tmp.write_text(json.dumps({**extra, **est.to_json(), "model": model}))
    tmp.replace(path)
    return path


def cmd_estimate(args):
    """Estimate coverage, holes and centerline of partial segments; one JSON per input."""
    from colonbench.benchmark.registry import as_estimate, load_method
    from colonbench.datagen.generate import write_points_ply
    from colonbench.pointio import read_surface, write_mesh_ply

    files = [Path(f) for f in args.files]
    names = [estimate_name(f) for f in files]
    clash = sorted({n for n in names if names.count(n) > 1})
    if clash:
        raise ColonbenchError(f"several inputs would write the same output name(s) {clash}; "
                              "call estimate separately for them")
    method = load_method(args.method, model=args.model, device=args.device)  # loaded once for every file
    if getattr(method, "uses_truth", False):
        raise ColonbenchError(f"method {method.name!r} is a reference that needs ground truth; it runs only in "
                              "colonbench evaluate")
    out = Path(args.out_dir)
    out.mkdir(parents=True, exist_ok=True)
    failed = 0
    for f, name in zip(files, names):
        try:
            points, dropped = read_surface(f)          # its messages name the file
        except ColonbenchError as exc:
            print(f"colonbench: error: {exc}", file=sys.stderr)
            failed += 1
            continue
        _note_dropped(f, dropped)
        try:
            est = as_estimate(method.estimate(points), method.name)
        except ColonbenchError as exc:                  # the method's do not
            print(f"colonbench: error: {f}: {exc}", file=sys.stderr)
            failed += 1
            continue
        write_estimate(out, name, est, method.version, input=str(f))
        if args.mesh and len(est.mesh_faces):
            import numpy as np

            colors = np.where(est.hole_vertices[:, None], [[220, 30, 30]], [[200, 200, 200]])
            write_mesh_ply(out / f"{name}_mesh.ply", est.mesh_vertices, est.mesh_faces, colors)
            write_points_ply(out / f"{name}_centerline.ply", est.centerline)
        total = sum(est.seconds.values()) if est.seconds else float("nan")
        print(f"{name}: coverage {est.coverage:.3f}, {len(est.holes)} hole points, "
              f"centerline {len(est.centerline)} points, {total:.2f} s")
    if failed:
        rest = "nothing was written" if failed == len(files) else "the others were written"
        raise ColonbenchError(f"{failed} of {len(files)} input(s) failed (see above); {rest}")


def _floats(text: str) -> list[float]:
    try:
        return [_finite(x) for x in text.split(",") if x.strip()]
    except argparse.ArgumentTypeError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a comma-separated list of finite numbers") from None


def _method_list(text: str) -> list[str]:
    from colonbench.benchmark.registry import DEFAULT_METHODS

    names = [m.strip() for m in text.split(",") if m.strip()]
    return list(DEFAULT_METHODS) if names == ["all"] else names


def cmd_evaluate(args):
    """Evaluate methods on a dataset's test shards into a run folder (resumable)."""
    from colonbench.benchmark.colon_evaluate import dataset_task
    from colonbench.benchmark.evaluate import evaluate, load_results
    from colonbench.benchmark.summary import summarize

    made_for = dataset_task(args.data)
    task = args.task or made_for
    if task != made_for:
        raise ColonbenchError(f"{args.data} is a {made_for} dataset; --task {task} needs a "
                              f"{'task: colon' if task == 'colon' else 'segment'} manifest's data")
    if task == "colon":
        return _evaluate_colons(args)
    if args.context_model:
        raise ColonbenchError("--context-model is for whole-colon maps (--task colon), where segments have planes "
                              "and context; the segment benchmark keeps the paper's protocol")
    t = time.perf_counter()
    run = evaluate(args.data, _method_list(args.methods), args.out, noise=args.noise, split=args.split,
                   limit=args.limit, workers=args.workers, model=args.model, device=args.device,
                   examples=args.examples, noise_seed=args.noise_seed, progress=not args.quiet)
    meta, results = load_results(run)
    s = summarize(results)
    for _, r in s.iterrows():
        failed = f", {r['failed']} failed" if r["failed"] else ""
        print(f"noise {r['noise_mm']:g} mm  {r['method']:<14} MAE {r['coverage_mae']:6.2f} points over "
              f"{r['segments'] - r['coverage_undefined']} of {r['segments']} segments{failed}")
    errors = results[results["error"] != ""]
    for name, g in errors.groupby("method"):
        print(f"colonbench: warning: {name} failed on {len(g)} segment(s); first: {g['error'].iloc[0]}",
              file=sys.stderr)
    session = meta["sessions"][-1]
    print(f"wrote {run}/results/: {session['segments']} segment evaluations in {time.perf_counter() - t:.0f} s "
          f"with {session['workers']} worker(s), peak memory {session['peak_process_mib']} MiB per process; "
          f"tables: colonbench leaderboard {run} --out DIR")


def _evaluate_colons(args):
    """colonbench evaluate --task colon: map every whole-colon sample with every method and track."""
    from colonbench.benchmark.colon_evaluate import ALL_METHODS, evaluate_colons, load_colon_results
    from colonbench.reports.colon_leaderboard import colon_table

    t = time.perf_counter()
    methods = list(ALL_METHODS) if args.methods == "all" else _method_list(args.methods)
    run = evaluate_colons(args.data, methods, args.out, noise=args.noise, contexts=args.contexts,
                          segment_mm=args.segment_length, split=args.split, limit=args.limit, workers=args.workers,
                          model=args.model, device=args.device, noise_seed=args.noise_seed,
                          progress=not args.quiet, context_model=args.context_model)
    meta, segments, colons = load_colon_results(run)
    tab = colon_table(segments, colons)
    for _, r in tab.iterrows():
        print(f"noise {r['noise_mm']:g} mm  {r['method']:<13} {r['track']:<14} segment MAE {r['segment_mae']:6.2f} "
              f"points over {r['segments']} segments, whole colon |error| {r['whole_mae']:5.2f} points")
    print(f"wrote {run}/results/ in {time.perf_counter() - t:.0f} s; tables: colonbench leaderboard {run} --out DIR")


def cmd_leaderboard(args):
    """Rebuild the leaderboard tables (and figures) from stored runs."""
    from colonbench.reports.leaderboard import write_leaderboard

    result = write_leaderboard(args.runs, args.out, figures=not args.no_figures)
    print(result["markdown"])
    print(f"wrote {', '.join(p.name for p in result['paths'])} to {args.out}")


def cmd_methods(args):
    """List the registered methods."""
    from colonbench.benchmark.registry import available

    for name, target in sorted(available().items()):
        print(f"{name:<14} {target}")


def cmd_map(args):
    """A whole reconstruction's coverage map: centerline, segments, each segment's coverage, map files."""
    from colonbench.benchmark.registry import load_method
    from colonbench.completion.method import DEFAULT_MODEL
    from colonbench.mapping.colonmap import map_colon, write_map
    from colonbench.mapping.inputs import check_trajectory, read_reconstruction, read_trajectory

    t0 = time.perf_counter()
    points, dropped = read_reconstruction(args.reconstruction)
    _note_dropped(args.reconstruction, dropped)
    positions = None
    if args.trajectory:
        positions = read_trajectory(args.trajectory)
        check_trajectory(positions, points, str(args.trajectory))
    method = load_method(args.method, model=args.model, device=args.device, context_model=args.context_model)
    if getattr(method, "uses_truth", False):
        raise ColonbenchError(f"method {method.name!r} is a reference that needs ground truth; it runs only in "
                              "colonbench evaluate")
    t1 = time.perf_counter()
    result = map_colon(points, method, segment_mm=args.segment_length, positions=positions,
                       progress=not args.quiet, context_mm=args.context_mm)
    result["seconds"] = {"read": t1 - t0, **result["seconds"]}
    # the methods built on the network share a predictor: they record the model they ran
    model = str(args.model or DEFAULT_MODEL) if hasattr(method, "predictor") else None
    paths, summary = write_map(result, args.out, method.name, model, figure=not args.no_figure)
    segs = result["segments"]
    done = [s for s in segs if s.coverage is not None]
    print(f"{len(segs)} segments of {args.segment_length:g} mm over {summary['centerline_mm']:.0f} mm of centerline "
          f"({len(result['interruptions'])} interruption(s)); {len(done)} estimated; whole-colon coverage "
          f"{summary['coverage']}; orientation {result['orientation']}")
    for s in segs:
        cov = f"{s.coverage:.3f}" if s.coverage is not None else f"- ({s.error})"
        print(f"  {s.index:3d}  {s.start_mm:7.1f}-{s.end_mm:7.1f} mm  {s.points:7d} points  coverage {cov}")
    print(f"wrote {', '.join(p.name for p in paths)} to {args.out} ({time.perf_counter() - t0:.1f} s)")


def _video_colon(args):
    """The colon of ``colonbench video``, its generator config, the seed, and where it came from."""
    if not args.manifest:
        if args.colon is not None:
            raise ColonbenchError("--colon picks a colon of a manifest; give the manifest first, or use --seed, "
                                  "--colon-id or --mesh")
        config = _generator_config(args)
        source = ({"mesh": str(args.mesh), "centerline": args.centerline, "lumen": args.lumen} if args.mesh
                  else {"seed": args.seed, "colon_id": args.colon_id, "config": args.config})
        return _colon_from_args(args, config), config, args.seed, source
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
    from colonbench.datagen.framedata import write_video

    colon, config, seed, source = _video_colon(args)
    meta = write_video(colon, args.out, seed=seed, start_mm=args.start_mm, end_mm=args.end_mm, config=config.video,
                       size=args.size, fps=args.fps, face_ids=args.face_ids, max_frames=args.max_frames,
                       gif_seconds=args.gif_seconds, source=source, progress=not args.quiet)
    ms = {k: 1000 * v / max(meta["frames"], 1) for k, v in meta["seconds"].items()}
    print(f"{meta['frames']} frames ({meta['duration_s']:.1f} s of withdrawal over {meta['stretch_mm'][0]:.0f}-"
          f"{meta['stretch_mm'][1]:.0f} mm at {meta['fps']:g} frames/s, {meta['size_px']} px) -> {args.out}: "
          f"{meta['frames_per_second']:.1f} frames/s; per frame depth {ms['depth']:.0f} ms, visibility "
          f"{ms['visibility']:.0f} ms, RGB {ms['rgb']:.0f} ms, writing {ms['write']:.0f} ms")


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
    from colonbench.mapping.colonmap import CONTEXT_MM, map_colon, write_map

    t0 = time.perf_counter()
    colon = generate_colon(seed=0, colon_id=0)
    partial = whole_partial(colon, seed=0)
    out.mkdir(parents=True, exist_ok=True)
    np.save(out / "reconstruction.npy", partial.points.astype(np.float32))
    np.save(out / "trajectory.npy", partial.positions)
    result = map_colon(partial.points, load_method("completion", model=model), positions=partial.positions,
                       progress=progress, context_mm=CONTEXT_MM)
    _, summary = write_map(result, out, "completion", str(model or DEFAULT_MODEL))
    score = map_metrics([s.row() for s in result["segments"]], summary["coverage"], result["centerline"],
                        colon.mesh.vertices, colon.mesh.faces, partial.observed, colon.centerline)
    print(f"map: a {colon.centerline.length:.0f} mm colon with {len(partial.spheres)} sphere holes "
          f"({len(partial.points)} points): {summary['segments']} segments; whole-colon coverage "
          f"{summary['coverage']:.3f} (truth {score['whole_truth']:.3f}); segment coverage MAE "
          f"{score['segment_mae']:.1f} points; centerline P/R @2 mm {score['centerline_precision']:.2f} / "
          f"{score['centerline_recall']:.2f}; {out} ({time.perf_counter() - t0:.0f} s; the same as colonbench map "
          f"{out / 'reconstruction.npy'} --trajectory {out / 'trajectory.npy'} --out DIR)")


def build_parser() -> argparse.ArgumentParser:
    from colonbench.mapping.colonmap import CONTEXT_MM, SEGMENT_MM

    parser = argparse.ArgumentParser(
        prog="colonbench",
        description="Synthetic colonoscopy coverage data and a benchmark of coverage-estimation methods. "
                    "All geometry is in millimetres.")
    parser.add_argument("--version", action="version", version=f"colonbench {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")

    p = sub.add_parser("colon", help="write one colon (mesh PLY, centerline NPY, parameters JSON)")
    _add_colon_source(p)
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("--picture", action="store_true", help="also write a PNG preview")
    p.set_defaults(func=cmd_colon)

    p = sub.add_parser("segments", help="cut a colon into segments with holes; one folder per sample")
    _add_colon_source(p)
    p.add_argument("--out", required=True, help="output folder")
    _add_segment_args(p, "only this segment index")
    p.add_argument("--permutations", type=_positive(int), default=1, help="hole permutations per segment (default 1)")
    p.add_argument("--noise", type=_finite, help="Gaussian noise sigma on the partial points, mm "
                   "(0.5 = the paper's noisy condition; default from the config, 0)")
    p.add_argument("--picture", action="store_true", help="also write a PNG per sample")
    p.set_defaults(func=cmd_segments)

    p = sub.add_parser("picture", help="write a picture of a colon or of one segment")
    _add_colon_source(p)
    p.add_argument("--out", required=True, help="PNG file to write")
    _add_segment_args(p, "show this segment with its holes instead of the whole colon")
    p.set_defaults(func=cmd_picture)

    p = sub.add_parser("generate", help="generate a dataset of HDF5 shards from a manifest (resumable)")
    p.add_argument("manifest", help="manifest YAML (see data_manifests/)")
    p.add_argument("--out", required=True, help="dataset folder (created; a rerun finishes what is missing)")
    p.add_argument("--workers", type=_positive(int), default=1, help="local processes (default 1)")
    p.add_argument("--scheduler", help="Dask scheduler address (tcp://host:8786): make the shards on its workers, "
                   "which must see --out at the same path")
    p.add_argument("--splits", help="only these splits, comma-separated (e.g. test)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.add_argument("--allow-version-mismatch", action="store_true",
                   help="generate even if the manifest names another colonbench version")
    p.set_defaults(func=cmd_generate)

    p = sub.add_parser("verify", help="check a dataset folder (or one shard): checksums, schema, completeness")
    p.add_argument("path", help="dataset folder or .h5 shard")
    p.add_argument("--quick", action="store_true", help="checksums and counts only, skip reading every heatmap")
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

    p = sub.add_parser("train", help="train (or resume) the completion network on generated shards or a pack")
    p.add_argument("data", nargs="+", help="dataset folder with train and validation splits (colonbench generate), "
                                           "or a pack of one (colonbench pack); several dataset folders (same grid) "
                                           "train together")
    p.add_argument("--out", required=True, help="run folder: log.csv, last.pt, best.safetensors; rerun to resume")
    p.add_argument("--network", default="small", help="network configuration: small (CPU) or large (GPU)")
    p.add_argument("--epochs", type=_positive(int), default=100, help="epochs in all (default 100)")
    p.add_argument("--batch-size", type=_positive(int), default=4, help="samples per step per process (default 4)")
    p.add_argument("--lr", type=_positive(float), default=1e-3, help="Adam learning rate (default 1e-3)")
    p.add_argument("--augment-prob", type=_finite, default=0.3,
                   help="share of samples augmented on the fly (default 0.3)")
    p.add_argument("--flips", action="store_true",
                   help="flip each sample's grid axes at random (exact augmentation; the only geometric one "
                        "for a pack)")
    p.add_argument("--transposes", type=_finite, default=0.0, metavar="P",
                   help="share of the training samples whose grid axes are exchanged (one of the five other orders, "
                        "each as likely; exact, like --flips): the tube then runs along another axis than the "
                        "first, which the grid always gives it (default 0)")
    p.add_argument("--erase", type=_finite, default=0.0, metavar="P",
                   help="share of a pack's training samples whose partial surface loses 1-3 ball-shaped patches "
                        "before its input heatmap is made: larger holes to complete (default 0)")
    p.add_argument("--repeat", type=_repeats, default=None, metavar="N,N,...",
                   help="times each dataset's training samples come up per epoch, one whole number per dataset in "
                        "the order given (default 1 each): e.g. 1,8 gives a small real-colon set eight times its "
                        "share beside a large procedural one")
    p.add_argument("--seed", type=int, default=0, help="seed of weights, sample order and augmentations")
    p.add_argument("--precision", choices=("fp32", "bf16"), default="fp32",
                   help="arithmetic of the forward pass in training: bf16 (autocast; weights and loss float32) "
                        "runs 2-3x faster on CPUs with AMX or AVX512-BF16 and on recent GPUs, slower on CPUs "
                        "without them (default fp32)")
    p.add_argument("--init", help="start from this model's weights (.safetensors or a shipped model's name, same "
                                  "network) instead of random ones: fine-tuning; its sha256 is recorded")
    p.add_argument("--workers", type=int, default=1,
                   help="DataLoader worker processes that read the shards, or on the CPU make a pack's batches while "
                        "the step runs (default 1)")
    p.add_argument("--device", default="auto", help="auto, cpu, cuda, cuda:1, ... (default auto)")
    p.add_argument("--max-minutes", type=_positive(float), help="stop cleanly after this long (resume later)")
    p.add_argument("--checkpoint-minutes", type=_positive(float), default=10.0,
                   help="rewrite last.pt this often (default 10)")
    p.add_argument("--keep-epochs", action="store_true",
                   help="also keep every epoch's weights (epoch-NNN.safetensors), to choose one afterwards by "
                        "the validation split's coverage error (colonbench evaluate DATA --split validation)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=cmd_train)

    p = sub.add_parser("average", help="average the weights of saved models of one network (a model soup), "
                                       "batch norm recomputed on training packs")
    p.add_argument("models", nargs="+", help="two or more .safetensors models (or shipped models by name), one "
                                             "network and grid, e.g. the epochs a run kept with --keep-epochs")
    p.add_argument("--out", required=True, help="the averaged model's .safetensors file")
    p.add_argument("--bn-data", nargs="+", required=True, metavar="PACK",
                   help="packs (colonbench pack) whose training samples recompute the batch-norm statistics: those "
                        "the models trained on")
    p.add_argument("--repeat", type=_repeats, default=None, metavar="N,N,...",
                   help="weights of the packs' samples, as colonbench train --repeat (default 1 each)")
    p.add_argument("--bn-samples", type=_positive(int), default=1000,
                   help="training samples for the batch-norm statistics (default 1000)")
    p.add_argument("--seed", type=int, default=0, help="seed of the samples drawn (default 0)")
    p.set_defaults(func=cmd_average)

    p = sub.add_parser("estimate", help="estimate coverage, holes and centerline of partial segments (mm)")
    p.add_argument("files", nargs="+", help="partial segments, mm, one each: point clouds (.ply, .npy, .xyz, .txt, "
                   ".csv) "
                   f"or meshes (.ply, .obj, .stl, .off; sampled on their faces at {MESH_DENSITY:g} points/mm^2)")
    p.add_argument("--out-dir", required=True, help="folder for <name>.json per input")
    p.add_argument("--method", default="completion", help="method (default completion: the paper's)")
    _add_model_args(p, "model .safetensors from colonbench train, or a shipped model by name: small (the default), "
                       "small-0.5 (the 0.5 model, before averaging its lineage's checkpoints), "
                       "small-0.4 (the 0.4 model, before a fourth epoch and real colons weighted 12x), "
                       "small-0.3 (the 0.3 model, before wide.yaml's 18,000 training segments), "
                       "small-0.2 (the 0.2 model, before more real-colon training), small-0.1 (the 0.1 model, "
                       "trained on paper-style colons only)")
    p.add_argument("--mesh", action="store_true",
                   help="also write <name>_mesh.ply (completed mesh, holes red) and <name>_centerline.ply")
    p.set_defaults(func=cmd_estimate)

    p = sub.add_parser("map", help="coverage map of a whole colon reconstruction: segments, their coverage, a "
                                   "coloured mesh and picture")
    p.add_argument("reconstruction",
                   help="the reconstruction, mm: points or a mesh (.ply, .obj, .stl, .off, .npy, .xyz, .txt, .csv)")
    p.add_argument("--out", required=True, help="output folder: segments.json/.csv, centerline.npy, summary.json, "
                                                "map.ply, map.glb, map.png")
    p.add_argument("--segment-length", type=_positive(float), default=SEGMENT_MM,
                   help=f"segment arc length, mm (default {SEGMENT_MM:g})")
    p.add_argument("--trajectory", help="camera positions of the run that made it, same frame and unit: a TUM "
                                        "trajectory (timestamp tx ty tz qx qy qz qw) or (k, 3) positions (.npy, "
                                        ".txt); the map is then numbered from the rectum (where it ends)")
    p.add_argument("--method", default="completion", help="method (default completion: the paper's)")
    p.add_argument("--context-mm", type=_finite, default=CONTEXT_MM,
                   help="give the method the neighbours' points up to this far beyond each plane and count "
                        f"coverage on its completed surface between the planes only (default {CONTEXT_MM:g}; 0: "
                        "each segment alone, the paper's segment-only protocol)")
    _add_model_args(p, "model .safetensors, or a shipped model by name (default: small)")
    p.add_argument("--context-model", help="an in-context model (.safetensors, or a shipped one by name) for "
                                           "the segments given context (--context-mm above 0): it sees the "
                                           "segment's planes; trained with colonbench pack --context "
                                           "(docs/mapping.md)")
    p.add_argument("--no-figure", action="store_true", help="skip map.png (the headless rendering)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=cmd_map)

    p = sub.add_parser("video", help="render a colonoscopy withdrawal through a colon into a frame dataset: RGB, "
                                     "depth, TUM poses, intrinsics, per-frame visibility, the mesh, a GIF preview")
    p.add_argument("manifest", nargs="?", help="take the colon, its config and seed from this manifest (--colon picks "
                                               "which; default its first split's first colon)")
    p.add_argument("--colon", help="with a manifest: a procedural colon id or the name of one of its meshes")
    _add_colon_source(p)
    p.add_argument("--out", required=True, help="dataset folder (docs/video.md: layout and conventions)")
    p.add_argument("--start-mm", type=_finite, help="withdraw from this arc length (mm from the caecum; default 0)")
    p.add_argument("--end-mm", type=_finite, help="to this arc length (default the colon's end)")
    p.add_argument("--fps", type=_positive(float), default=15.0, help="frames per second of examination (default 15)")
    p.add_argument("--size", type=_positive(int), default=256, help="frame side, px (default 256)")
    p.add_argument("--face-ids", action="store_true", help="also write the face under every pixel (faces/*.npz)")
    p.add_argument("--max-frames", type=_positive(int), help="stop after this many frames")
    p.add_argument("--gif-seconds", type=_non_negative, default=10.0,
                   help="length of preview.gif, s (0: none; default 10)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=cmd_video)

    p = sub.add_parser("evaluate", help="run methods over a dataset's test shards into a run folder (resumable)")
    p.add_argument("data", help="dataset folder (colonbench generate)")
    p.add_argument("--methods", default="all",
                   help="comma-separated registered names or package.module:Class (default all: "
                        "the paper's method, its baselines and the reference rows; see colonbench methods)")
    p.add_argument("--noise", type=_floats, default=[0.0, 0.5],
                   help="input noise sigmas, mm, comma-separated (default 0,0.5)")
    p.add_argument("--out", required=True, help="run folder (a rerun finishes it or adds methods)")
    p.add_argument("--split", default="test", help="split to evaluate (default test)")
    p.add_argument("--limit", type=_positive(int), help="only this many samples, spread evenly over the split")
    p.add_argument("--workers", type=_positive(int), default=1, help="processes (default 1)")
    _add_model_args(p, "model .safetensors for the methods built on the network, or a shipped model by name "
                       "(default: small)")
    p.add_argument("--examples", type=int, default=3, help="segments whose meshes are kept for figures (default 3)")
    p.add_argument("--noise-seed", type=int, default=0, help="root seed of the input noise (default 0)")
    p.add_argument("--task", choices=["segments", "colon"],
                   help="segments (the paper's protocol) or colon (whole-colon maps, docs/mapping.md); "
                        "default: what the dataset was made for")
    p.add_argument("--contexts", type=_floats, default=[0.0, CONTEXT_MM],
                   help=f"--task colon: context margins, one track each, mm (0 = segment-only; default 0,"
                        f"{CONTEXT_MM:g})")
    p.add_argument("--segment-length", type=_finite, default=SEGMENT_MM,
                   help=f"--task colon: segment arc length of the maps, mm (default {SEGMENT_MM:g})")
    p.add_argument("--context-model", help="--task colon: an in-context model for the tracks with context (the "
                                           "segment-only track keeps --model; docs/mapping.md)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=cmd_evaluate)

    p = sub.add_parser("leaderboard", help="tables (md, csv, json) and figures from stored runs on the same data")
    p.add_argument("runs", nargs="+", help="run folders (colonbench evaluate)")
    p.add_argument("--out", required=True, help="folder for leaderboard.md/.csv/.json and the figures")
    p.add_argument("--no-figures", action="store_true", help="tables only")
    p.set_defaults(func=cmd_leaderboard)

    p = sub.add_parser("methods", help="list the registered coverage-estimation methods")
    p.set_defaults(func=cmd_methods)

    p = sub.add_parser("demo", help="the main job on demo.yaml: generate, evaluate every method, leaderboard, figures")
    p.add_argument("--out", default="out/demo", help="output folder (default out/demo)")
    p.add_argument("--manifest", default="data_manifests/demo.yaml", help="manifest (default data_manifests/demo.yaml)")
    p.add_argument("--workers", type=_positive(int), default=2, help="processes (default 2)")
    p.add_argument("--model", help="model .safetensors (default: the shipped one)")
    p.add_argument("--no-map", action="store_true", help="skip the whole-colon map (out/demo/map)")
    p.add_argument("--quiet", action="store_true", help="no progress bars")
    p.set_defaults(func=cmd_demo)
    return parser


def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 0
    try:
        status = args.func(args)
    except ColonbenchError as exc:
        print(f"colonbench: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("colonbench: interrupted", file=sys.stderr)
        return 130
    return int(status or 0)


if __name__ == "__main__":
    sys.exit(main())
