"""Generalization (0.2): the tube's own axis, real-mesh import as colonoscopy sees it, the widened generator."""

import json

import h5py
import numpy as np
import pytest
import trimesh
import yaml

from colonbench.datagen.colon import generate_colon, tube_colon
from colonbench.datagen.config import ColonConfig, SegmentConfig
from colonbench.datagen.holes import unseen_end
from colonbench.datagen.lumen import import_lumen
from colonbench.datagen.sample import reconstruction_cloud
from colonbench.datagen.segments import SegmentSurface
from colonbench.datagen.tube import self_intersections
from colonbench.errors import InputError
from colonbench.grid import fit_grid, principal_axes, tube_axes
from colonbench.meshes import sample_surface
from colonbench.shards.manifest import resolve
from colonbench.shards.schema import sha256_file
from conftest import MANIFESTS
from shapes import arc, straight

WIDE = MANIFESTS / "wide.yaml"


def _cylinder_cloud(radius, length, density=2.0, seed=0, rotation=None):
    """Points on a straight tube of ``radius`` x ``length`` mm (the real swept mesh), turned by ``rotation``."""
    colon = tube_colon(straight(length), radius, ring_spacing_mm=1.0, n_around=256)
    pts = sample_surface(np.random.default_rng(seed), colon.mesh.vertices, colon.mesh.faces, density)
    return pts if rotation is None else pts @ rotation.T


def _angle(a, b):
    return float(np.degrees(np.arccos(min(1.0, abs(float(a @ b))))))


def test_short_wide_cylinder_gets_its_axis():
    # a 50 mm piece of a 40 mm-radius colon: wider than long, so its largest spread runs across it
    rot = np.linalg.qr(np.random.default_rng(3).normal(size=(3, 3)))[0]
    pts = _cylinder_cloud(40.0, 50.0, rotation=rot)
    axis = rot[:, 2]
    assert _angle(tube_axes(pts)[0], axis) < 2.0
    assert _angle(principal_axes(pts)[0], axis) > 45.0        # what the grid followed before
    # a cloud with one side of the wall missing, and with noise, still gets it
    half = pts[(pts @ rot[:, 0]) > 0]
    assert _angle(tube_axes(half)[0], axis) < 2.0
    noisy = pts + np.random.default_rng(4).normal(0, 0.5, pts.shape)
    assert _angle(tube_axes(noisy)[0], axis) < 2.0
    grid = fit_grid(pts, axes="tube")
    assert _angle(grid.rotation[0], axis) < 2.0
    assert np.isclose(np.linalg.det(grid.rotation), 1.0)
    with pytest.raises(InputError, match="grid axes"):
        fit_grid(pts, axes="longest")


def _open_tube(radius, length=200.0):
    return tube_colon(straight(length), radius, ring_spacing_mm=1.0, n_around=160).mesh


def _lumen_band_area(mesh, z0=40.0, z1=160.0):
    """Area of the faces whose centroids lie between two planes across a tube along z."""
    z = mesh.triangles_center[:, 2]
    return float(mesh.area_faces[(z > z0) & (z < z1)].sum())


def test_double_walled_cylinder_imports_as_its_inner_surface():
    inner, outer = _open_tube(20.0), _open_tube(24.0)
    shell = trimesh.util.concatenate([inner, outer])
    lumen = import_lumen(shell, straight(200.0).points)
    r = np.linalg.norm(lumen.mesh.vertices[:, :2], axis=1)
    band = (lumen.mesh.vertices[:, 2] > 40) & (lumen.mesh.vertices[:, 2] < 160)
    assert np.abs(r[band] - 20.0).max() < 0.7          # nothing of the outer wall
    expected = 2 * np.pi * 20.0 * 120.0
    assert _lumen_band_area(lumen.mesh) == pytest.approx(expected, rel=0.02)
    assert lumen.mesh.is_watertight
    # the open ends were sealed inside the tube; those stretches are never cut into segments
    assert 0 < lumen.info["open_share"] < 0.5
    assert lumen.collapsed[0][0] == 0.0 and lumen.collapsed[-1][1] == pytest.approx(lumen.centerline.length)
    # the re-centred centerline is the axis
    mid = (lumen.centerline.points[:, 2] > 40) & (lumen.centerline.points[:, 2] < 160)
    assert np.abs(lumen.centerline.points[mid, :2]).max() < 0.5
    assert np.median(lumen.radius[mid]) == pytest.approx(20.0, rel=0.03)


