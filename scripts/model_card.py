"""Write the model card of a trained model from what the run recorded (no figure typed by hand).

    python scripts/model_card.py runs/small-cpu/best.safetensors --log runs/small-cpu/log.csv \
        --eval eval-noiseless.json eval-noisy.json --hardware "2-core CPU" > colonbench/completion/models/MODEL_CARD.md
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import sys
from pathlib import Path

from colonbench.completion.average import describe_batchnorm
from colonbench.completion.network import load_model
from colonbench.shards.schema import sha256_file


def _commands(manifests: list[str], meta: dict) -> str:
    """The commands that made the model, from the data it was trained on."""
    names = [Path(m).stem for m in manifests]
    steps = [f"`colonbench generate {m} --out data/{n} --workers 2`" for m, n in zip(manifests, names)]
    if meta.get("data_format") == "pack":  # data_dir: the packs' folder names joined by '+', in the order trained
        packs = (meta.get("data_dir") or "+".join(names)).split("+")
        steps += [f"`colonbench pack data/{n} --out packs/{p} --workers 2`" for n, p in zip(names, packs)]
    steps.append(f"`{meta.get('command') or 'colonbench train'}`")
    return ", then ".join(steps)


def _data(manifests: list[str], meta: dict) -> str:
    """The training manifests with the sha256 the run recorded for each."""
    shas = meta.get("data_manifests") or [meta.get("data_manifest_sha256", "?")]
    if len(shas) != len(manifests):
        raise SystemExit(f"the model was trained on {len(shas)} dataset(s); --data-manifest names {len(manifests)}")
    return " + ".join(f"`{m}` (manifest sha256 `{h}`)" for m, h in zip(manifests, shas))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("model")
    ap.add_argument("--log", help="the run's log.csv (a trained model; an averaged model has none)")
    ap.add_argument("--eval", nargs="*", default=[], help="JSON files of scripts/bench_completion.py --json")
    ap.add_argument("--leaderboard", nargs="*", default=[],
                    help="leaderboard.json files of colonbench leaderboard over runs of this model (one per suite)")
    ap.add_argument("--evaluated-as", default=None,
                    help="the weights file the leaderboards' runs were given (--model RUN/epoch-NNN.safetensors) when "
                         "that is the model under another name: its sha256 must be the model's")
    ap.add_argument("--hardware", required=True)
    ap.add_argument("--data-manifest", nargs="+", default=["data_manifests/train-cpu.yaml"],
                    help="the manifest(s) of the training data, in the order given to colonbench train")
    ap.add_argument("--note", default="")
    args = ap.parse_args(argv)
    _, config, meta = load_model(args.model)
    out = [f"# Model card: the shipped completion network (`{Path(args.model).name}`)", ""]
    if args.note:
        out += [args.note, ""]
    if meta.get("average"):
        out += _average_rows(args, config, meta)
    else:
        if not args.log:
            raise SystemExit("--log: the run's log.csv is needed for a trained model")
        out += _trained_rows(args, config, meta)
    out += _figures(args, meta)
    out += intervals_rows(Path(args.model))
    print("\n".join(out))
    return 0


def _flags(by: str, threshold: float) -> str:
    """What makes an estimate flagged, in words (:mod:`colonbench.completion.review`)."""
    if by == "odds":
        from colonbench.completion.review import chance

        return (f"a chance over {100 * chance(threshold):.1f} % that the estimate is off by more than 15 points (the "
                f"log odds of a logistic fit of its signals over {threshold:.2f})")
    where = {"width": "wider than", "reach": "reaching from its estimate more than",
             "drop": "reaching below its estimate more than"}[by]
    return f"an interval {where} {round(100 * threshold, 1):g} points"


def intervals_rows(model: Path) -> list[str]:
    """The card's section on the model's coverage intervals, from its calibration file (none: no section)."""
    from colonbench.completion import calfile

    cal = calfile.load(model, steps=None)               # None where the model has no calibration file
    if cal is None:
        return []
    src = cal.source
    manifests = src.get("manifests") or {src.get("manifest", "?"): src.get("manifest_sha256", "")}  # one before 0147
    scaled = any("features" in g for g in cal.groups.values())
    two_sided = any("weights_low" in g for g in cal.groups.values())
    names = ", ".join(next(iter(cal.groups.values())).get("features", ()))
    how = (f"scaled by `exp(w . f)` of the estimate's signals ({names})"
           + (", a scale for each end" if two_sided else "") if scaled else f"grouped by {cal.scheme}")
    if any("ranges" in g for g in cal.groups.values()):
        how += f", each clipped into the range calibrated on (the line up to {cal.longest_mm():.0f} mm)"
    held, map_width = src.get("held_out"), cal.map.get("review_width")
    who = "a length given" if map_width else "a map's segment or a length given"
    out = ["", "## Coverage intervals", "",
           f"`{calfile.path_for(model).name}` (id `{src.get('id')}`): {cal.level:.0%} split-conformal intervals "
           f"for {src.get('steps')}, {how}, calibrated by `python scripts/calibrate_intervals.py` on "
           f"{' and '.join(f'`{name}` (sha256 `{sha[:16]}...`)' for name, sha in manifests.items())}, "
           f"{src.get('estimates')} estimates at noise {', '.join(f'{x:g}' for x in src.get('noise_mm', []))} mm"
           + (f" (the table beside the model, `{src['estimates_table']}`, sha256 `{src['estimates_sha256'][:16]}...`)"
              if src.get("estimates_table") else "")
           + (f" (chosen {held}; left out: {src.get('not_calibrated_on')})" if held else "")
           + f"; {_flags(cal.review_by, cal.review_width)} flags its estimate for review"
           + (f" (an estimate of known extent, {who}: "
              f"{_flags(cal.review_by_known or cal.review_by, cal.review_known)}"
              + (f"; a map's segment: {_flags('width', map_width)}"
                 + (f", or points per mm of the map's line more than {math.exp(cal.map['review_point_rate']):.2f} "
                    "times, or less than the inverse of, the map's median segment's" if cal.map.get("review_point_rate")
                    else "")
                 + ", chosen on the validation maps by `python scripts/map_intervals.py --write`" if map_width else "")
              + ")" if cal.review_known else "") + ".", "",
           "| group | calibration estimates | interval around the estimate | scale weights |", "|---|---:|---|---|"]
    rows = [(k, g) for k, g in cal.groups.items() if k != "all" or scaled] + \
        ([("extent known" + (" (a map's planes)" if "short" in cal.known else ""), cal.known)] if cal.known else []) + \
        [(f"extent known, a length given that {how} the estimate", cal.known[k])
         for k, how in (("full", "left"), ("short", "shortened")) if k in cal.known]
    for key, g in rows:
        two = "weights_low" in g                       # this group's scale for each end (``scaled2...``, ``quant...``)
        ends = (f"{g['low']:+.2f} s_low to {g['high']:+.2f} s_high" if two
                else f"{g['low']:+.2f} s to {g['high']:+.2f} s" if "features" in g
                else f"{100 * g['low']:+.1f} to {100 * g['high']:+.1f} points")
        if "band_edges" in g:                          # quantiles per band of the scale (``binned...``)
            edges = ", ".join(f"{e:+.2f}" for e in g["band_edges"])
            ends = (f"per band of log s (cut at {edges}): " + ", ".join(
                f"{lo:+.2f} s to {hi:+.2f} s" for lo, hi in zip(g["band_low"], g["band_high"]))
                + " (each band's colon shift included)")
        if "shift_low" in g:
            ends += f" (colon shift {g['shift_low']:+.2f}, {g['shift_high']:+.2f} included)"
        named = lambda ws: ", ".join(f"{n} {w:+.2f}" for n, w in zip(g.get("features", ()), ws))  # noqa: E731
        weights = (f"s_low: {named(g['weights_low'])}; s_high: {named(g['weights_high'])}" if two
                   else named(g.get("weights", ())))
        out.append(f"| {key} | {g['n']} | {ends} | {weights} |")
    if cal.review_odds:                                  # the review's odds (decision record 0167)
        o = cal.review_odds
        weights = ", ".join(f"{n} {w:+.2f}" for n, w in zip(o["features"], o["weights"]))
        out.append(f"| review: odds of off by > 15 points | {src.get('estimates')} | flagged above log odds "
                   f"{cal.review_width:+.2f} | {weights} |")
    if cal.like:                                         # which group: the likeness classifier (decision record 0170)
        o = cal.like
        weights = ", ".join(f"{n} {w:+.2f}" for n, w in zip(o["features"], o["weights"]))
        out.append(f"| which group: `like=1` (like the paper's colons) or `like=0` | {src.get('estimates')} | "
                   f"`like=1` over a {100 * o['threshold']:.0f} % chance | log odds: {weights} |")
    for track, g in (cal.map.get("groups") or {}).items():
        out.append(f"| map segments, {track} | {g['n']} | {100 * g['low']:+.1f} to {100 * g['high']:+.1f} points | |")
    return out


def _network(config) -> str:
    return (f"| network | MONAI 3D UNet, channels {list(config.channels)}, strides {list(config.strides)}, "
            f"{config.num_res_units} residual unit(s), {config.norm} norm; 64^3 input heatmap -> 64^3 target heatmap |")


def _average_rows(args, config, meta) -> list[str]:
    """The table of an averaged model (colonbench average): its models, each with the run that wrote it."""
    avg = meta["average"]
    bn = avg["batchnorm"]
    out = ["| | |", "|---|---|", _network(config),
           f"| training data | {_data(args.data_manifest, meta)}, the data of every averaged model; their "
           "validation splits for model selection |",
           f"| command | {_commands(args.data_manifest, {**meta, 'command': avg.get('command')})} |",
           f"| batch norm | statistics recomputed after averaging: {describe_batchnorm(bn)}, {bn['batches']} batches |",
           f"| hardware | {args.hardware} |",
           f"| software | colonbench {meta.get('colonbench')}, torch {meta.get('torch')} |",
           f"| grid | {meta.get('grid_options')} |", "",
           "## Averaged models", "",
           "Uniform weights, in this order. Each was written by the run command beside it (`--keep-epochs`).", "",
           "| model | sha256 | epoch | steps | validation L2 | run command |", "|---|---|---|---|---|---|"]
    for m in avg["models"]:
        path = Path(m["path"])
        if path.is_file() and sha256_file(path) == m["sha256"]:
            mm = load_model(path)[2]
            row = (f"{mm.get('epoch')} | {mm.get('steps')} | {mm.get('val_l2', float('nan')):.6f} | "
                   f"`{mm.get('command')}`")
        else:
            row = "? | ? | ? | (file not here)"
        out.append(f"| {m['path']} | `{m['sha256'][:16]}...` | {row} |")
    return out


def _trained_rows(args, config, meta) -> list[str]:
    """The table and training log of a model from colonbench train."""
    rows = list(csv.DictReader(open(args.log)))
    tc = meta.get("train_config", {})
    out = ["| | |", "|---|---|", _network(config),
            f"| training data | {_data(args.data_manifest, meta)}, "
            + ("its train split; validation split" if len(args.data_manifest) == 1 else
               "their train splits as one; their validation splits as one") + " for model selection |",
            f"| command | {_commands(args.data_manifest, meta)} (rerun the same command to resume a stopped run) |",
            f"| settings | batch {tc.get('batch_size')}, Adam lr {tc.get('lr')}, L2 loss, geometric augmentation "
            f"share {tc.get('augment_prob')}, axis flips {'on' if tc.get('flips') else 'off'}, seed {tc.get('seed')}"
            + (f", repeat {tc['repeat']}" if tc.get("repeat") else "")
            + f", forward pass in {tc.get('precision', 'fp32')} |",
            f"| selected | epoch {meta.get('epoch')}, {meta.get('steps')} steps, "
            f"{meta.get('samples_seen')} samples seen, "
            f"validation L2 {meta.get('val_l2'):.5f} |",
            f"| hardware | {args.hardware} ({meta.get('device')}, {meta.get('world_size')} process(es)) |",
            f"| wall time | {meta.get('train_seconds', 0) / 60:.0f} min of training to the selected checkpoint |",
            f"| software | colonbench {meta.get('colonbench')}, torch {meta.get('torch')} |",
            f"| grid | {meta.get('grid_options')} |", "",
            "## Training log", "", "| epoch | steps | train L2 | validation L2 | lr | minutes |",
            "|---|---|---|---|---|---|"]
    out += [f"| {r['epoch']} | {r['steps']} | {r['train_l2']} | {r['val_l2']} | {r['lr']} | "
            f"{float(r['seconds']) / 60:.0f} |" for r in rows]
    return out


def _figures(args, meta) -> list[str]:
    """The bench_completion figures and the leaderboards' rows of this model."""
    out = []
    if args.eval:
        out += ["", "## Figures", "",
                "Measured with `python scripts/bench_completion.py DATA --split test --limit N [--noise S] "
                "[--gt]` (one process, one torch thread, the model loaded and set up once; s per segment is the "
                "`estimate` call).", "",
                "| evaluated | samples | noise mm | coverage MAE (points) | median | bias | holes P / R @2mm (mean) | "
                "centerline P / R @2mm (mean) | s per segment | constant guess MAE |",
                "|---|---|---|---|---|---|---|---|---|---|"]
        for path in args.eval:
            e = json.load(open(path))
            m = e["metrics_mean"]
            out.append(f"| {e['model']} on {e['data']} {e['split']} | {e['samples']} | {e['noise_mm']} | "
                       f"{e['coverage_mae_points']:.2f} | {e['coverage_median_abs_points']:.2f} | "
                       f"{e['coverage_bias_points']:+.2f} | {m['holes_precision_2mm']:.2f} / "
                       f"{m['holes_recall_2mm']:.2f} | {m['centerline_precision_2mm']:.2f} / "
                       f"{m['centerline_recall_2mm']:.2f} | "
                       f"{e.get('estimate_per_segment', e['wall_per_segment']):.2f} | "
                       + (f"{e['constant_guess_mae_points']:.2f} |" if e.get("constant_guess_mae_points") else "- |"))
    name = Path(args.model).stem
    if args.evaluated_as:
        if sha256_file(args.evaluated_as) != sha256_file(args.model):
            raise SystemExit(f"--evaluated-as {args.evaluated_as} is not the same weights as {args.model}")
        name = Path(args.evaluated_as).stem
    for path in args.leaderboard:
        out += leaderboard_rows(path, f"{name}@{meta.get('steps')}")
    return out


