"""Procedural colons: determinism, anatomy within the configured ranges, no self-intersection."""

import numpy as np
import pytest

from colonbench.datagen.camera import SurfaceScene
from colonbench.datagen.colon import generate_colon
from colonbench.datagen.config import ColonConfig
from colonbench.datagen.generate import GeneratorConfig, colon_samples, procedural_colon
from colonbench.datagen.segments import segment_surface, windows
from colonbench.datagen.tube import self_intersections
from colonbench.errors import ColonbenchError, InputError


def test_same_seed_same_geometry(small_config):
    a = procedural_colon(small_config, seed=11, colon_id=2)
    b = procedural_colon(small_config, seed=11, colon_id=2)
    c = procedural_colon(small_config, seed=11, colon_id=3)
    assert a.mesh.vertices.tobytes() == b.mesh.vertices.tobytes()
    assert a.mesh.faces.tobytes() == b.mesh.faces.tobytes()
    assert a.centerline.points.tobytes() == b.centerline.points.tobytes()
    assert a.centerline.length != c.centerline.length   # another colon id is another colon


def test_anatomy_within_configured_ranges(small_colon, small_config):
    cfg = small_config.colon
    cl = small_colon.centerline
    assert cfg.length_mm[0] <= cl.length <= cfg.length_mm[1]
    assert np.diff(cl.arclength).max() <= 0.5 + 1e-9
    info = small_colon.info
    assert cfg.radius_caecum_mm[0] <= info["radius_caecum_mm"] <= cfg.radius_caecum_mm[1]
    assert cfg.radius_sigmoid_mm[0] <= info["radius_sigmoid_mm"] <= cfg.radius_sigmoid_mm[1]
    # the wall near the caecum is wider than in the sigmoid
    s = cl.arclength / cl.length
    assert small_colon.radius[s < 0.05].max() > small_colon.radius[(s > 0.75) & (s < 0.85)].max()
    # haustral folds: spacing 10-40 mm in three sectors
    assert info["n_folds"] >= 3 * cl.length / 40.0 - 3
    assert set(info["regions"]) >= {"caecum", "ascending", "transverse", "descending", "sigmoid", "rectum"}


def test_folds_reach_into_the_lumen(small_colon):
    # along a ring of the ascending colon the wall distance varies by the fold depth
    v = small_colon.mesh.vertices
    n = small_colon.n_around
    s = small_colon.ring_arclength
    lo, hi = small_colon.info["regions"]["ascending"]
    k = np.flatnonzero((s > lo) & (s < hi))
    centers = small_colon.centerline.point_at(s[k])
    dist = np.linalg.norm(v.reshape(-1, n, 3)[k] - centers[:, None, :], axis=2)
    # per angle, the radius along the colon dips at folds by at least 8% of the radius
    dips = (dist.max(axis=0) - dist.min(axis=0)) / dist.max(axis=0)
    assert np.median(dips) > 0.08


@pytest.mark.parametrize("colon_id", range(4))
def test_no_self_intersection(colon_id):
    cfg = ColonConfig(ring_spacing_mm=3.0, edge_mm=4.0)
    colon = generate_colon(cfg, seed=5, colon_id=colon_id)
    assert len(self_intersections(colon.centerline, colon.radius, cfg.clearance_mm)) == 0


def test_no_self_intersection_by_open3d():
    import open3d as o3d

    colon = generate_colon(ColonConfig(ring_spacing_mm=3.0, edge_mm=5.0), seed=5, colon_id=0)
    m = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(colon.mesh.vertices),
                                  o3d.utility.Vector3iVector(colon.mesh.faces))
    assert not m.is_self_intersecting()


def test_impossible_layout_is_refused():
    cfg = ColonConfig(length_mm=(300.0, 300.0), radius_caecum_mm=(55.0, 60.0), radius_transverse_mm=(55.0, 60.0),
                      max_attempts=2)
    with pytest.raises(ColonbenchError, match="self-intersection"):
        generate_colon(cfg, seed=0)


def test_segments_tile_the_colon_exactly(small_colon):
    scene = SurfaceScene(small_colon.mesh.vertices, small_colon.mesh.faces)
    cl = small_colon.centerline
    wins = windows(cl.length, 50.0, 10.0)
    k = len(wins) // 2
    parts = [segment_surface(scene, cl, *wins[i]).area for i in (k, k + 1, k + 2)]
    whole = segment_surface(scene, cl, wins[k][0], wins[k + 2][1]).area
    assert sum(parts) == pytest.approx(whole, rel=1e-9)


def test_samples_are_reproducible_and_consistent(small_colon, small_config):
    run = lambda: list(colon_samples(small_colon, small_config, 3, 0, 60.0, 2, "camera+spheres", [4]))  # noqa: E731
    a, b = run(), run()
    assert [x[:2] for x in a] == [(4, 0), (4, 1)]
    for (_, _, s1), (_, _, s2) in zip(a, b):
        assert s1.partial_points.tobytes() == s2.partial_points.tobytes()
        assert s1.coverage == s2.coverage
    s = a[0][2]
    area = s.complete.area_faces
    assert s.coverage == pytest.approx(area[s.observed_faces].sum() / area.sum())
    assert 0.0 < s.coverage < 1.0
    assert s.hole_areas.sum() == pytest.approx(area[~s.observed_faces].sum())
    assert len(s.partial_points) == pytest.approx(2.0 * area[s.observed_faces].sum(), abs=1)
    assert a[0][2].coverage != a[1][2].coverage   # permutations differ


def test_config_errors_name_the_field():
    with pytest.raises(InputError, match=r"ColonConfig.length_mm = 50 is out of range"):
        GeneratorConfig.from_dict({"colon": {"length_mm": [50, 1000]}})
    with pytest.raises(InputError, match="low > high"):
        GeneratorConfig.from_dict({"camera": {"reach_mm": [100, 50]}})
    with pytest.raises(InputError, match="unknown ColonConfig field"):
        GeneratorConfig.from_dict({"colon": {"lenght_mm": [1000, 1200]}})
    with pytest.raises(InputError, match="unknown config section"):
        GeneratorConfig.from_dict({"colons": {}})
    with pytest.raises(InputError, match="must be an integer"):
        GeneratorConfig.from_dict({"camera": {"poses": [2.5, 4]}})
    with pytest.raises(InputError, match="must be numeric"):
        GeneratorConfig.from_dict({"camera": {"fov_deg": "wide"}})


def test_every_sample_reaches_the_minimum_coverage(small_colon, small_config):
    covs = [s.coverage for _, _, s in colon_samples(small_colon, small_config, 0, 0, 70.0, 1, "camera")]
    assert len(covs) >= 15
    assert min(covs) >= small_config.segments.min_coverage
    assert max(covs) > 0.9


def test_empty_point_cloud_is_written(tmp_path):
    import trimesh
    from colonbench.datagen.generate import write_points_ply

    pts = np.random.default_rng(0).normal(size=(20, 3)) * 40
    assert np.array_equal(trimesh.load(write_points_ply(tmp_path / "a.ply", pts)).vertices, pts)
    empty = (tmp_path / "e.ply")
    write_points_ply(empty, np.zeros((0, 3)))
    assert b"element vertex 0" in empty.read_bytes()
