"""Typed configuration of the data generator, with documented defaults and ranges.

Every parameter is a field of a frozen dataclass. A field whose value is a
``(low, high)`` pair is a *range*: each colon (or segment, or pose) draws its
own value uniformly from it. Each field carries in its metadata the unit, a
one-line description and the hard limits that :func:`validate` enforces; the
docs table (``docs/datagen.md``) is written from the same metadata by
:func:`describe`.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from colonbench.errors import InputError
from colonbench.params import param


@dataclass(frozen=True)
class ColonConfig:
    """Shape of a procedural colon."""

    length_mm: tuple = param((1200.0, 1900.0), 200.0, 5000.0, "mm", "centerline length, caecum to anus")
    radius_caecum_mm: tuple = param((25.0, 35.0), 5.0, 60.0, "mm", "lumen radius at the caecum")
    radius_transverse_mm: tuple = param((20.0, 28.0), 5.0, 60.0, "mm", "lumen radius of the transverse colon")
    radius_sigmoid_mm: tuple = param((12.0, 20.0), 5.0, 60.0, "mm", "lumen radius of the sigmoid")
    radius_rectum_mm: tuple = param((18.0, 26.0), 5.0, 60.0, "mm", "lumen radius of the rectal ampulla")
    transverse_sag_mm: tuple = param((20.0, 90.0), 0.0, 200.0, "mm", "how far the transverse colon hangs down")
    sigmoid_loop_mm: tuple = param((30.0, 80.0), 0.0, 150.0, "mm", "how far the sigmoid loop reaches up and forward")
    layout_jitter_mm: float = param(10.0, 0.0, 40.0, "mm", "random displacement of each anatomical control point")
    tortuosity_mm: tuple = param((0.0, 0.0), 0.0, 60.0, "mm",
                              "standard deviation of a smooth random bending of the centerline across itself "
                              "(0 = the anatomical layout alone; real colons' segments turn 2-3 times as much)")
    tortuosity_scale_mm: tuple = param((15.0, 30.0), 5.0, 200.0, "mm",
                                    "arc length over which that bending changes (Gaussian sigma; small = sharp turns)")
    fold_spacing_mm: tuple = param((10.0, 40.0), 2.0, 200.0, "mm", "distance between successive haustral folds")
    fold_depth: tuple = param((0.08, 0.35), 0.0, 0.6, "fraction of radius", "how far a fold reaches into the lumen")
    fold_width_mm: tuple = param((1.5, 5.0), 0.5, 20.0, "mm", "half-width of a fold (small = sharp)")
    taenia_depth: tuple = param((0.04, 0.10), 0.0, 0.4, "fraction of radius", "indentation along the three taeniae coli")
    taenia_depth_transverse: tuple = param((0.12, 0.22), 0.0, 0.4, "fraction of radius",
                                        "taenia indentation in the transverse colon (triangular section)")
    fold_free_share: float = param(0.0, 0.0, 1.0, "fraction of colons", "colons drawn smooth, without haustral folds")
    ellipticity: tuple = param((0.0, 0.0), 0.0, 0.5, "fraction of radius",
                            "elliptic cross-section: semi-axes (1 + e) and (1 - e) times the radius, turning slowly")
    flattening: tuple = param((0.0, 0.0), 0.0, 0.5, "fraction of radius",
                           "one side of the cross-section pressed flat, at (1 - f) times the radius from the axis")
    polyps: tuple = param((0, 4), 0, 50, "count", "number of polyps per colon")
    polyp_size_mm: tuple = param((2.0, 15.0), 0.5, 40.0, "mm", "polyp diameter")
    pedunculated_polyps: tuple = param((0, 0), 0, 20, "count",
                                    "polyps on a stalk per colon (CSG with manifold3d), beside the sessile ones")
    polyp_head_mm: tuple = param((6.0, 16.0), 1.0, 40.0, "mm", "head diameter of a pedunculated polyp")
    polyp_stalk_mm: tuple = param((3.0, 12.0), 0.5, 40.0, "mm", "stalk length of a pedunculated polyp")
    diverticula: tuple = param((0, 0), 0, 50, "count", "outpouchings of the wall per colon (CSG with manifold3d)")
    diverticulum_radius_mm: tuple = param((2.0, 7.0), 0.5, 20.0, "mm", "radius of a diverticulum's ball")
    diverticulum_neck: tuple = param((0.0, 0.6), 0.0, 0.9, "fraction of its radius",
                                  "how far a diverticulum's centre lies outside the wall (0 = hemisphere; more = "
                                  "narrower neck, deeper pouch)")
    roughness_mm: tuple = param((0.0, 0.4), 0.0, 3.0, "mm", "standard deviation of smooth surface roughness")
    ring_spacing_mm: float = param(0.75, 0.1, 5.0, "mm", "mesh resolution along the centerline")
    edge_mm: float = param(1.0, 0.1, 5.0, "mm", "mesh edge length around the lumen at the widest point")
    clearance_mm: float = param(3.0, 0.0, 30.0, "mm", "smallest gap allowed between two loops of the tube")
    max_attempts: int = param(25, 1, 1000, "count", "redraws allowed before giving up on a self-intersecting layout")


@dataclass(frozen=True)
class CameraConfig:
    """Virtual colonoscope poses and what they see."""

    poses: tuple = param((3, 12), 1, 1000, "count", "camera poses per hole permutation")
    fov_deg: float = param(140.0, 10.0, 179.0, "degree", "full field of view (a cone)")
    reach_mm: tuple = param((50.0, 100.0), 5.0, 1000.0, "mm", "farthest distance the camera sees, drawn per pose")
    near_mm: float = param(2.0, 0.0, 50.0, "mm", "closest distance the camera sees")
    lateral_offset: tuple = param((0.0, 0.6), 0.0, 0.95, "fraction of radius", "distance of the camera from the centerline")
    cone_deg: float = param(45.0, 0.0, 180.0, "degree", "spread of the view direction around the tangent")
    backward_fraction: float = param(0.3, 0.0, 1.0, "fraction", "share of poses looking backwards along the centerline")
    spread_mm: float = param(40.0, 0.0, 500.0, "mm", "poses lie within this arc length beyond the segment ends")


@dataclass(frozen=True)
class SphereConfig:
    """Sphere cropping, the paper's hole model for CT colons."""

    spheres: tuple = param((1, 6), 0, 1000, "count", "spheres removed per hole permutation")
    radius_mm: tuple = param((4.0, 18.0), 0.1, 200.0, "mm", "sphere radius")