def leaderboard_rows(path, version: str) -> list[str]:
    """The leaderboard's rows of this model's methods and of the references, as a Markdown table."""
    lb = json.load(open(path))
    rows = [r for r in lb["rows"] if r["reference"] or r["version"].split(",")[0] == version]
    if not any(r["method"] == "completion" for r in rows):
        raise SystemExit(f"{path} has no completion row of version {version}")
    d = lb["data"]
    out = ["", f"## Benchmark: `{d['manifest_name']}`", "",
           f"`colonbench evaluate` on manifest `{d['manifest_name']}`, split `{d['split']}`, {d['samples']} "
           "segments, then `colonbench leaderboard` (docs/benchmark.md). Coverage errors in points; P / R are "
           "means at 2 mm; * = reference rows given ground truth, or the constant guess.", "",
           "| noise mm | method | MAE | median | bias | q95 | holes P / R | centerline P / R | s per segment |",
           "|---|---|---|---|---|---|---|---|---|"]

    def f(x, fmt):
        return "n/a" if x is None else format(x, fmt)

    for r in rows:
        out.append(f"| {r['noise_mm']:g} | {r['method']}{' *' if r['reference'] else ''} | "
                   f"{f(r['coverage_mae'], '.2f')} | {f(r['coverage_median'], '.2f')} | "
                   f"{f(r['coverage_bias'], '+.2f')} | "
                   f"{f(r['coverage_q95'], '.1f')} | {f(r['holes_precision_2mm_mean'], '.2f')} / "
                   f"{f(r['holes_recall_2mm_mean'], '.2f')} | {f(r['centerline_precision_2mm_mean'], '.2f')} / "
                   f"{f(r['centerline_recall_2mm_mean'], '.2f')} | {f(r['seconds'], '.2f')} |")
    return out


if __name__ == "__main__":
    sys.exit(main())