def test_duplicated_overlapping_piece_counts_once():
    tube = _open_tube(20.0)
    # a piece of the wall drawn a second time, a tenth of a millimetre off, as segmentations overlap
    sel = np.flatnonzero((tube.triangles_center[:, 2] > 60) & (tube.triangles_center[:, 2] < 120)
                         & (tube.triangles_center[:, 0] > 0))
    piece = trimesh.Trimesh(tube.vertices + [0.1, 0.0, 0.0], tube.faces[sel], process=False)
    doubled = trimesh.util.concatenate([tube, piece])
    assert _lumen_band_area(doubled) > 1.2 * 2 * np.pi * 20.0 * 120.0      # the input counts it twice
    lumen = import_lumen(doubled, straight(200.0).points)
    assert _lumen_band_area(lumen.mesh) == pytest.approx(2 * np.pi * 20.0 * 120.0, rel=0.02)


def test_lumen_import_refuses_a_midline_outside_the_mesh():
    with pytest.raises(InputError, match="midline"):
        import_lumen(_open_tube(20.0), straight(200.0).points + [60.0, 0.0, 0.0])


def test_collapsed_stretch_is_reported():
    # a tube pinched to 2 mm between 90 and 110 mm
    def radius(s, theta):
        return np.where(np.abs(s - 100.0) < 10.0, 2.0, 20.0) + 0 * theta
    mesh = tube_colon(straight(200.0), radius, ring_spacing_mm=1.0, n_around=160).mesh
    lumen = import_lumen(mesh, straight(200.0).points)
    inner = [c for c in lumen.collapsed if 0 < c[0] and c[1] < lumen.centerline.length - 1]
    assert len(inner) == 1
    a, b = inner[0]
    assert 80 < a < 95 and 105 < b < 120


def test_unseen_end_removes_a_known_share():
    colon = tube_colon(straight(60.0), 20.0, ring_spacing_mm=0.5, n_around=256)
    cl = straight(60.0).points
    areas = colon.mesh.area_faces
    for seed in range(4):
        unseen, info = unseen_end(np.random.default_rng(seed), colon.mesh.triangles_center, cl, (0.3, 0.3))
        assert areas[unseen].sum() / areas.sum() == pytest.approx(0.3, abs=0.01)
        z = colon.mesh.triangles_center[unseen, 2]
        assert (z.max() < 18.5) if info["end"] == "start" else (z.min() > 41.5)


def test_reconstruction_flaws_have_their_drawn_sizes():
    colon = tube_colon(straight(60.0), 20.0, ring_spacing_mm=0.5, n_around=256)
    mesh = colon.mesh
    observed = np.ones(len(mesh.faces), bool)
    surface = SegmentSurface(mesh, np.arange(len(mesh.faces)), (0.0, 60.0), straight(60.0).points)
    area = mesh.area
    cfg = SegmentConfig(point_density=2.0, point_density_scale=(2.0, 2.0), outlier_share=(0.1, 0.1),
                        outlier_distance_mm=(5.0, 5.0), double_layer_share=(0.2, 0.2),
                        double_layer_offset_mm=(2.0, 2.0))
    pts, info = reconstruction_cloud(np.random.default_rng(0), mesh, observed, surface, cfg, {})
    n = round(4.0 * area)
    assert info["points"] == n
    assert len(pts) == n + round(0.2 * n) + round(0.1 * (n + round(0.2 * n)))
    r = np.linalg.norm(pts[:, :2], axis=1)
    first = r[:n]
    assert np.abs(first - 20.0).max() < 0.05                      # the surface itself
    layer = r[n:n + round(0.2 * n)]
    assert np.median(np.abs(layer - 20.0)) > 0.3                  # the second layer is off the wall
    assert info["double_layer_shift_mm"] == pytest.approx(2.0)
    # non-uniform density: with falloff, points crowd near the one viewpoint
    far = SegmentConfig(density_falloff=(2.0, 2.0))
    view = {"poses": {"positions": [[0.0, 0.0, 5.0]]}}
    pts, _ = reconstruction_cloud(np.random.default_rng(1), mesh, observed, surface, far, view)
    near = (pts[:, 2] < 30).mean()
    assert near > 0.7


