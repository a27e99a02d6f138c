"""From a config to samples: colons, their segments and hole permutations, and sample folders on disk.

Random streams (see :mod:`colonbench.seeding`): colon ``i`` draws from
``("colon", i, attempt)``; permutation ``p`` of segment ``k`` of length ``l`` of
colon ``i`` draws its holes and points from ``("sample", i, l, k, p)``. Any one
sample can thus be regenerated alone, in any process, in any order.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from colonbench import seeding
from colonbench.datagen.camera import SurfaceScene
from colonbench.datagen.colon import Colon, generate_colon
from colonbench.datagen.config import (CONFIG_CLASSES, CameraConfig, ColonConfig, SegmentConfig, SphereConfig,
                                       TruthConfig, VideoConfig, WholeConfig, from_dict, read_yaml, to_dict)
from colonbench.datagen.holes import check_hole_model
from colonbench.datagen.sample import Sample, make_sample
from colonbench.datagen.segments import segment_surface, windows
from colonbench.errors import InputError


@dataclass(frozen=True)
class GeneratorConfig:
    """All the parameters of the data generator (YAML sections ``colon``, ``camera``, ``spheres``, ``segments``,
    ``video``, ``whole``, ``truth``)."""

    colon: ColonConfig = field(default_factory=ColonConfig)
    camera: CameraConfig = field(default_factory=CameraConfig)
    spheres: SphereConfig = field(default_factory=SphereConfig)
    segments: SegmentConfig = field(default_factory=SegmentConfig)
    video: VideoConfig = field(default_factory=VideoConfig)
    whole: WholeConfig = field(default_factory=WholeConfig)
    truth: TruthConfig = field(default_factory=TruthConfig)

    @classmethod
    def from_dict(cls, data: dict | None) -> "GeneratorConfig":
        """Validated config from a dict of sections; unknown sections or fields are errors."""
        data = dict(data or {})
        unknown = sorted(set(data) - set(CONFIG_CLASSES))
        if unknown:
            raise InputError(f"unknown config section(s) {unknown}; known sections: {sorted(CONFIG_CLASSES)}")
        return cls(**{k: from_dict(c, data.get(k)) for k, c in CONFIG_CLASSES.items()})

    @classmethod
    def from_yaml(cls, path) -> "GeneratorConfig":
        """Read a YAML file of sections (all optional)."""
        data = read_yaml(path, "config")
        if data is not None and not isinstance(data, dict):
            raise InputError(f"{path}: a config must be a mapping of sections")
        return cls.from_dict(data)

    def to_dict(self) -> dict:
        """Plain dict of all sections (ranges as lists).

        The ``video``, ``whole`` and ``truth`` sections are left out while they
        hold their defaults, so that manifests from before they existed keep
        their hash.
        """
        out = {k: to_dict(getattr(self, k)) for k in CONFIG_CLASSES}
        for name, default in (("video", VideoConfig()), ("whole", WholeConfig()), ("truth", TruthConfig())):
            if getattr(self, name) == default:
                del out[name]
        return out


class PreparedColon:
    """A colon loaded into Embree, ready to cut segments from."""

    def __init__(self, colon: Colon):
        self.colon = colon
        self.scene = SurfaceScene(colon.mesh.vertices, colon.mesh.faces)

    def segment(self, s0: float, s1: float):
        """The :class:`SegmentSurface` of the window ``[s0, s1]`` (mm)."""
        return segment_surface(self.scene, self.colon.centerline, s0, s1)

    def windows(self, length_mm: float, end_margin_mm: float = 0.0):
        """Consecutive windows of ``length_mm`` along this colon."""
        return windows(self.colon.centerline.length, length_mm, end_margin_mm)

    def usable_windows(self, length_mm: float, end_margin_mm: float = 0.0):
        """The windows of :meth:`windows` that have a lumen, and those left out with why.

        A window that overlaps a collapsed (or open) stretch of an imported
        colon (``colon.info["collapsed_mm"]``, :mod:`colonbench.datagen.lumen`)
        has no lumen to see and is left out.

        Returns
        -------
        windows : list of (float, float)
        skipped : list of dict
            ``{"window_mm": [s0, s1], "reason": str}`` per window left out.
        """
        keep, skipped = [], []
        collapsed = self.colon.info.get("collapsed_mm", [])
        for w in self.windows(length_mm, end_margin_mm):
            hit = [c for c in collapsed if c[0] < w[1] and c[1] > w[0]]
            if hit:
                skipped.append({"window_mm": [round(w[0], 2), round(w[1], 2)],
                                "reason": f"lumen collapsed or open to the outside at {hit[0][0]:.0f}-{hit[0][1]:.0f} mm"})
            else:
                keep.append(w)
        return keep, skipped


def colon_samples(colon: Colon, config: GeneratorConfig, seed: int, colon_id: int, length_mm: float,
                  permutations: int = 1, hole_model: str = "camera", segments=None):
    """Samples of every segment of one colon.

    Parameters
    ----------
    colon : Colon
    config : GeneratorConfig
    seed : int
        Root seed.
    colon_id : int
    length_mm : float
        Segment arc length.
    permutations : int
        Hole permutations per segment.
    hole_model : {"camera", "spheres", "camera+spheres"}
    segments : iterable of int, optional
        Only these segment indices.

    Yields
    ------
    segment_id : int
    permutation : int
    sample : Sample
    """
    check_hole_model(hole_model)
    prepared = PreparedColon(colon)
    wins, _ = prepared.usable_windows(length_mm, config.segments.end_margin_mm)
    wanted = range(len(wins)) if segments is None else segments
    for k in wanted:
        if not 0 <= k < len(wins):
            raise InputError(f"segment {k} does not exist; this colon has {len(wins)} segments of {length_mm} mm")
        surface = prepared.segment(*wins[k])
        for p in range(permutations):
            rng = seeding.rng(seed, "sample", colon_id, int(round(length_mm * 1000)), k, p)
            yield k, p, make_sample(rng, prepared.scene, colon.centerline, surface, hole_model,
                                    config.camera, config.spheres, config.segments, video=config.video)


def procedural_colon(config: GeneratorConfig, seed: int, colon_id: int) -> Colon:
    """Colon ``colon_id`` under ``seed`` (see :func:`colonbench.datagen.colon.generate_colon`)."""
    return generate_colon(config.colon, seed=seed, colon_id=colon_id,
                          lumen_centerline=bool(config.truth.lumen_centerline))


def write_points_ply(path, points) -> Path:
    """Write (n, 3) points (mm) as a binary little-endian PLY of float64 x, y, z; n may be 0."""
    pts = np.ascontiguousarray(np.asarray(points, dtype="<f8").reshape(-1, 3))
    header = (f"ply\nformat binary_little_endian 1.0\ncomment colonbench point cloud, mm\n"
              f"element vertex {len(pts)}\nproperty double x\nproperty double y\nproperty double z\nend_header\n")
    path = Path(path)
    with open(path, "wb") as fh:
        fh.write(header.encode("ascii"))
        fh.write(pts.tobytes())
    return path


def write_sample_folder(sample: Sample, folder, meta: dict | None = None) -> Path:
    """Write one sample as a folder of plain files, mm, the colon's frame.

    Files
    -----
    ``partial.ply``
        The partial point cloud (the input a method sees).
    ``complete.ply``
        The complete segment surface.
    ``observed_faces.npy``
        (f,) bool, which faces of ``complete.ply`` are observed.
    ``hole_points.npy``, ``centerline.npy``
        (k, 3) float64 GT hole points and GT centerline.
    ``gt.json``
        Coverage, arc-length window, hole areas, hole model, noise, ``meta``.
    """
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    write_points_ply(folder / "partial.ply", sample.partial_points)
    sample.complete.export(folder / "complete.ply")
    np.save(folder / "observed_faces.npy", sample.observed_faces)
    np.save(folder / "hole_points.npy", sample.hole_points)
    np.save(folder / "centerline.npy", sample.centerline)
    gt = {"coverage": sample.coverage, "window_mm": list(sample.window), "hole_model": sample.hole_model,
          "noise_mm": sample.noise_mm, "hole_areas_mm2": sample.hole_areas.tolist(),
          "complete_area_mm2": float(sample.complete.area), **(meta or {})}
    (folder / "gt.json").write_text(json.dumps(gt, indent=1))
    return folder
