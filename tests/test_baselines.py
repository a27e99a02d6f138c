"""Baselines on tubes with known answers: a straight cylinder with a cut window, a curved tube."""

import numpy as np
import pytest

from colonbench.baselines.threshold import threshold_coverage
from colonbench.baselines.unwrap import pca_axis, unwrap_coverage
from colonbench.datagen.colon import tube_colon
from colonbench.grid import fit_grid
from colonbench.heatmaps import sample_heatmaps
from colonbench.meshes import sample_surface
from shapes import arc, straight

R = 20.0
WINDOW_RAD, WINDOW_Z = 1.0, (20.0, 40.0)  # a 1 rad x 20 mm window: 400 mm^2 of a 2 pi 20 x 60 mm wall


@pytest.fixture(scope="module", params=[2.0, 10.0], ids=["2/mm2", "10/mm2"])
def windowed(request):
    colon = tube_colon(straight(60.0), R, ring_spacing_mm=0.5, n_around=256)
    pts = sample_surface(np.random.default_rng(0), colon.mesh.vertices, colon.mesh.faces, request.param)
    theta = np.arctan2(pts[:, 1], pts[:, 0])
    window = (np.abs(theta) < WINDOW_RAD / 2) & (pts[:, 2] > WINDOW_Z[0]) & (pts[:, 2] < WINDOW_Z[1])
    truth = 1 - R * WINDOW_RAD * (WINDOW_Z[1] - WINDOW_Z[0]) / (2 * np.pi * R * 60.0)
    return colon, pts[~window], truth, request.param


def in_window(points, slack=0.05, dz=1.0):
    theta = np.arctan2(points[:, 1], points[:, 0])
    return (np.abs(theta) < WINDOW_RAD / 2 + slack) & (points[:, 2] > WINDOW_Z[0] - dz) & \
        (points[:, 2] < WINDOW_Z[1] + dz)


def test_unwrapping_measures_a_cut_window(windowed):
    colon, pts, truth, _ = windowed
    est = unwrap_coverage(pts, colon.centerline.points)
    # within the 1 mm raster: cells the window's edge crosses hold points when the cloud is dense
    assert est.coverage == pytest.approx(truth, abs=0.01)
    assert in_window(est.holes).mean() > 0.99
    assert np.linalg.norm(est.holes[:, :2], axis=1) == pytest.approx(R, abs=0.3)


def test_unwrapping_with_a_straight_axis_fails_on_a_curved_segment():
    colon = tube_colon(arc(40.0, 1.6), 15.0, ring_spacing_mm=0.5, n_around=256)  # 64 mm bent through 92 degrees
    pts = sample_surface(np.random.default_rng(1), colon.mesh.vertices, colon.mesh.faces, 2.0)
    assert unwrap_coverage(pts, colon.centerline.points).coverage > 0.99  # nothing is missing
    assert unwrap_coverage(pts, pca_axis(pts)).coverage < 0.9  # Ma et al.'s straight axis sees holes


def test_thresholding_the_exact_heatmap_finds_the_window(windowed):
    colon, pts, truth, density = windowed
    grid = fit_grid(pts)
    hm = sample_heatmaps(grid, pts, colon.mesh.vertices, colon.mesh.faces, colon.centerline.points)
    est = threshold_coverage(hm.target, grid, pts)
    assert len(est.centerline) > 100
    if density >= 10:  # a dense cloud: every surface voxel centre has a point within sqrt(2)/2 voxel
        assert est.coverage == pytest.approx(truth, abs=0.01)
        assert in_window(est.holes, slack=0.1, dz=2.0).mean() > 0.95
    else:  # the paper's point: voxel centres of a thick shell sit too far from a sparse cloud, false holes
        assert truth - 0.1 < est.coverage < truth - 0.02


def last_bit(points: np.ndarray) -> np.ndarray:
    """Every coordinate moved by one unit in its last place, up or down by a bit of its own value (equal points
    stay equal), as another machine's float arithmetic may move them."""
    up = (points.view(np.int64) >> 7) & 1 == 1
    return np.where(up, np.nextafter(points, np.inf), np.nextafter(points, -np.inf))


def test_unwrapping_gives_the_same_answer_for_a_cloud_moved_at_its_last_bit(windowed):
    """The resampled line's samples sit on row edges in exact arithmetic (a 60 mm line: 120 samples, 60 rows); rows
    from the samples' indices keep whole rows of points from changing sides under float noise, and each row's centre
    is a sample, so hole points placed at it by integers, not by comparing floats, stay where they are (they moved
    by half a millimetre, whole rows of them, under another CPU's BLAS kernel)."""
    colon, pts, _, _ = windowed
    line = colon.centerline.points
    for cl in (line, pca_axis(pts)):
        est = unwrap_coverage(pts, cl)
        for moved_pts, moved_line in ((last_bit(pts), cl), (pts, last_bit(cl)), (last_bit(pts), last_bit(cl))):
            again = unwrap_coverage(moved_pts, moved_line)
            assert again.coverage == est.coverage
            assert len(again.holes) == len(est.holes)
            assert np.abs(again.holes - est.holes).max() < 1e-9