@dataclass(frozen=True)
class SegmentConfig:
    """Splitting a colon into segments and sampling them."""

    lengths_mm: tuple = field(default=(50.0, 60.0, 70.0), metadata={
        "limits": (10.0, 500.0), "unit": "mm", "doc": "segment arc lengths to cut (one colon is cut once per length)",
        "kind": "list"})
    end_margin_mm: float = param(10.0, 0.0, 500.0, "mm", "arc length left out at each end of the colon")
    point_density: float = param(2.0, 0.01, 100.0, "points/mm^2", "density of the partial point cloud")
    hole_point_density: float = param(4.0, 0.01, 100.0, "points/mm^2", "density of the GT hole points")
    centerline_spacing_mm: float = param(0.5, 0.05, 0.5, "mm", "spacing of GT centerline points")
    noise_mm: float = param(0.0, 0.0, 10.0, "mm", "Gaussian noise on partial points (0.5 = the paper's noisy condition)")
    min_coverage: float = param(0.2, 0.0, 0.99, "fraction",
                             "holes are redrawn (up to 20 times) until a segment is at least this much covered")
    point_density_scale: tuple = param((1.0, 1.0), 0.01, 100.0, "factor",
                                    "multiplies point_density, drawn per sample (log-uniform)")
    density_falloff: tuple = param((0.0, 0.0), 0.0, 4.0, "exponent",
                                "points thin out as (d_min / d)^falloff with the distance d to the nearest camera "
                                "(or, for sphere holes, to random centerline viewpoints); 0 = uniform")
    outlier_share: tuple = param((0.0, 0.0), 0.0, 0.5, "fraction of points",
                              "stray points added, each off a partial point in a random direction")
    outlier_distance_mm: tuple = param((1.0, 10.0), 0.0, 100.0, "mm", "how far an outlier lies from the surface")
    double_layer_share: tuple = param((0.0, 0.0), 0.0, 1.0, "fraction of points",
                                   "share of the cloud (one patch) repeated as a misregistered second layer")
    double_layer_offset_mm: tuple = param((0.5, 3.0), 0.0, 20.0, "mm", "shift of the second layer (random direction)")
    unseen_end: tuple = param((0.15, 0.5), 0.01, 0.95, "fraction of length",
                           "share of the segment's arc length never seen by the 'end' hole model")