def test_widened_colons_keep_the_self_intersection_check():
    wide = yaml.safe_load(open(WIDE))["config"]["colon"]
    cfg = ColonConfig(**{k: tuple(v) if isinstance(v, list) else v for k, v in wide.items()})
    cfg = ColonConfig(**{**cfg.__dict__, "ring_spacing_mm": 3.0, "edge_mm": 4.0})
    for colon_id in range(3):
        colon = generate_colon(cfg, seed=20261122, colon_id=colon_id)
        assert len(self_intersections(colon.centerline, colon.radius, cfg.clearance_mm)) == 0
    # a smooth colon has no folds; an elliptic one has unequal diameters
    smooth = generate_colon(ColonConfig(ring_spacing_mm=3.0, edge_mm=4.0, fold_free_share=1.0), seed=1)
    assert smooth.info["n_folds"] == 0
    flat = generate_colon(ColonConfig(ring_spacing_mm=3.0, edge_mm=4.0, ellipticity=(0.3, 0.3),
                                      taenia_depth=(0.0, 0.0), taenia_depth_transverse=(0.0, 0.0),
                                      fold_depth=(0.0, 0.0), polyps=(0, 0), roughness_mm=(0.0, 0.0)), seed=1)
    n = flat.n_around
    ring = flat.mesh.vertices[100 * n:101 * n]
    r = np.linalg.norm(ring - ring.mean(axis=0), axis=1)
    assert r.max() / r.min() == pytest.approx(1.3 / 0.7, rel=0.03)


def _pinched(s, theta):
    """A 15 mm tube collapsed to 2 mm between 142 and 158 mm."""
    return np.where(np.abs(s - 150.0) < 8.0, 2.0, 15.0) + 0 * theta


def _mesh_manifest(tmp_path, splits, meshes=None):
    tube = tube_colon(straight(300.0), _pinched, ring_spacing_mm=1.0, n_around=96)
    tube.mesh.export(tmp_path / "tube.ply")
    np.save(tmp_path / "tube_mid.npy", straight(300.0).points)
    entry = {"id": 9000, "mesh": "tube.ply", "mesh_sha256": sha256_file(tmp_path / "tube.ply"),
             "centerline": "tube_mid.npy", "centerline_sha256": sha256_file(tmp_path / "tube_mid.npy")}
    manifest = {"name": "mesh-test", "seed": 3, "generator_version": "0.2.0", "grid": {"axes": "tube"},
                "config": {"segments": {"lengths_mm": [50.0]}}, "meshes": meshes or {"tube": entry},
                "splits": splits}
    path = tmp_path / "m.yaml"
    path.write_text(yaml.safe_dump(manifest))
    return path, manifest


def test_a_mesh_is_a_colon_source_in_manifests(tmp_path):
    from colonbench.shards.dataset import generate
    from colonbench.shards.reader import ShardDataset

    path, manifest = _mesh_manifest(tmp_path, {"test": {"meshes": ["tube"], "permutations": 1,
                                                        "hole_models": {"spheres": 1.0}}})
    lock = generate(path, tmp_path / "data", progress=False)
    assert list(lock["shards"]) == ["test/mesh-tube-50mm.h5"]
    with h5py.File(tmp_path / "data/test/mesh-tube-50mm.h5") as h5:
        assert h5.attrs["colon_source"] == "tube"
        assert h5.attrs["grid_axes"] == "tube"
        skipped = json.loads(h5.attrs["skipped_segments"])
        windows = h5["segments/window_mm"][:]
        cov = h5["samples/coverage"][:]
    # the window across the collapse is left out with its reason; the others are kept
    across = [s for s in skipped if s["window_mm"][0] < 150 < s["window_mm"][1]]
    assert len(across) == 1 and "collapsed" in across[0]["reason"]
    assert len(windows) >= 2 and not any(a < 150 < b for a, b in windows)
    assert np.all((cov > 0.2) & (cov <= 1.0))
    ds = ShardDataset(tmp_path / "data", split="test")
    assert ds.shards[0].grid_options["axes"] == "tube"
    # a mesh that is not the file the manifest names is refused, naming it
    (tmp_path / "tube.ply").write_bytes((tmp_path / "tube.ply").read_bytes() + b"\n")
    from colonbench.errors import ColonbenchError
    with pytest.raises(ColonbenchError, match="sha256 differs"):
        generate(path, tmp_path / "data2", progress=False)


