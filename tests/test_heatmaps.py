"""Grid fitting and the paper's heatmaps on a cylinder, where distances are known exactly."""

import numpy as np
import pytest

from colonbench.datagen.colon import tube_colon
from colonbench.errors import InputError
from colonbench.grid import Grid, fit_grid, principal_axes
from colonbench.heatmaps import (densify_polyline, input_from_points, sample_heatmaps, target_heatmap,
                                 triangle_lattice)
from shapes import straight

R = 20.0  # cylinder radius, mm = voxels on the unit grid below
C = 32  # axis at voxel i = j = 32


@pytest.fixture(scope="module")
def cylinder():
    """A cylinder of radius 20 mm along z, z in [0, 63] mm, on a grid of 1 mm voxels with the axis on voxel centres."""
    colon = tube_colon(straight(63.0), R, ring_spacing_mm=0.5, n_around=360)
    grid = Grid(np.diag([1.0, 1.0, 1.0, 1.0]) @ np.array(
        [[1, 0, 0, -C], [0, 1, 0, -C], [0, 0, 1, 0], [0, 0, 0, 1]], float))
    return colon, grid


def dense_points(colon, keep):
    """Points 0.2 mm apart on the cylinder wall where ``keep(theta, z)``."""
    theta, z = np.meshgrid(np.arange(0, 2 * np.pi, 0.2 / R), np.arange(0.0, 63.0, 0.2), indexing="ij")
    theta, z = theta.ravel(), z.ravel()
    ok = keep(theta, z)
    return np.stack([R * np.cos(theta[ok]), R * np.sin(theta[ok]), z[ok]], 1)


def test_target_heatmap_on_known_voxels(cylinder):
    colon, grid = cylinder
    hm = sample_heatmaps(grid, dense_points(colon, lambda t, z: np.ones_like(z, bool)), colon.mesh.vertices,
                         colon.mesh.faces, colon.centerline.points)
    t = hm.target
    z = 30
    assert t[C, C, z] == 1.0  # on the centerline
    assert t[C + 20, C, z] == 0.0 and t[C, C - 20, z] == 0.0  # on the wall
    # along +x from the axis: d(v, C) = r exactly; d(v, S1) = 20 - r up to the voxelization of the
    # round wall, whose voxels reach up to half a voxel diagonal inwards
    th = lambda d: np.tanh(0.2 * d)  # noqa: E731
    f = lambda ds, r: th(ds) / (th(ds) + th(r))  # noqa: E731
    for r in (2, 5, 10, 15):
        assert f(20 - r - 0.6, r) - 1e-6 <= t[C + r, C, z] <= f(20 - r, r) + 1e-6
    assert t[C + 10, C, z] == pytest.approx(0.5, abs=0.02)
    # outside the tube the centerline is farther than the wall: below 0.5, rising towards 0.5
    assert 0 < t[C + 24, C, z] < t[C + 30, C, z] < 0.5
    assert hm.outside["complete"] == 0.0 and hm.outside["centerline"] == 0.0


def test_input_heatmap_across_a_cut_band(cylinder):
    colon, grid = cylinder
    # the band 25 < z < 35 mm is a hole all around: the wall voxel at z = 30 is 5 voxels from the points
    pts = dense_points(colon, lambda t, z: (z < 25) | (z > 35))
    h_in, outside = input_from_points(grid, pts)
    assert outside == 0.0
    assert h_in[C + 20, C, 30] == pytest.approx(np.tanh(0.2 * 5), abs=1e-6)
    assert h_in[C + 20, C, 28] == pytest.approx(np.tanh(0.2 * 3), abs=1e-6)
    assert h_in[C + 20, C, 20] == 0.0  # a voxel holding points
    # on the axis at z = 30 the nearest points are on the wall at z = 25 or 35, sqrt(20^2 + 5^2) away, less
    # up to 0.6 voxel because the wall's voxels reach inwards
    d = np.arctanh(np.float64(h_in[C, C, 30])) / 0.2
    assert np.hypot(19.4, 5) - 0.01 <= d <= np.hypot(20, 5) + 0.01