@dataclass(frozen=True)
class VideoConfig:
    """The ``video`` hole model: a rendered withdrawal, degraded like a real pipeline's input and fused (TSDF)."""

    speed_mm_s: tuple = param((3.0, 12.0), 0.5, 50.0, "mm/s", "withdrawal speed of the colonoscope tip")
    push_back_per_100mm: float = param(0.5, 0.0, 10.0, "count",
                                    "how often the scope is pushed back in, per 100 mm of withdrawal")
    push_back_mm: tuple = param((10.0, 30.0), 0.0, 200.0, "mm", "how far it is pushed back in each time")
    look_around_deg: tuple = param((10.0, 50.0), 0.0, 89.0, "degree",
                                "largest tilt of the view away from the lumen ahead (looking around)")
    look_period_s: tuple = param((4.0, 10.0), 0.5, 60.0, "s", "period of the slowest looking-around swing")
    lateral_offset: tuple = param((0.0, 0.5), 0.0, 0.9, "fraction of the wall distance",
                               "how far the tip wanders off the centerline")
    fps: float = param(10.0, 1.0, 60.0, "frames/s", "frames rendered for a sample")
    image_px: int = param(128, 16, 1024, "px", "side of the square depth frames fused for a sample")
    fov_deg: float = param(140.0, 30.0, 170.0, "degree", "diagonal field of view of the pinhole camera")
    reach_mm: tuple = param((30.0, 80.0), 10.0, 1000.0, "mm",
                         "distance beyond which a frame's depth is not trusted: nothing farther is fused or seen")
    near_mm: float = param(2.0, 0.0, 50.0, "mm", "depth below which nothing is seen or fused")
    max_incidence_deg: tuple = param((70.0, 85.0), 10.0, 90.0, "degree",
                                  "surface seen more obliquely than this (line of sight to normal) gives no "
                                  "usable depth: it is neither fused nor seen")
    depth_noise: tuple = param((0.0, 0.02), 0.0, 0.2, "fraction of depth",
                            "sigma of the per-pixel depth noise, proportional to the depth")
    edge_blur_px: tuple = param((0.0, 2.0), 0.0, 10.0, "px",
                             "Gaussian smoothing of depth across edges, as monocular depth networks do")
    drift_rot_deg: tuple = param((0.0, 0.3), 0.0, 10.0, "degree/sqrt(s)", "rotation random walk of the pose drift")
    drift_trans_mm: tuple = param((0.0, 0.5), 0.0, 20.0, "mm/sqrt(s)", "translation random walk of the pose drift")
    drift_scale: tuple = param((0.0, 0.01), 0.0, 0.2, "1/sqrt(s)", "log-scale random walk of the depth (scale drift)")
    tracking_loss_per_100mm: float = param(2.0, 0.0, 20.0, "count",
                                        "how often tracking is lost, per 100 mm of the trajectory's arc length")
    tracking_loss_s: tuple = param((1.0, 8.0), 0.0, 60.0, "s", "how long each loss lasts: its frames are not fused")
    skip_deg_s: float = param(60.0, 1.0, 10000.0, "degree/s", "frames turning faster than this are dropped (blur)")
    skip_mm_s: float = param(25.0, 1.0, 10000.0, "mm/s", "frames moving faster than this are dropped (blur)")
    voxel_mm: float = param(1.0, 0.2, 5.0, "mm", "TSDF voxel size")
    trunc_mm: float = param(4.0, 0.5, 20.0, "mm", "TSDF truncation distance")


@dataclass(frozen=True)
class WholeConfig:
    """Whole-colon partial reconstructions (``datagen.wholecolon``): the data of the whole-colon benchmark."""

    point_density: float = param(2.0, 0.01, 100.0, "points/mm^2", "density of the partial cloud on the observed faces")
    holes_per_m: float = param(25.0, 0.0, 1000.0, "count per m",
                            "hole spheres per metre of centerline (spheres model), centred on the surface")
    sphere_radius_mm: tuple = param((4.0, 18.0), 0.1, 200.0, "mm", "hole sphere radius (spheres model)")
    camera_step_mm: float = param(10.0, 1.0, 200.0, "mm", "arc length between the views of the camera model")
    camera_tilt_deg: float = param(60.0, 0.0, 90.0, "degree",
                                "largest tilt of a view away from looking up the colon (camera model)")
    camera_reach_mm: tuple = param((50.0, 100.0), 5.0, 1000.0, "mm", "how far each view sees (camera model)")
    camera_offset: float = param(0.5, 0.0, 0.9, "fraction of the wall distance",
                              "largest offset of a view off the centerline (camera model)")
    fov_deg: float = param(140.0, 30.0, 170.0, "degree", "field of view of each view (camera model)")
    trajectory_offset: float = param(0.5, 0.0, 0.9, "fraction of the wall distance",
                                  "largest drift of the recorded camera positions off the centerline, as a SLAM "
                                  "trajectory's (0: the centerline's points, as whole-colon shards were made "
                                  "before this field)")
    trajectory_drift_mm: float = param(40.0, 1.0, 1000.0, "mm",
                                    "arc length over which the recorded positions' drift changes (knot spacing)")


