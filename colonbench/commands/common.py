"""What the verbs share: argument types, the colon-source and model options, messages about a user's files."""

from __future__ import annotations

import argparse
import math
import sys
from contextlib import contextmanager
from pathlib import Path

from colonbench.errors import ColonbenchError


def generator_config(args):
    from colonbench.datagen.generate import GeneratorConfig

    return GeneratorConfig.from_yaml(args.config) if args.config else GeneratorConfig()


def colon_from_args(args, config):
    """A Colon: imported from ``--mesh`` or procedural from ``--seed/--colon-id``."""
    if args.mesh:
        from colonbench.datagen.realmesh import import_colon

        return import_colon(args.mesh, args.centerline, lumen=args.lumen)
    if args.centerline or args.lumen:
        raise ColonbenchError("--centerline and --lumen go with --mesh")
    from colonbench.datagen.generate import procedural_colon

    return procedural_colon(config, args.seed, args.colon_id)


def add_colon_source(p):
    p.add_argument("--seed", type=int, default=0, help="root seed (default 0)")
    p.add_argument("--colon-id", type=int, default=0, help="which colon under the seed (default 0)")
    p.add_argument("--mesh", help="use a real colon surface (PLY/STL/OBJ/OFF, mm) instead of a procedural one")
    p.add_argument("--centerline", help="centerline of --mesh (.npy or text, (n, 3) mm); computed if omitted")
    p.add_argument("--lumen", action="store_true",
                   help="keep only what colonoscopy sees of --mesh: its lumen surface, remeshed at 1 mm, shells and "
                        "duplicates resolved, the --centerline (needed) re-centred; collapsed stretches are reported")
    p.add_argument("--config", help="generator config YAML (sections colon, camera, spheres, segments)")


def finite(text: str) -> float:
    """A float argument that is a finite number (``nan`` and ``inf`` parse as floats and are refused here)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"must be a finite number, got {text}")
    return value


def non_negative(text: str) -> float:
    """A finite float argument that is 0 or more."""
    value = finite(text)
    if value < 0:
        raise argparse.ArgumentTypeError(f"must be 0 or more, got {text}")
    return value


def positive(kind):
    def parse(text):
        try:
            value = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
        if not math.isfinite(value) or value <= 0:
            raise argparse.ArgumentTypeError(f"must be a positive number, got {text}")
        return value
    return parse


def add_model_args(p, model_help):
    p.add_argument("--model", help=model_help)
    p.add_argument("--device", default="cpu", help="cpu, cuda, auto (default cpu)")
    from colonbench.completion.symmetry import TTA_CHOICES

    p.add_argument("--tta", type=int, default=1, choices=TTA_CHOICES, metavar="K",
                   help="average the network's heatmap over K symmetries of the grid that keep the tube's axis: "
                        f"{', '.join(map(str, TTA_CHOICES))} (default 1, the network once; K times its time; "
                        "docs/method.md)")


def add_segment_args(p, segment_help):
    from colonbench.datagen import HOLE_MODELS

    p.add_argument("--length", type=positive(float), default=60.0, help="segment arc length, mm (default 60)")
    p.add_argument("--segment", type=int, help=segment_help)
    p.add_argument("--hole-model", default="camera", choices=HOLE_MODELS, help="how holes are made (default camera)")


def repeats(text: str) -> tuple:
    """--repeat's comma-separated whole numbers >= 1."""
    try:
        values = tuple(int(v) for v in text.split(","))
    except ValueError:
        values = ()
    if not values or min(values) < 1:
        raise argparse.ArgumentTypeError(f"{text!r}: whole numbers >= 1, comma-separated, one per dataset")
    return values


def floats(text: str) -> list[float]:
    try:
        return [finite(x) for x in text.split(",") if x.strip()]
    except argparse.ArgumentTypeError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a comma-separated list of finite numbers") from None


def note_dropped(path, dropped: int) -> None:
    """Say on stderr how many rows of a user's file were left out for not being finite (nothing for none)."""
    if dropped:
        print(f"colonbench: note: {path}: {dropped} point(s) that are NaN or infinite left out", file=sys.stderr)


@contextmanager
def output_folder(path):
    """Make the folder ``path`` (and its missing parents) for the duration; on leaving, remove those of them that
    this made and that are still empty, so that a command that wrote nothing leaves no folder behind.

    Yields
    ------
    Path
    """
    path = Path(path)
    made, p = [], path
    while not p.exists() and p != p.parent:
        made.append(p)  # the deepest first
        p = p.parent
    path.mkdir(parents=True, exist_ok=True)
    try:
        yield path
    finally:
        for p in made:
            try:
                p.rmdir()  # only an empty folder goes
            except OSError:
                break


def model_sha256(model):
    """sha256 of a model file or shipped model's, None for None; a missing one is left for the command to report."""
    from colonbench.completion.method import model_path
    from colonbench.shards.schema import sha256_file

    path = model_path(model) if model is not None else None
    return sha256_file(path) if path is not None and path.is_file() else None


def method_list(values) -> list[str]:
    from colonbench.commands.benchmark import parse_methods

    return parse_methods(values or ["all"])


def add_suite_check_args(p, where: str = "the data and output folders") -> None:
    """``--scheduler`` (Dask) and ``--allow-unverified`` (suite data whose hash is not the published one)."""
    p.add_argument("--scheduler", help=f"Dask scheduler address (tcp://host:8786): run on its workers, which must see "
                                       f"{where} at the same paths")
    p.add_argument("--allow-unverified", action="store_true",
                   help="evaluate data that is a named suite's by manifest and selection but not by its published "
                        "content hash (development; the results then say unverified and the shipped results stay "
                        "out)")