def test_mesh_manifest_errors(tmp_path):
    _, manifest = _mesh_manifest(tmp_path, {"train": {"meshes": ["tube"]}, "test": {"meshes": ["tube"]}})
    with pytest.raises(InputError, match="test colons must never"):
        resolve(manifest)
    _, manifest = _mesh_manifest(tmp_path, {"train": {"colons": {"first": 9000, "count": 2}, "meshes": ["tube"]}})
    with pytest.raises(InputError, match="give it an id outside"):
        resolve(manifest)
    _, manifest = _mesh_manifest(tmp_path, {"train": {"meshes": ["other"]}})
    with pytest.raises(InputError, match="names from the manifest's meshes"):
        resolve(manifest)
    _, manifest = _mesh_manifest(tmp_path, {"train": {"meshes": ["tube"]}})
    manifest["meshes"]["tube"]["mesh_sha256"] = "abc"
    with pytest.raises(InputError, match="64 hex digits"):
        resolve(manifest)


def _end_frame(colon):
    cl = colon.centerline
    return cl.point_at([0.0, cl.length]), cl.tangent_at([0.0, cl.length])


def test_hemispherical_diverticulum_adds_its_known_area():
    from colonbench.datagen import irregular

    # a wide tube, so that its wall is flat on the scale of the pouch: the added area is 2 pi r^2 - pi r^2
    n_around, r = 2048, 5.0
    tube = tube_colon(straight(40.0), 300.0, ring_spacing_mm=0.5, n_around=n_around)
    point = tube.mesh.vertices[40 * n_around]
    normal = point - tube.centerline.point_at([20.0])[0]
    normal /= np.linalg.norm(normal)
    ends, tangents = _end_frame(tube)
    mesh = irregular.apply(tube.mesh.vertices, tube.mesh.faces, n_around, ends, tangents,
                           [(point, normal, r, 0.0)], [])
    assert mesh.area - tube.mesh.area == pytest.approx(2 * np.pi * r**2 - np.pi * r**2, rel=0.02)
    assert mesh.is_winding_consistent
    assert not mesh.is_watertight                 # the caps used for CSG are gone again
    # the pouch lies outside the wall, as deep as its radius
    depth = (mesh.vertices - point) @ normal
    assert depth.max() == pytest.approx(r, abs=0.1)


def test_pedunculated_polyp_reaches_into_the_lumen():
    from colonbench.datagen import irregular

    n_around = 256
    tube = tube_colon(straight(60.0), 20.0, ring_spacing_mm=0.5, n_around=n_around)
    point = tube.mesh.vertices[60 * n_around]
    normal = point - tube.centerline.point_at([30.0])[0]
    normal /= np.linalg.norm(normal)
    ends, tangents = _end_frame(tube)
    head, stalk = 4.0, 6.0
    mesh = irregular.apply(tube.mesh.vertices, tube.mesh.faces, n_around, ends, tangents, [],
                           [(point, normal, head, stalk, 1.5)])
    # the head's far side lies stalk + 1.8 head radii into the lumen from the wall
    rel = mesh.vertices - point
    reach = -(rel @ normal)
    near_axis = np.linalg.norm(rel + np.outer(reach, normal), axis=1) < head + 0.5
    assert reach[near_axis & (reach < 30)].max() == pytest.approx(stalk + 1.8 * head, abs=0.15)
    assert mesh.area > tube.mesh.area + 0.9 * 4 * np.pi * head**2


