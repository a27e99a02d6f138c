"""Real colons as colonoscopy sees them: the lumen import (shells, duplicates, collapsed stretches) and its centerline."""


import numpy as np
import pytest
import trimesh

from colonbench.datagen.colon import tube_colon
from colonbench.datagen.lumen import import_lumen
from colonbench.errors import InputError
from colonbench.grid import fit_grid, principal_axes, tube_axes
from colonbench.meshes import sample_surface
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
    from colonbench.datagen.lumen_midline import MIN_TURN_RATIO, limit_curvature, turning_radius

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
    from colonbench.datagen.lumen_midline import _unfold

    pts = np.array([[0.0, 0, 0], [2, 0, 0], [4, 1, 0], [3, 3, 0], [6, 0, 0], [8, 0, 0]])
    tangent = np.tile([1.0, 0, 0], (len(pts), 1))
    assert np.array_equal(_unfold(pts, tangent), pts[[0, 1, 2, 4, 5]])


@pytest.mark.slow
def test_real_colon_centerline_has_no_kinks(gca00060):
    # gca00060's re-centred line had folded back on itself (a 172 degree turn within 3 mm at 873 mm) and
    # kinked at two more places; the segments cut there had planes at random angles
    from colonbench.datagen.lumen_midline import MIN_TURN_RATIO, turning_radius

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