@dataclass(frozen=True)
class TruthConfig:
    """How a procedural colon's ground truth is recorded."""

    lumen_centerline: int = param(0, 0, 1, "flag",
                               "1: the true centerline runs through the lumen's centre (each cross-section's core "
                               "centroid, smoothed, as imported colons are re-centred); 0: the axis the tube is "
                               "swept around, which elliptic and flattened sections leave off-centre")


CONFIG_CLASSES = {"colon": ColonConfig, "camera": CameraConfig, "spheres": SphereConfig, "segments": SegmentConfig,
                  "video": VideoConfig, "whole": WholeConfig, "truth": TruthConfig}


def _check_value(cls, f, value):
    meta = f.metadata
    lo, hi = meta["limits"]
    name = f"{cls.__name__}.{f.name}"
    is_int = isinstance(f.default, int) or (isinstance(f.default, tuple) and isinstance(f.default[0], int))
    if isinstance(f.default, tuple):
        if not isinstance(value, (tuple, list)):
            raise InputError(f"{name} must be a list of numbers, got {value!r}")
        values = tuple(value)
        if meta.get("kind") != "list":
            if len(values) != 2:
                raise InputError(f"{name} must be a [low, high] range, got {value!r}")
            if values[0] > values[1]:
                raise InputError(f"{name} range has low > high: {value!r}")
        elif not values:
            raise InputError(f"{name} must not be empty")
    else:
        values = (value,)
    for v in values:
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            raise InputError(f"{name} must be numeric, got {v!r}")
        if is_int and int(v) != v:
            raise InputError(f"{name} must be an integer, got {v!r}")
        if not (lo <= v <= hi):
            raise InputError(f"{name} = {v!r} is out of range [{lo}, {hi}] {meta['unit']}")
    if isinstance(f.default, tuple):
        return tuple(int(v) if is_int else float(v) for v in values)
    return int(value) if is_int else float(value)


def validate(cfg):
    """Check every field of a config dataclass; returns ``cfg`` normalised (tuples, floats).

    Raises
    ------
    InputError
        Naming the field and the allowed range.
    """
    cls = type(cfg)
    values = {f.name: _check_value(cls, f, getattr(cfg, f.name)) for f in dataclasses.fields(cfg)}
    return cls(**values)


def from_dict(cls, data: dict[str, Any] | None):
    """Build and validate a config of class ``cls`` from a plain dict (e.g. YAML).

    Unknown keys are an error, naming the key and the known ones.
    """
    data = dict(data or {})
    known = {f.name for f in dataclasses.fields(cls)}
    unknown = sorted(set(data) - known)
    if unknown:
        raise InputError(f"unknown {cls.__name__} field(s) {unknown}; known fields: {sorted(known)}")
    return validate(cls(**data))


def to_dict(cfg) -> dict[str, Any]:
    """A plain, YAML/JSON-friendly dict of a config (ranges as lists)."""
    return {k: list(v) if isinstance(v, tuple) else v for k, v in dataclasses.asdict(cfg).items()}


def describe(cls) -> list[tuple[str, str, str, str, str]]:
    """Rows ``(field, default, limits, unit, description)`` for the docs."""
    rows = []
    for f in dataclasses.fields(cls):
        m = f.metadata
        rows.append((f.name, str(list(f.default) if isinstance(f.default, tuple) else f.default),
                     f"[{m['limits'][0]}, {m['limits'][1]}]", m["unit"], m["doc"]))
    return rows


def read_yaml(path, what: str = "config"):
    """The parsed content of a YAML file, or an :class:`InputError` naming the file and what is wrong."""
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: no such {what} file")
    try:
        return yaml.safe_load(path.read_text())
    except (yaml.YAMLError, UnicodeDecodeError) as exc:
        raise InputError(f"{path}: not valid YAML ({exc})") from None