def test_colons_with_diverticula_and_stalked_polyps(small_config):
    cfg = ColonConfig(ring_spacing_mm=1.5, edge_mm=2.0, diverticula=(2, 2), pedunculated_polyps=(1, 1))
    colon = generate_colon(cfg, seed=3, colon_id=0)
    assert len(colon.info["diverticula"]) == 2 and len(colon.info["pedunculated_polyps"]) == 1
    assert colon.mesh.is_winding_consistent
    assert len(self_intersections(colon.centerline, colon.radius, cfg.clearance_mm)) == 0
    # each pouch reaches beyond the wall where it sits by the depth of its ball
    from scipy.spatial import cKDTree

    tree = cKDTree(colon.mesh.vertices)
    for d in colon.info["diverticula"]:
        p = np.array(d["position_mm"])
        axis_point = colon.centerline.point_at([d["arclength_mm"]])[0]
        out = (p - axis_point) / np.linalg.norm(p - axis_point)
        near = colon.mesh.vertices[tree.query_ball_point(p, 2.5 * d["radius_mm"])]
        depth = ((near - p) @ out).max()
        assert depth == pytest.approx(d["radius_mm"] * (1 + d["neck"]), abs=0.6)


@pytest.mark.parametrize("name", ["paper", "demo", "smoke", "train-cpu", "train-gpu", "wide", "real-test",
                                  "train-wide", "train-real", "bends"])
def test_resolving_a_resolved_manifest_keeps_its_hash(name):
    # a dataset folder keeps the resolved manifest; a resumed run compares their hashes
    from colonbench.shards.manifest import dumps, load, manifest_hash

    resolved = load(MANIFESTS / f"{name}.yaml")
    assert manifest_hash(resolve(yaml.safe_load(dumps(resolved)))) == manifest_hash(resolved)


@pytest.fixture(scope="module")
def gca00060(real_dir):
    """The real CT colon gca00060 imported as colonoscopy sees it (about 20 s; shared by the tests below)."""
    from colonbench.datagen.realmesh import import_colon

    return import_colon(real_dir / "gca00060_large_intestine_mm.ply", real_dir / "gca00060_path_mm.npy", lumen=True)


@pytest.mark.slow
def test_real_colon_segments_hold_only_their_own_stretch(gca00060):
    # gca00060 bends sharply at its caecum and flexures: the two cutting planes of a segment there form a
    # wedge whose far side holds wall of another stretch, connected to this segment's wall
    from colonbench.datagen.generate import PreparedColon

    prepared = PreparedColon(gca00060)
    wins, skipped = prepared.usable_windows(70.0, 10.0)
    assert len(wins) >= 10 and skipped                      # the open rectum end is left out
    r = np.median(gca00060.radius[gca00060.radius > 0])
    for s0, s1 in wins:
        seg = prepared.segment(s0, s1)
        span = np.ptp(seg.mesh.vertices, axis=0).max()
        assert span < (s1 - s0) + 4 * r + 40.0, (s0, s1, span)
        assert seg.area < 4 * 2 * np.pi * r * (s1 - s0), (s0, s1, seg.area)



def test_curvature_limit_rounds_a_kink_and_leaves_the_rest():
    # two straight legs meeting at a right angle: the re-centring's kink, in a 20 mm lumen
    from colonbench.polyline import Centerline
    from colonbench.datagen.lumen import MIN_TURN_RATIO, limit_curvature, turning_radius

    t = np.arange(0.0, 100.0, 0.5)
    corner = Centerline.from_points(np.concatenate([np.stack([t, 0 * t, 0 * t], 1),
                                                    np.stack([100 + 0 * t, t, 0 * t], 1)]))
    assert turning_radius(corner).min() < 3.0
    line = limit_curvature(corner, lambda s: np.full_like(s, 20.0))
    assert turning_radius(line).min() >= 0.95 * MIN_TURN_RATIO * 20.0
    # far from the corner the legs stay where they were
    far = np.linalg.norm(line.points - [100.0, 0.0, 0.0], axis=1) > 40.0
    assert np.abs(np.minimum(np.abs(line.points[far, 1]), np.abs(line.points[far, 0] - 100.0))).max() < 0.05
    # a bend the lumen allows (radius 30 mm in a 20 mm lumen) is not touched
    gentle = arc(30.0, np.pi / 2, spacing=1.0)
    kept = limit_curvature(gentle, lambda s: np.full_like(s, 20.0))
    assert np.abs(np.linalg.norm(kept.points[:, :2], axis=1) - 30.0).max() < 1e-6