def test_target_formula_edge_cases():
    d = np.array([0.0, 0.0, 3.0, 50.0], np.float32)
    c = np.array([0.0, 4.0, 0.0, 50.0], np.float32)
    out = target_heatmap(d, c)
    assert out[0] == 0.0 and out[1] == 0.0 and out[2] == 1.0 and out[3] == pytest.approx(0.5)


def test_fit_grid_places_a_segment_from_its_points_alone(cylinder):
    colon, _ = cylinder
    pts = dense_points(colon, lambda t, z: np.ones_like(z, bool))
    grid = fit_grid(pts, min_extent_mm=0.0)
    # principal axis along the cylinder (63 mm long > 40 mm wide), longest side spans 64 - 1 - 2 * 4 voxels
    assert abs(grid.rotation[0] @ [0, 0, 1]) == pytest.approx(1.0, abs=1e-6)
    assert grid.voxel_size == pytest.approx(np.ptp(pts[:, 2]) / 55, rel=1e-9)
    # by default the box counts as at least 70 mm, room for the longest segment
    assert fit_grid(pts).voxel_size == pytest.approx(70.0 / 55, rel=1e-9)
    ijk = grid.to_voxel(pts)
    assert ijk.min() >= 4 - 1e-9 and ijk.max() <= 59 + 1e-9
    np.testing.assert_allclose(grid.to_mm(ijk), pts, atol=1e-9)
    assert np.linalg.det(grid.rotation) == pytest.approx(1.0)
    # the same points in another order or another frame give the same grid relative to them
    rng = np.random.default_rng(0)
    assert np.allclose(fit_grid(pts[rng.permutation(len(pts))], min_extent_mm=0.0).affine, grid.affine)
    shifted = fit_grid(pts + [100.0, -50.0, 3.0], min_extent_mm=0.0)
    np.testing.assert_allclose(shifted.to_voxel(pts + [100.0, -50.0, 3.0]), ijk, atol=1e-9)


def test_principal_axes_are_a_deterministic_right_handed_frame():
    rng = np.random.default_rng(1)
    pts = rng.normal(size=(500, 3)) * [10, 4, 1] + [0, 0, 0]
    pts[:, 0] += np.abs(pts[:, 0]) * 0.5  # skewed along x
    ax = principal_axes(pts)
    np.testing.assert_allclose(ax @ ax.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(ax) == pytest.approx(1.0)
    assert ax[0] @ [1, 0, 0] > 0.99  # largest variance first, towards the heavier tail


@pytest.mark.parametrize("bad, message", [
    (np.zeros((5, 3)), "at least 10"),
    (np.full((20, 3), np.nan), "NaN"),
    (np.zeros((20, 2)), "expected an \\(n, 3\\)"),
    (np.ones((20, 3)), "coincide"),
])
def test_fit_grid_refuses_bad_clouds(bad, message):
    with pytest.raises(InputError, match=message):
        fit_grid(bad)


def test_lattice_and_polyline_spacing():
    a, b, c = np.array([[0.0, 0, 0]]), np.array([[3.0, 0, 0]]), np.array([[0.0, 3, 0]])
    pts = triangle_lattice(a, b, c, 0.5)
    assert len(pts) == 55  # longest edge 3 sqrt(2) -> n = 9 cuts: (n + 1)(n + 2) / 2 lattice points
    assert pts.min() == 0 and np.all(pts.sum(axis=1) <= 3 + 1e-12)
    line = densify_polyline(np.array([[0.0, 0, 0], [2.0, 0, 0], [2.0, 1.0, 0]]), 0.5)
    assert np.all(np.linalg.norm(np.diff(line, axis=0), axis=1) <= 0.5 + 1e-12)
    assert np.allclose(line[-1], [2, 1, 0])
