"""Dataset manifests: everything needed to regenerate a dataset, and the shards it is cut into.

A manifest is a YAML file (see ``data_manifests/``)::

    name: smoke
    description: a few seconds of data for tests
    generator_version: 0.1.0      # the colonbench version whose generator it was written for
    seed: 7                       # root seed of every random stream
    task: segments                # segments (the default) or colon: whole-colon shards (see below)
    grid: {size: 64, margin: 4, min_extent_mm: 70, axes: tube}   # heatmap grid (colonbench.grid.fit_grid);
                                  # axes: tube (the tube's own axis) or pca (the default, as before 0.2)
    config:                       # the full generator config (colonbench.datagen.generate.GeneratorConfig)
      colon: {...}
      camera: {...}
      spheres: {...}
      segments: {...}             # segments.lengths_mm: the segment lengths cut from every colon
    splits:
      train:
        colons: {first: 0, count: 340}    # procedural colons 0..339
        segments_per_length: 10           # evenly spread along the colon; null = every segment
        permutations: 15                  # hole permutations per segment
        hole_models: {camera: 0.5, spheres: 0.5}   # mix, drawn per sample
        noise_mm: {0.0: 1.0}              # sigma mix, drawn per sample

Real (or a user's own) colons are a second colon source: a top-level
``meshes`` section names each mesh once, and a split lists the names it takes::

    meshes:
      gca00090: {id: 90090, mesh: meshes/gca00090_large_intestine_mm.ply, mesh_sha256: ...,
                 centerline: meshes/gca00090_path_mm.npy, centerline_sha256: ...}
    splits:
      train: {colons: {first: 0, count: 100}, meshes: [gca00090], ...}

Paths are relative to the manifest file's folder; the sha256 of each file is
part of the manifest (and of its hash), and a file that differs is refused
when the data are made. The mesh is imported as colonoscopy sees it
(:func:`colonbench.datagen.lumen.import_lumen`); ``id`` addresses its random
streams as a procedural colon index would, and must not fall in any split's
procedural range.

With ``task: colon`` a manifest makes one *whole-colon shard* per colon
(:mod:`colonbench.shards.colonshard`): ``permutations`` whole partial
reconstructions of it, with the whole-colon hole models (``spheres``,
``camera``; drawn systematically, so that each colon gets each model in its
share) and the config's ``whole`` section; ``segments_per_length`` and
the grid do not apply.

Colon ranges of different splits may not overlap, and a mesh may belong to
one split only, so test colons never appear in training or validation. A *shard* is the samples of one colon at one
segment length for one split; it is the unit of work and of storage.

The resolved manifest (defaults filled in, mixes normalised) has a SHA-256,
:func:`manifest_hash`, written into every shard and the lock, so results can
name exactly the data they came from.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass

import numpy as np
import yaml

from colonbench import seeding
from colonbench._version import __version__
from colonbench.datagen.config import read_yaml, to_dict
from colonbench.datagen.generate import GeneratorConfig
from colonbench.datagen.holes import HOLE_MODELS
from colonbench.errors import InputError
from colonbench.grid import AXES, GRID_MARGIN, GRID_MIN_EXTENT_MM, GRID_SIZE

#: The names a split may have.
SPLITS = ("train", "validation", "test")
_SPLIT_KEYS = {"colons", "meshes", "segments_per_length", "permutations", "hole_models", "noise_mm"}
_TOP_KEYS = {"name", "description", "generator_version", "seed", "task", "grid", "config", "splits", "meshes"}
#: What a manifest makes: segment shards (the paper's protocol; the default) or whole-colon shards.
TASKS = ("segments", "colon")
_MESH_KEYS = {"id", "mesh", "mesh_sha256", "centerline", "centerline_sha256"}


@dataclass(frozen=True)
class Unit:
    """One shard to make: a colon at one segment length, in one split."""

    split: str
    colon_id: int
    length_mm: float
    #: For an imported colon: its name in the manifest's ``meshes``, and the entry with absolute paths.
    mesh: str | None = None
    source: tuple | None = None
    #: A whole-colon shard (``task: colon``; ``length_mm`` is then 0).
    whole: bool = False

    @property
    def colon_key(self) -> tuple:
        """What the units of one colon share (a process that makes them in turn makes the colon once)."""
        return (self.colon_id, self.mesh, self.whole)

    @property
    def name(self) -> str:
        """Path of the shard below the dataset folder, e.g. ``train/colon-00012-60mm.h5``, ``test/mesh-x-60mm.h5``;
        whole-colon shards ``test/colon-00012.h5``, ``test/mesh-x.h5``."""
        if self.whole:
            return f"{self.split}/mesh-{self.mesh}.h5" if self.mesh is not None else \
                f"{self.split}/colon-{self.colon_id:05d}.h5"
        if self.mesh is not None:
            return f"{self.split}/mesh-{self.mesh}-{self.length_mm:g}mm.h5"
        return f"{self.split}/colon-{self.colon_id:05d}-{self.length_mm:g}mm.h5"


def _mix(value, what: str, cast) -> dict:
    """A ``{choice: weight}`` mapping with positive weights, normalised to sum 1 (12 decimals), keys sorted."""
    if not isinstance(value, dict) or not value:
        raise InputError(f"{what}: expected a mapping of choice -> weight, got {value!r}")
    out = {}
    for k, w in value.items():
        key = cast(k)
        try:
            w = float(w)
        except (TypeError, ValueError):
            raise InputError(f"{what}: the weight of {k!r} is {w!r}, not a number") from None
        if not np.isfinite(w) or w < 0:
            raise InputError(f"{what}: weight of {k!r} must be >= 0")
        out[key] = out.get(key, 0.0) + w
    total = sum(out.values())
    if total <= 0:
        raise InputError(f"{what}: weights sum to 0")
    # rounded, so that resolving a resolved mix gives it back bit for bit (its hash is the data's identity)
    return {k: round(out[k] / total, 12) for k in sorted(out)}


def _hole_model(name):
    if name not in HOLE_MODELS:
        raise InputError(f"unknown hole model {name!r}; known: {list(HOLE_MODELS)}")
    return name


def _noise(value):
    try:
        sigma = float(value)
    except (TypeError, ValueError):
        raise InputError(f"noise sigma {value!r} is not a number of mm") from None
    if not 0 <= sigma <= 5:
        raise InputError(f"noise sigma {sigma} mm is outside [0, 5] mm")
    return sigma


def _int(value, what: str, lo: int) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < lo:
        raise InputError(f"{what}: expected an integer >= {lo}, got {value!r}")
    return int(value)


def meshes_section(value, source: str) -> dict:
    """A manifest's ``meshes`` section, checked (``source`` names the manifest in errors): name -> {id, mesh,
    mesh_sha256, centerline, centerline_sha256}; ``{}`` for none."""
    if value is None:
        return {}
    if not isinstance(value, dict):
        raise InputError(f"{source}: meshes must map a name to {{id, mesh, mesh_sha256, centerline, "
                         "centerline_sha256}}")
    out = {}
    for name, entry in value.items():
        where = f"{source}: meshes.{name}"
        if not isinstance(name, str) or not name.replace("-", "").replace("_", "").isalnum():
            raise InputError(f"{where}: a mesh name is letters, digits, '-' and '_'")
        if not isinstance(entry, dict) or set(entry) != _MESH_KEYS:
            raise InputError(f"{where}: expected the keys {sorted(_MESH_KEYS)}, got {entry!r}")
        for key in ("mesh_sha256", "centerline_sha256"):
            digest = str(entry[key])
            if len(digest) != 64 or any(c not in "0123456789abcdef" for c in digest):
                raise InputError(f"{where}.{key}: expected the file's sha256 (64 hex digits), got {digest!r}")
        out[name] = {"id": _int(entry["id"], f"{where}.id", 0), "mesh": str(entry["mesh"]),
                     "mesh_sha256": str(entry["mesh_sha256"]), "centerline": str(entry["centerline"]),
                     "centerline_sha256": str(entry["centerline_sha256"])}
    ids = [m["id"] for m in out.values()]
    if len(set(ids)) != len(ids):
        raise InputError(f"{source}: two meshes share an id")
    return out


def resolve(data: dict, source: str = "manifest") -> dict:
    """Validate a manifest dict and fill in every default; the result is what gets hashed.

    Raises
    ------
    InputError
        Naming the offending key and what was expected.
    """
    if not isinstance(data, dict):
        raise InputError(f"{source}: a manifest must be a mapping")
    unknown = sorted(set(data) - _TOP_KEYS)
    if unknown:
        raise InputError(f"{source}: unknown key(s) {unknown}; known: {sorted(_TOP_KEYS)}")
    for key in ("name", "seed", "splits"):
        if key not in data:
            raise InputError(f"{source}: {key!r} is required")
    name = str(data["name"])
    seed = _int(data["seed"], f"{source}: seed", 0)
    kind = task(data)
    if kind not in TASKS:
        raise InputError(f"{source}: task {kind!r} is not one of {list(TASKS)}")
    config = GeneratorConfig.from_dict(data.get("config"))
    grid = dict(data.get("grid") or {})
    bad = sorted(set(grid) - {"size", "margin", "min_extent_mm", "axes"})
    if bad:
        raise InputError(f"{source}: unknown grid key(s) {bad}; known: ['axes', 'margin', 'min_extent_mm', 'size']")
    axes = grid.get("axes", "pca")
    if axes not in AXES:
        raise InputError(f"{source}: grid.axes {axes!r} is not one of {list(AXES)}")
    size = _int(grid.get("size", GRID_SIZE), f"{source}: grid.size", 8)
    margin = _int(grid.get("margin", GRID_MARGIN), f"{source}: grid.margin", 0)
    try:
        min_extent = float(grid.get("min_extent_mm", GRID_MIN_EXTENT_MM))
    except (TypeError, ValueError):
        raise InputError(f"{source}: grid.min_extent_mm must be a number of mm") from None
    if not 0 <= min_extent <= 1000:
        raise InputError(f"{source}: grid.min_extent_mm {min_extent} is outside [0, 1000] mm")
    if size < 2 * margin + 4:
        raise InputError(f"{source}: grid.size {size} leaves no room inside a margin of {margin}")
    meshes = meshes_section(data.get("meshes"), source)
    splits_in = data["splits"]
    if not isinstance(splits_in, dict) or not splits_in:
        raise InputError(f"{source}: splits must map split names ({', '.join(SPLITS)}) to their settings")
    splits = {}
    for split in SPLITS:
        if split not in splits_in:
            continue
        s = splits_in[split] or {}
        where = f"{source}: splits.{split}"
        unknown = sorted(set(s) - _SPLIT_KEYS)
        if unknown:
            raise InputError(f"{where}: unknown key(s) {unknown}; known: {sorted(_SPLIT_KEYS)}")
        names = s.get("meshes") or []
        if not isinstance(names, list) or any(n not in meshes for n in names) or len(set(names)) != len(names):
            raise InputError(f"{where}.meshes: expected a list of distinct names from the manifest's meshes "
                             f"({sorted(meshes)}), got {names!r}")
        colons = s.get("colons", {"first": 0, "count": 0} if names else None)
        if not isinstance(colons, dict) or set(colons) != {"first", "count"}:
            raise InputError(f"{where}.colons: expected {{first: ID, count: N}}, got {colons!r}")
        first = _int(colons["first"], f"{where}.colons.first", 0)
        count = _int(colons["count"], f"{where}.colons.count", 0 if names else 1)
        per_length = s.get("segments_per_length")
        per_length = None if per_length is None else _int(per_length, f"{where}.segments_per_length", 1)
        if kind == "colon":
            from colonbench.datagen.wholecolon import WHOLE_HOLE_MODELS

            if per_length is not None:
                raise InputError(f"{where}.segments_per_length: a task: colon manifest makes whole colons, "
                                 "not segments; leave it out")
            models = s.get("hole_models", {"camera": 1.0})
            bad = sorted(set(models) - set(WHOLE_HOLE_MODELS)) if isinstance(models, dict) else []
            if bad:
                raise InputError(f"{where}.hole_models: {bad} are not whole-colon hole models "
                                 f"({list(WHOLE_HOLE_MODELS)})")
        splits[split] = {
            "colons": {"first": first, "count": count},
            **({"meshes": list(names)} if names else {}),
            "segments_per_length": per_length,
            "permutations": _int(s.get("permutations", 1), f"{where}.permutations", 1),
            "hole_models": _mix(s.get("hole_models", {"camera": 1.0}), f"{where}.hole_models", _hole_model),
            "noise_mm": _mix(s.get("noise_mm", {config.segments.noise_mm: 1.0}), f"{where}.noise_mm", _noise),
        }
    extra = sorted(set(splits_in) - set(SPLITS))
    if extra:
        raise InputError(f"{source}: unknown split(s) {extra}; splits are {list(SPLITS)}")
    owner = {}
    for k, v in splits.items():
        for n in v.get("meshes", []):
            if n in owner:
                raise InputError(f"{source}: mesh {n!r} is in splits {owner[n]} and {k}; test colons must never be "
                                 "seen in training or validation")
            owner[n] = k
    for n, m in meshes.items():
        for k, v in splits.items():
            c = v["colons"]
            if c["first"] <= m["id"] < c["first"] + c["count"]:
                raise InputError(f"{source}: mesh {n!r} has id {m['id']}, a procedural colon of split {k}; "
                                 "give it an id outside every split's colons")
    ranges = sorted((v["colons"]["first"], v["colons"]["first"] + v["colons"]["count"], k) for k, v in splits.items()
                    if v["colons"]["count"] > 0)
    for (a0, a1, ka), (b0, b1, kb) in zip(ranges, ranges[1:]):
        if b0 < a1:
            raise InputError(f"{source}: the colons of splits {ka} [{a0}, {a1}) and {kb} [{b0}, {b1}) overlap; "
                             "test colons must never be seen in training or validation")
    grid = {"size": size, "margin": margin, "min_extent_mm": min_extent}
    if axes != "pca":  # written only when set, so that manifests from before keep their hash
        grid["axes"] = axes
    config_dict = config.to_dict()
    if any("video" in v["hole_models"] for v in splits.values()):  # spelled out where it is used
        config_dict["video"] = to_dict(config.video)
    if kind == "colon":  # spelled out where it is used
        config_dict["whole"] = to_dict(config.whole)
    out = {"name": name, "description": str(data.get("description", "")),
           "generator_version": str(data.get("generator_version", __version__)), "seed": seed,
           "grid": grid, "config": config_dict, "splits": splits}
    if kind != "segments":  # only when set, so that manifests from before keep their hash
        out = {"task": kind, **out}
    if meshes:  # only when used, so that manifests from before keep their hash
        out["meshes"] = meshes
    return out


def task(manifest: dict) -> str:
    """What a (resolved) manifest makes: ``"segments"`` (when it names no task) or ``"colon"``."""
    return manifest.get("task", "segments")


def load(path) -> dict:
    """Read and :func:`resolve` a manifest YAML file."""
    return resolve(read_yaml(path, "manifest"), str(path))


def mesh_source(resolved: dict, name: str, base) -> tuple:
    """``(name, mesh path, mesh sha256, centerline path, centerline sha256)`` of a manifest mesh, paths under ``base``."""
    from pathlib import Path

    m = resolved["meshes"][name]
    base = Path(base)
    return (name, str((base / m["mesh"]).resolve()), m["mesh_sha256"], str((base / m["centerline"]).resolve()),
            m["centerline_sha256"])


class _NoAliases(yaml.SafeDumper):
    def ignore_aliases(self, data):
        return True


def dumps(manifest: dict) -> str:
    """A manifest dict as YAML, keys in their given order, short lists inline, no YAML aliases."""
    return yaml.dump(manifest, Dumper=_NoAliases, sort_keys=False, default_flow_style=None, width=110)


#: Colon fields added after 0.2.0. While ``tortuosity_mm`` is [0, 0] (no bending, the default) neither changes
#: the data, so both are left out of the hashes: the hashes recorded for datasets and model cards before they
#: came still name the same data. Set, they enter the hashes.
TORTUOSITY_FIELDS = ("tortuosity_mm", "tortuosity_scale_mm")


def _hashed(resolved: dict) -> dict:
    """The resolved manifest as hashed: :data:`TORTUOSITY_FIELDS` left out while they change nothing."""
    config = resolved.get("config", {})
    colon = config.get("colon", {})
    if max(colon.get("tortuosity_mm", [0.0]), default=0.0) > 0:
        return resolved
    kept = {k: v for k, v in colon.items() if k not in TORTUOSITY_FIELDS}
    return {**resolved, "config": {**config, "colon": kept}}


def _canonical(obj) -> bytes:
    return json.dumps(obj, sort_keys=True, separators=(",", ":")).encode()


def manifest_hash(resolved: dict) -> str:
    """SHA-256 (hex) of a resolved manifest; equal for manifests that generate the same data."""
    return hashlib.sha256(_canonical(_hashed(resolved))).hexdigest()


def config_hash(resolved: dict) -> str:
    """SHA-256 (hex) of the generator config and grid of a resolved manifest."""
    hashed = _hashed(resolved)
    return hashlib.sha256(_canonical({"config": hashed["config"], "grid": hashed["grid"]})).hexdigest()


def units(resolved: dict, splits=None, base=".") -> list[Unit]:
    """The shards of a manifest, split by split, colon by colon (procedural, then meshes), length by length.

    ``base`` is the folder that the manifest's mesh paths are relative to (the manifest file's).
    """
    whole = task(resolved) == "colon"
    lengths = [0.0] if whole else resolved["config"]["segments"]["lengths_mm"]
    out = []
    for split, s in resolved["splits"].items():
        if splits is not None and split not in splits:
            continue
        first, count = s["colons"]["first"], s["colons"]["count"]
        out += [Unit(split, c, float(length), whole=whole) for c in range(first, first + count) for length in lengths]
        for name in s.get("meshes", []):
            src = mesh_source(resolved, name, base)
            out += [Unit(split, resolved["meshes"][name]["id"], float(length), name, src, whole=whole)
                    for length in lengths]
    return out


def pick_segments(n_windows: int, per_length: int | None) -> list[int]:
    """Indices of ``per_length`` windows spread evenly along a colon of ``n_windows`` (all if None or more)."""
    if per_length is None or per_length >= n_windows:
        return list(range(n_windows))
    return sorted({int(round(x)) for x in np.linspace(0, n_windows - 1, per_length)})


def _pick(mix: dict, r: float):
    """The choice of a ``{choice: weight}`` mix at ``r`` in [0, 1) of its cumulative weights."""
    keys = list(mix)
    cum = np.cumsum([mix[k] for k in keys])
    return keys[min(int(np.searchsorted(cum, r * cum[-1], side="right")), len(keys) - 1)]


def draw_mix(mix: dict, root_seed: int, *path):
    """A choice from a ``{choice: weight}`` mix, drawn from its own stream ``("mix", *path)``."""
    return _pick(mix, seeding.rng(root_seed, "mix", *path).random())


def stratified_draw(mix: dict, n: int, k: int, root_seed: int, *path):
    """The ``k``-th of ``n`` choices from a ``{choice: weight}`` mix, drawn systematically.

    One uniform offset ``u`` is drawn from the stream ``("mix", *path)``; draw
    ``k`` takes the choice at ``(u + k) / n`` of the cumulative weights. Every
    choice then comes ``n * weight`` times, rounded up or down (2 draws of a
    half-and-half mix: one of each), and the choice of each draw is still random.
    """
    u = seeding.rng(root_seed, "mix", *path).random()
    return _pick(mix, ((u + k) / n) % 1.0)
