"""Generalization: the widened generator, real meshes in manifests, the probe generator, tortuous colons."""

import json

import h5py
import numpy as np
import pytest
import yaml

from colonbench.datagen.colon import generate_colon, tube_colon
from colonbench.datagen.config import ColonConfig, SegmentConfig
from colonbench.datagen.holes import unseen_end
from colonbench.datagen.sample import reconstruction_cloud
from colonbench.datagen.segments import SegmentSurface
from colonbench.datagen.tube import self_intersections
from colonbench.errors import InputError
from colonbench.shards.manifest import resolve
from colonbench.shards.schema import sha256_file
from conftest import MANIFESTS
from shapes import straight

WIDE = MANIFESTS / "wide.yaml"


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