def test_moved_points_that_step_back_are_dropped():
    from colonbench.datagen.lumen import _unfold

    pts = np.array([[0.0, 0, 0], [2, 0, 0], [4, 1, 0], [3, 3, 0], [6, 0, 0], [8, 0, 0]])
    tangent = np.tile([1.0, 0, 0], (len(pts), 1))
    assert np.array_equal(_unfold(pts, tangent), pts[[0, 1, 2, 4, 5]])


@pytest.mark.slow
def test_real_colon_centerline_has_no_kinks(gca00060):
    # gca00060's re-centred line had folded back on itself (a 172 degree turn within 3 mm at 873 mm) and
    # kinked at two more places; the segments cut there had planes at random angles
    from colonbench.datagen.lumen import MIN_TURN_RATIO, turning_radius

    inner = gca00060.radius > 0
    ratio = turning_radius(gca00060.centerline)[inner] / gca00060.radius[inner]
    assert np.quantile(ratio, 0.001) >= 0.8 * MIN_TURN_RATIO
    turn = np.degrees(3.0 / turning_radius(gca00060.centerline).min())
    assert turn < 45.0


def test_lumen_centre_of_a_segment_is_the_tube_axis_beside_an_offset_line():
    # scripts/centerline_convention.py: a line 3 mm off a straight tube's axis is re-centred onto the axis,
    # and a D-shaped (flattened) section moves the centre away from the flat side by a known amount
    import importlib.util

    spec = importlib.util.spec_from_file_location("centerline_convention",
                                                  MANIFESTS.parent / "scripts" / "centerline_convention.py")
    conv = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(conv)
    tube = tube_colon(straight(80.0), 15.0, ring_spacing_mm=1.0, n_around=256)
    axis = straight(80.0).resample(0.5).points
    direction = axis[-1] - axis[0]
    direction /= np.linalg.norm(direction)
    side = np.cross(direction, [0.0, 0.0, 1.0] if abs(direction[2]) < 0.9 else [1.0, 0.0, 0.0])
    side /= np.linalg.norm(side)
    off = axis + 3.0 * side
    line = conv.lumen_line(tube.mesh.vertices, tube.mesh.faces, off)
    middle = line[20:-20]
    d = np.linalg.norm(np.cross(middle - axis[0], direction), axis=1)  # distance to the true axis
    assert np.median(d) < 0.3 and d.max() < 0.6
    # flattened: a circle of R = 15 mm pressed flat at x = 0.5 R. Its deepest point (the inscribed circle's
    # centre) is at x = -0.25 R with depth 0.75 R; the core (depth >= 0.8 of that) is the disc of radius 6 mm
    # about the axis cut at x <= -1.5, a circular segment whose centroid lies at
    # x = -4 r sin^3(a) / (3 (2a - sin 2a)), r = 6, cos a = 1.5 / 6: -3.37 mm
    theta = np.linspace(0, 2 * np.pi, 256, endpoint=False)
    ring = np.c_[15.0 * np.cos(theta), 15.0 * np.sin(theta)]
    ring[:, 0] = np.minimum(ring[:, 0], 7.5)
    pts = np.concatenate([np.c_[ring, np.full(len(ring), z)] for z in np.arange(0.0, 40.1, 1.0)])
    n = len(ring)
    faces = []
    for k in range(40):
        for j in range(n):
            a, b = k * n + j, k * n + (j + 1) % n
            faces += [(a, b, a + n), (b, b + n, a + n)]
    centre = conv.section_centre(trimesh.Trimesh(pts, np.array(faces), process=False),
                                 np.array([0.0, 0.0, 20.0]), np.array([0.0, 0.0, 1.0]))
    assert centre is not None
    assert centre[0] == pytest.approx(-3.37, abs=0.3) and abs(centre[1]) < 0.3


