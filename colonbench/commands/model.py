"""``colonbench train``, ``average`` and ``estimate``: the completion network trained, averaged and run on files."""

from __future__ import annotations

import json
import math
import inspect
import shlex
import sys
from pathlib import Path

from colonbench.commands.common import (add_model_args, finite, model_sha256, note_dropped, output_folder, positive,
                                        repeats)
from colonbench.errors import ColonbenchError
from colonbench.pointio import MESH_DENSITY


def cmd_train(args):
    """Train (or resume) the completion network on a generated dataset."""
    from colonbench.completion.train import TrainConfig, train

    cfg = TrainConfig(network=args.network, batch_size=args.batch_size, lr=args.lr, epochs=args.epochs,
                      augment_prob=args.augment_prob, seed=args.seed, workers=args.workers, flips=args.flips,
                      transposes=args.transposes, erase=args.erase, repeat=tuple(args.repeat or ()),
                      precision=args.precision, hole_weight=args.hole_weight, pool=args.pool,
                      checkpoint_minutes=args.checkpoint_minutes, max_minutes=args.max_minutes,
                      keep_epochs=args.keep_epochs, init=args.init, init_sha256=model_sha256(args.init))
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
    from colonbench.benchmark.registry import load_method
    from colonbench.estimate import as_estimate
    from colonbench.datagen.generate import write_points_ply
    from colonbench.pointio import read_surface, write_mesh_ply

    files = [Path(f) for f in args.files]
    names = [estimate_name(f) for f in files]
    clash = sorted({n for n in names if names.count(n) > 1})
    if clash:
        raise ColonbenchError(f"several inputs would write the same output name(s) {clash}; "
                              "call estimate separately for them")
    method = load_method(args.method, model=args.model, device=args.device, tta=args.tta)  # loaded once for every file
    if getattr(method, "uses_truth", False):
        raise ColonbenchError(f"method {method.name!r} is a reference that needs ground truth; it runs only in "
                              "colonbench evaluate")
    known = {} if args.length_mm is None else {"length_mm": args.length_mm}
    if known and "length_mm" not in inspect.signature(method.estimate).parameters:
        raise ColonbenchError(f"--length-mm: method {method.name!r} does not take a segment's length")
    failed = 0
    with output_folder(args.out_dir) as out:  # gone again, if made here, when nothing is written into it
        for f, name in zip(files, names):
            try:
                points, dropped = read_surface(f)          # its messages name the file
            except ColonbenchError as exc:
                print(f"colonbench: error: {exc}", file=sys.stderr)
                failed += 1
                continue
            note_dropped(f, dropped)
            try:
                est = as_estimate(method.estimate(points, **known), method.name)
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
            within = "" if est.coverage_interval is None else \
                f" [{est.coverage_interval[0]:.3f}, {est.coverage_interval[1]:.3f}]" + (" REVIEW" if est.review else "")
            print(f"{name}: coverage {est.coverage:.3f}{within}, {len(est.holes)} hole points, "
                  f"centerline {len(est.centerline)} points, {total:.2f} s")
    if failed:
        rest = "nothing was written" if failed == len(files) else "the others were written"
        raise ColonbenchError(f"{failed} of {len(files)} input(s) failed (see above); {rest}")


def add_parsers(sub) -> None:
    """Add ``train``, ``average``, ``estimate`` to the ``colonbench`` subparsers."""
    p = sub.add_parser("train", help="train (or resume) the completion network on generated shards or a pack")
    p.add_argument("data", nargs="+", help="dataset folder with train and validation splits (colonbench generate), "
                                           "or a pack of one (colonbench pack); several dataset folders (same grid) "
                                           "train together")
    p.add_argument("--out", required=True, help="run folder: log.csv, last.pt, best.safetensors; rerun to resume")
    p.add_argument("--network", default="small", help="network configuration: small (CPU) or large (GPU)")
    p.add_argument("--epochs", type=positive(int), default=100, help="epochs in all (default 100)")
    p.add_argument("--batch-size", type=positive(int), default=4, help="samples per step per process (default 4)")
    p.add_argument("--lr", type=positive(float), default=1e-3, help="Adam learning rate (default 1e-3)")
    p.add_argument("--augment-prob", type=finite, default=0.3,
                   help="share of samples augmented on the fly (default 0.3)")
    p.add_argument("--flips", action="store_true",
                   help="flip each sample's grid axes at random (exact augmentation; the only geometric one "
                        "for a pack)")
    p.add_argument("--transposes", type=finite, default=0.0, metavar="P",
                   help="share of the training samples whose grid axes are exchanged (one of the five other orders, "
                        "each as likely; exact, like --flips): the tube then runs along another axis than the "
                        "first, which the grid always gives it (default 0)")
    p.add_argument("--erase", type=finite, default=0.0, metavar="P",
                   help="share of the training samples (of a pack, or of format-2 shards with --augment-prob 0) "
                        "whose partial surface loses 1-3 ball-shaped patches before its input heatmap is made: "
                        "larger holes to complete (default 0)")
    p.add_argument("--hole-weight", type=finite, default=0.0, metavar="A",
                   help="each voxel's squared error counts 1 + A times where the complete surface lies and the input "
                        "has no partial point within 2 voxels: the missing wall weighs more in the loss (default 0, "
                        "the paper's plain L2)")
    p.add_argument("--pool", type=int, default=1, metavar="N",
                   help="screening set-up: train on a pack's grids pooled N times (2: 32^3 from 64^3, their heatmaps "
                        "made once and kept); the model then runs at that resolution inside the full grid. Several "
                        "times faster, for ranking recipes, not for shipping (default 1; docs/training.md)")
    p.add_argument("--repeat", type=repeats, default=None, metavar="N,N,...",
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
    p.add_argument("--max-minutes", type=positive(float), help="stop cleanly after this long (resume later)")
    p.add_argument("--checkpoint-minutes", type=positive(float), default=10.0,
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
    p.add_argument("--repeat", type=repeats, default=None, metavar="N,N,...",
                   help="weights of the packs' samples, as colonbench train --repeat (default 1 each)")
    p.add_argument("--bn-samples", type=positive(int), default=1000,
                   help="training samples for the batch-norm statistics (default 1000)")
    p.add_argument("--seed", type=int, default=0, help="seed of the samples drawn (default 0)")
    p.set_defaults(func=cmd_average)

    p = sub.add_parser("estimate", help="estimate coverage, holes and centerline of partial segments (mm)")
    p.add_argument("files", nargs="+", help="partial segments, mm, one each: point clouds (.ply, .npy, .xyz, .txt, "
                   ".csv) "
                   f"or meshes (.ply, .obj, .stl, .off; sampled on their faces at {MESH_DENSITY:g} points/mm^2)")
    p.add_argument("--out-dir", required=True, help="folder for <name>.json per input")
    p.add_argument("--method", default="completion", help="method (default completion: the paper's)")
    add_model_args(p, "model .safetensors from colonbench train (an earlier shipped model: its file from git history, "
                      "CHANGELOG.md), or small, the shipped model (the default)")
    p.add_argument("--mesh", action="store_true",
                   help="also write <name>_mesh.ply (completed mesh, holes red) and <name>_centerline.ply")
    p.add_argument("--length-mm", type=positive(float), metavar="L",
                   help="the segments' arc length along the colon where known, mm: a cloud that stops short of it "
                        "has the rest counted unobserved (completion; docs/method.md, How sure it is)")
    p.set_defaults(func=cmd_estimate)