def test_lumen_centerline_of_a_flattened_colon_sits_where_its_sections_core_is():
    # truth.lumen_centerline: a colon whose every section is a circle pressed flat at 0.5 r (no folds, taeniae,
    # polyps or roughness) has its lumen's centre 0.2249 r from the axis (the core centroid of that D shape,
    # see the test above: 3.37 mm at r = 15 mm), away from the flat side; the surface is the same
    from colonbench.datagen.generate import GeneratorConfig, procedural_colon

    shape = {"ring_spacing_mm": 1.0, "edge_mm": 1.5, "length_mm": [600.0, 600.0], "fold_depth": [0.0, 0.0],
             "taenia_depth": [0.0, 0.0], "taenia_depth_transverse": [0.0, 0.0], "polyps": [0, 0],
             "roughness_mm": [0.0, 0.0], "flattening": [0.5, 0.5], "ellipticity": [0.0, 0.0]}
    axis_colon = procedural_colon(GeneratorConfig.from_dict({"colon": shape}), seed=3, colon_id=0)
    config = GeneratorConfig.from_dict({"colon": shape, "truth": {"lumen_centerline": 1}})
    assert config.to_dict()["truth"] == {"lumen_centerline": 1}
    assert "truth" not in GeneratorConfig.from_dict({"colon": shape}).to_dict()  # old manifests keep their hash
    colon = procedural_colon(config, seed=3, colon_id=0)
    assert np.array_equal(colon.mesh.vertices, axis_colon.mesh.vertices)
    assert colon.info["centerline"] == "lumen-centred"
    axis = axis_colon.centerline.points
    line = colon.centerline.points
    s = axis_colon.centerline.arclength
    inner = (s > 60) & (s < s[-1] - 60)  # away from the ends, where the smoothing reaches past them
    from scipy.spatial import cKDTree

    d = cKDTree(line).query(axis[inner])[0]  # how far the lumen's centre lies from the axis
    # the ring radius at each axis point: the largest distance of its ring's vertices from the axis
    rings = axis_colon.mesh.vertices.reshape(-1, axis_colon.n_around, 3)
    ring_s = axis_colon.ring_arclength
    r = np.linalg.norm(rings - axis_colon.centerline.point_at(ring_s)[:, None, :], axis=2).max(axis=1)
    r_at = np.interp(s[inner], ring_s, r)
    ratio = d / r_at
    assert np.median(ratio) == pytest.approx(0.2249, abs=0.02)
    assert np.percentile(ratio, 95) < 0.26
    # every point of the new line is inside the tube: nearer the axis than the ring's flat side (0.5 r)
    assert ratio.max() < 0.5


def test_the_probe_generator_makes_tubes_of_its_ranges_and_scores_a_method_by_its_seen_area():
    # scripts/probe_tubes.py: the segment's faces lie 15 mm to 15 mm + its length along the axis, the wall
    # within the drawn radius bounds; a method that always says 1.0 errs by exactly the unseen share
    import importlib.util

    from colonbench.benchmark.references import ConstantMethod
    from colonbench.seeding import rng

    spec = importlib.util.spec_from_file_location("probe_tubes", MANIFESTS.parent / "scripts" / "probe_tubes.py")
    probe = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(probe)
    mesh, axis, in_segment, info = probe.tube(rng(3, "t"), 60.0, "deep")
    length = np.linalg.norm(np.diff(axis, axis=0), axis=1).sum()
    assert abs(length - 90.0) < 0.6
    s_face = probe.STEP_MM * (mesh.faces // (len(mesh.vertices) // len(axis))).mean(axis=1)
    assert s_face[in_segment].min() >= 15.0 - 1e-9 and s_face[in_segment].max() <= 75.0 + 1e-9
    # each ring of vertices around its axis point: within radius * ratio * (1 - depth)(1 - lobes) .. radius (1 + lobes)
    ring = np.repeat(axis, len(mesh.vertices) // len(axis), axis=0)
    r = np.linalg.norm(mesh.vertices - ring, axis=1)
    lo = info["radius"] * info["ratio"] * (1 - info["fold_depth"]) * (1 - info["lobes"])
    assert r.min() >= lo - 1e-6 and r.max() <= info["radius"] * (1 + info["lobes"]) + 1e-6
    table = probe.probe(3, 7, "smooth", ["spheres", "camera", "band"], {"one": ConstantMethod(coverage=1.0)},
                        noise=(0.0,))
    assert len(table) == 3 and ((table.truth > 0.3) & (table.truth < 1.0)).all()
    assert np.allclose(table.error, 100.0 * (1.0 - table.truth))

    class Count:   # reports its cloud's size, so that the density can be read back
        def estimate(self, points):
            return ConstantMethod(coverage=len(points) / 1e6).estimate(points)

    dense = probe.probe(3, 7, "smooth", ["spheres", "camera", "band"], {"n": Count()}, noise=(0.0,), density=2.0)
    sparse = probe.probe(3, 7, "smooth", ["spheres", "camera", "band"], {"n": Count()}, noise=(0.0,), density=0.5)
    assert np.allclose(sparse.truth, table.truth) and np.allclose(dense.truth, table.truth)  # the same tubes
    assert np.allclose(sparse.estimate / dense.estimate, 0.25, atol=0.002)


def _end_angles(centerline, length_mm=55.0, step_mm=5.0):
    """Angle between the first and last 5 mm chords of windows of ``length_mm`` every 20 mm along a line, degrees."""
    s = centerline.arclength
    out = []
    for a in np.arange(20.0, s[-1] - length_mm - 20.0, 20.0):
        p = centerline.point_at(np.arange(a, a + length_mm + 1e-9, step_mm))
        t = np.diff(p, axis=0)
        t /= np.linalg.norm(t, axis=1, keepdims=True)
        out.append(np.degrees(np.arccos(np.clip(t[0] @ t[-1], -1.0, 1.0))))
    return np.array(out)


def test_random_bending_moves_a_straight_line_across_itself_by_its_amplitude():
    from colonbench.datagen.colon import bend_randomly

    line = straight(2000.0, spacing=1.0).points
    bent = bend_randomly(line, np.random.default_rng(0), 12.0, 20.0)
    d = bent - line
    assert np.abs(d[:, 2]).max() < 1e-9                        # across the line only
    np.testing.assert_allclose(d[:, :2].std(axis=0), 12.0, rtol=1e-6)
    # smooth over its scale: neighbouring points 1 mm apart move alike, points 200 mm apart do not
    step = np.linalg.norm(np.diff(d, axis=0), axis=1)
    assert np.median(step) < 0.1 * 12.0
    far = np.corrcoef(d[:-200, 0], d[200:, 0])[0, 1]
    assert abs(far) < 0.3


def test_tortuous_colons_turn_like_real_ones_and_keep_the_self_intersection_check():
    # bends.yaml's ranges: its segments turn more than the same colons drawn without bending, no bend is
    # tighter than the curvature limit allows, and the exact self-intersection check holds
    from colonbench.polyline import Centerline

    raw = yaml.safe_load((MANIFESTS / "bends.yaml").read_text())["config"]["colon"]
    cfg = ColonConfig(**{k: tuple(v) if isinstance(v, list) else v for k, v in raw.items()})
    cfg = ColonConfig(**{**cfg.__dict__, "ring_spacing_mm": 3.0, "edge_mm": 4.0})
    flat = ColonConfig(**{**cfg.__dict__, "tortuosity_mm": (0.0, 0.0)})
    bent_angles, flat_angles = [], []
    for colon_id in range(2):
        colon = generate_colon(cfg, seed=20261126, colon_id=colon_id)
        assert colon.info["tortuosity_mm"] >= 10.0
        assert len(self_intersections(colon.centerline, colon.radius, cfg.clearance_mm)) == 0
        line = Centerline.from_points(colon.centerline.points)
        assert (line.curvature() * colon.radius).max() < 1.0    # every bend wider than the lumen
        bent_angles.append(_end_angles(colon.centerline))
        flat_angles.append(_end_angles(generate_colon(flat, seed=20261126, colon_id=colon_id).centerline))
    bent, unbent = np.median(np.concatenate(bent_angles)), np.median(np.concatenate(flat_angles))
    assert bent > 1.3 * unbent and bent > 40.0      # real colons' segments: 52 degrees; wide.yaml's: 24-28


def test_colons_without_bending_hash_as_before_the_field_came():
    # the dataset hash the shipped model's card records for wide.yaml still names its data; bending enters it
    import copy

    from colonbench.shards.manifest import load, manifest_hash

    wide = load(WIDE)
    assert manifest_hash(wide) == "9687e5fd0bb9eedde8e888008693290ce8b958816c3ef28d1b34700f1ee2247d"
    bent = copy.deepcopy(wide)
    bent["config"]["colon"]["tortuosity_mm"] = [5.0, 10.0]
    assert manifest_hash(bent) != manifest_hash(wide)
