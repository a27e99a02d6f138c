"""The completion method: centerline, mesh and coverage on shapes with known answers, training and estimate."""

import json

import numpy as np
import pytest
from scipy.spatial import cKDTree

pytest.importorskip("torch")
pytest.importorskip("monai")

from colonbench.cli import main  # noqa: E402
from colonbench.completion.heatmap_centerline import extract_centerline  # noqa: E402
from colonbench.completion.method import CompletionMethod, check_cloud, from_heatmap  # noqa: E402
from colonbench.completion.network import build_network, load_model, network_config, save_model  # noqa: E402
from colonbench.completion.surface import complete, hole_vertices, mesh_coverage, segment_planes, wall_gaps
from colonbench.completion.train import TrainConfig, train  # noqa: E402
from colonbench.datagen.colon import tube_colon  # noqa: E402
from colonbench.datagen.generate import write_points_ply  # noqa: E402
from colonbench.errors import InputError  # noqa: E402
from colonbench.grid import Grid, fit_grid  # noqa: E402
from colonbench.heatmaps import densify_polyline, sample_heatmaps  # noqa: E402
from colonbench.meshes import triangle_areas
from colonbench.shards.reader import ShardDataset  # noqa: E402
from shapes import arc, straight  # noqa: E402

R = 20.0
UNIT = Grid(np.array([[1, 0, 0, -32], [0, 1, 0, -32], [0, 0, 1, 0], [0, 0, 0, 1]], float))


def tube_heatmaps(centerline, grid=None, radius=R):
    colon = tube_colon(centerline, radius, ring_spacing_mm=0.5, n_around=256)
    pts = colon.mesh.vertices[::2]
    grid = grid or fit_grid(pts)
    return colon, grid, pts, sample_heatmaps(grid, pts, colon.mesh.vertices, colon.mesh.faces,
                                             colon.centerline.points)


def half_pipe():
    """Points and heatmaps of the half (x > 0) of a straight tube of radius R along z."""
    colon = tube_colon(straight(63.0), R, ring_spacing_mm=0.5, n_around=256)
    v, f = colon.mesh.vertices, colon.mesh.faces
    f = f[(v[f][:, :, 0] > 0).all(axis=1)]
    pts = v[v[:, 0] > 0][::2]
    return pts, sample_heatmaps(UNIT, pts, v, f, colon.centerline.points)


def distance_to_polyline(points, polyline):
    d, _ = cKDTree(densify_polyline(polyline, 0.05)).query(points)
    return d


@pytest.mark.parametrize("shape", ["straight", "curved"])
def test_centerline_of_a_tube_heatmap_is_within_one_voxel(shape):
    line = straight(63.0) if shape == "straight" else arc(60.0, 1.0)  # a 60 mm arc of radius 60 mm
    colon, grid, _, hm = tube_heatmaps(line, UNIT if shape == "straight" else None, radius=15.0)
    est = extract_centerline(hm.target)
    gt = grid.to_voxel(colon.centerline.points)
    d = distance_to_polyline(est, gt)
    # every estimated point near the true line; its ends follow the lumen (END_LEVEL), which on the exact
    # heatmap runs on past the tube's cut ends by up to 2.5 voxels (a method reports the line between its planes)
    assert d[2:-2].max() < 1.0 and d.max() < 3.0
    assert distance_to_polyline(gt, est).max() < 1.5  # and the whole true line covered, ends included


def test_a_ridge_broken_into_pieces_still_gives_the_whole_centerline():
    # a weak prediction: the ridge dips below 1 - delta in two places, and specks lie off the line (between
    # the ends: past an end, a speck is indistinguishable from the ridge going on)
    colon, grid, _, hm = tube_heatmaps(arc(60.0, 1.0), radius=15.0)
    h = hm.target.copy()
    gt = grid.to_voxel(colon.centerline.points)
    k = np.rint(gt[[len(gt) // 3, 2 * len(gt) // 3]]).astype(int)
    for x in k:
        h[x[0] - 2:x[0] + 3, x[1] - 2:x[1] + 3, x[2] - 2:x[2] + 3] *= 0.85  # three pieces above 1 - delta
    rng = np.random.default_rng(0)
    inside = np.argwhere((h > 0.6) & (h < 0.8))
    _, nearest = cKDTree(gt).query(inside)
    inside = inside[(nearest > 0.15 * len(gt)) & (nearest < 0.85 * len(gt))]
    specks = inside[rng.choice(len(inside), 30, replace=False)]
    h[tuple(specks.T)] = 0.97  # single voxels, not on the ridge
    est = extract_centerline(h)
    assert distance_to_polyline(gt, est).max() < 1.5  # the whole line, not its largest piece
    assert np.quantile(distance_to_polyline(est, gt), 0.9) < 1.0


@pytest.mark.parametrize("shape", ["straight", "curved"])
def test_a_ridge_that_fades_before_the_ends_still_gives_the_line_to_them(shape):
    # a prediction whose peak fades over the last 10 voxels at each end (as the network's does before a cut):
    # the candidates above 1 - delta stop there; the lumen's core (heatmap >= END_LEVEL) still runs on, and
    # the line's ends follow it to the tube's ends, on its axis
    line = straight(40.0) if shape == "straight" else arc(40.0, 1.2)
    colon, grid, _, hm = tube_heatmaps(line, radius=12.0)
    gt = grid.to_voxel(colon.centerline.points)
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(gt, axis=0), axis=1))])
    _, nearest = cKDTree(gt).query(np.argwhere(np.ones(hm.target.shape, bool)))
    to_end = np.minimum(s[nearest], s[-1] - s[nearest]).reshape(hm.target.shape)
    faded = hm.target * np.where(to_end < 10.0, 0.85 + 0.015 * to_end, 1.0)     # the peak 0.85 at the ends
    short = extract_centerline(faded, end_level=None)
    est = extract_centerline(faded)
    for ends in (short[[0, -1]], est[[0, -1]]):
        assert min(np.linalg.norm(ends - gt[0], axis=1)) == pytest.approx(
            min(np.linalg.norm(ends - gt[-1], axis=1)), abs=2.5)            # both ends alike
    assert distance_to_polyline(gt[[0, -1]], short).min() > 4.0              # the candidates stop short
    assert distance_to_polyline(gt[[0, -1]], est).max() < 2.0               # the core reaches the ends
    assert np.quantile(distance_to_polyline(est, gt), 0.9) < 1.0            # on the axis


def test_the_reported_centerline_stops_at_the_cut_rims_where_the_line_runs_past_them():
    # the line follows the lumen past the cuts (z = 10 and 50): the mesh is clipped at the rims, and the
    # method reports its line between them; a rim before the line's end holds (steps version 6)
    from colonbench.completion.surface import rim_planes

    pts, _ = _cut_tube_cloud()
    long_line = np.stack([np.full(53, 32.0), np.full(53, 32.0), np.linspace(4.0, 56.0, 53)], 1)
    (p0, n0), (p1, n1) = rim_planes(long_line, pts)
    assert abs(p0[2] - 10.0) < 1.0 and abs(p1[2] - 50.0) < 1.0
    assert n0 @ [0, 0, 1.0] > 0.999 and n1 @ [0, 0, -1.0] > 0.999
    colon, grid, tube_pts, hm = tube_heatmaps(straight(63.0), UNIT)
    cut = tube_pts[(tube_pts[:, 2] >= 10.0) & (tube_pts[:, 2] <= 50.0)]
    est = from_heatmap(hm.target, grid, cut)
    assert est.centerline[:, 2].min() > 10.0 - 1.0 and est.centerline[:, 2].max() < 50.0 + 1.0
    assert np.ptp(est.centerline[:, 2]) > 36.0
    assert est.mesh_vertices[:, 2].min() > 10.0 - 0.5 and est.mesh_vertices[:, 2].max() < 50.0 + 0.5


def test_marching_cubes_on_a_cylinder_heatmap_gives_its_area():
    colon, grid, pts, hm = tube_heatmaps(straight(63.0), UNIT)
    comp = complete(hm.target, extract_centerline(hm.target), grid.to_voxel(pts))
    centroid_z = comp.vertices[comp.faces].mean(axis=1)[:, 2]
    mid = (centroid_z > 5) & (centroid_z < 58)
    area = triangle_areas(comp.vertices, comp.faces)[mid].sum()
    assert area == pytest.approx(2 * np.pi * R * 53.0, rel=0.02)
    radius = np.linalg.norm(comp.vertices[:, :2] - 32, axis=1)
    assert np.median(radius) == pytest.approx(R, abs=0.25)
    assert comp.coverage == pytest.approx(1.0, abs=0.01)  # every part of the wall has points


def test_the_field_outside_the_band_takes_the_mean_of_the_nearest_valid_neighbours():
    from colonbench.completion.surface import _nearest_valid_mean

    values = np.zeros((5, 5, 5))
    valid = np.zeros((5, 5, 5), bool)
    for voxel, value in {(1, 2, 2): 1.0, (3, 2, 2): 3.0, (2, 1, 1): 100.0, (3, 3, 3): 7.0}.items():
        values[voxel], valid[voxel] = value, True
    where = np.zeros((5, 5, 5), bool)
    for voxel in [(2, 2, 2), (2, 0, 0), (4, 4, 4), (4, 4, 0)]:
        where[voxel] = True
    out = _nearest_valid_mean(values, valid, where)
    assert out[2, 2, 2] == 2.0          # two face neighbours tie: their mean; the edge neighbour is farther
    assert out[2, 0, 0] == 100.0        # across an edge only
    assert out[4, 4, 4] == 7.0          # across a corner only
    assert out[4, 4, 0] == 0.0          # no valid neighbour
    assert np.count_nonzero(out) == 3   # nothing outside ``where``


@pytest.mark.parametrize("clip", [True, False])
def test_a_half_pipe_heatmap_gives_its_own_area_without_flaps_past_its_edges(clip):
    # half a tube (x > 0): the heatmap's surface stops along two free edges; marching cubes runs on past
    # them as flaps, with no points on them, unless the faces off the heatmap's surface are dropped
    pts, hm = half_pipe()
    options = {"gaps": False} if clip else {"shell_level": None, "gaps": False}
    comp = complete(hm.target, extract_centerline(hm.target), UNIT.to_voxel(pts), **options)
    centroid = comp.vertices[comp.faces].mean(axis=1)
    mid = (centroid[:, 2] > 5) & (centroid[:, 2] < 58)
    area = triangle_areas(comp.vertices, comp.faces)[mid].sum()
    if clip:
        assert area == pytest.approx(np.pi * R * 53.0, rel=0.05)
        assert (centroid[:, 0] - 32 > -1.0).all()  # nothing past the edges (x = 0) by a voxel
        assert comp.coverage > 0.97  # a fully observed wall
    else:  # as before version 4 of the steps: flaps past both edges, all holes
        assert area > 1.1 * np.pi * R * 53.0 and comp.coverage < 0.92


def test_a_faint_half_of_a_tube_becomes_hole_surface_of_its_area_and_an_open_half_does_not():
    # a prediction whose wall fades on one side (x < 0: the heatmap at least 0.3 there, above the surface
    # threshold but with a faint valley where the wall is) and points on the other side only: the rays
    # across the centerline meet no surface voxel on the faint side, and wall_gaps puts that half of the
    # tube back at the wall's radius, all of it hole
    colon, grid, pts, hm = tube_heatmaps(straight(63.0), UNIT)
    faint = hm.target.copy()
    faint[:32] = np.maximum(faint[:32], 0.3)
    half = UNIT.to_voxel(pts[pts[:, 0] > 0])
    line = extract_centerline(hm.target)
    planes = segment_planes(line, half, cut_rims=False)
    gap_v, gap_f = wall_gaps(faint, line, planes)
    centroid = gap_v[gap_f].mean(axis=1)
    assert (centroid[:, 0] - 32 < 1.5).all()                       # only where the wall is faint
    length = np.ptp(gap_v[:, 2])
    assert triangle_areas(gap_v, gap_f).sum() == pytest.approx(np.pi * R * length, rel=0.08)
    assert np.median(np.linalg.norm(gap_v[:, :2] - 32, axis=1)) == pytest.approx(R, abs=1.0)
    comp = complete(faint, line, half)
    assert comp.coverage == pytest.approx(0.5, abs=0.04)            # the observed half over the whole tube
    assert comp.hole[len(comp.hole) - len(gap_v):].all()
    assert complete(faint, line, half, gaps=False).coverage > 0.95  # without: the faint half is simply left out
    # a whole tube has a wall in every direction: nothing added; a surface that is open (the half pipe's
    # exact heatmap: nothing faint where the wall is missing, as where a real colon's walls touch) gets
    # only the rays that pass within about 2 voxels of its two edges, where the heatmap dips
    assert len(wall_gaps(hm.target, line, planes)[1]) == 0
    pts, hm = half_pipe()
    line = extract_centerline(hm.target)
    gap_v, gap_f = wall_gaps(hm.target, line, segment_planes(line, UNIT.to_voxel(pts), cut_rims=False))
    assert triangle_areas(gap_v, gap_f).sum() < 0.15 * np.pi * R * np.ptp(gap_v[:, 2])
    assert (np.abs(gap_v[gap_f].mean(axis=1)[:, 0] - 32) < 0.3 * R).all()


def test_a_cut_window_is_found_as_a_hole_of_its_area():
    colon, grid, pts, hm = tube_heatmaps(straight(63.0), UNIT)
    theta = np.arctan2(pts[:, 1], pts[:, 0])
    window = (np.abs(theta) < 0.5) & (pts[:, 2] > 20) & (pts[:, 2] < 40)  # 1 rad x 20 mm: 400 mm^2
    est = from_heatmap(hm.target, grid, pts[~window])
    wall = 2 * np.pi * R * (est.mesh_vertices[:, 2].max() - est.mesh_vertices[:, 2].min())
    assert 1 - est.coverage == pytest.approx(R * 1.0 * 20.0 / wall, abs=0.01)
    inside = (np.abs(np.arctan2(est.holes[:, 1], est.holes[:, 0])) < 0.55) & (est.holes[:, 2] > 19) & \
        (est.holes[:, 2] < 41)
    assert inside.mean() > 0.95


def test_end_planes_follow_the_axis_when_the_last_voxel_wobbles():
    # a straight centerline along z whose end voxel sits 1.5 voxels to the side, as a ridge's last voxel
    # can: the planes stay perpendicular to the axis, and a tube clipped by them keeps its whole length
    from colonbench.completion.surface import clip_to_segment, end_planes

    line = np.stack([np.full(41, 32.0), np.full(41, 32.0), np.arange(10.0, 51.0)], 1)
    line[-1, 0] += 1.5
    line[0, 1] -= 1.5
    planes = end_planes(line)
    assert len(planes) == 2
    for (point, normal), inward in zip(planes, ([0, 0, 1.0], [0, 0, -1.0])):
        assert np.degrees(np.arccos(normal @ inward)) < 8.0
    colon, grid, pts, hm = tube_heatmaps(straight(63.0), UNIT)
    comp = complete(hm.target, extract_centerline(hm.target), grid.to_voxel(pts))
    v, f = clip_to_segment(comp.vertices, comp.faces, line)
    z = v[f].mean(axis=1)[:, 2]
    assert z.min() < 12.0 and z.max() > 48.0
    assert triangle_areas(v, f).sum() == pytest.approx(2 * np.pi * R * 38.0, rel=0.05)


def _cut_tube_cloud(z0=10.0, z1=50.0, radius=R, density=2.0, tilt_deg=0.0, seed=0):
    """Points on a tube along z (voxel units, axis at x = y = 32) cut at z0 and by a plane through
    (32, 32, z1) tilted by ``tilt_deg`` about x; the far plane's outward unit normal."""
    rng = np.random.default_rng(seed)
    n = int(density * 2 * np.pi * radius * (z1 - z0 + radius))
    theta, z = rng.uniform(0, 2 * np.pi, n), rng.uniform(z0, z1 + radius, n)
    pts = np.stack([32 + radius * np.cos(theta), 32 + radius * np.sin(theta), z], 1)
    t = np.radians(tilt_deg)
    out = np.array([0.0, -np.sin(t), np.cos(t)])
    return pts[(pts - [32, 32, z1]) @ out <= 0], out


@pytest.mark.parametrize("tilt", [0.0, 20.0])
def test_cut_rims_give_the_planes_a_short_centerline_misses(tilt):
    # the network's ridge fades before the segment ends: its centerline stops 8 voxels short of each cut;
    # the cloud's rims give the cuts back (the far one tilted by `tilt` degrees)
    from colonbench.completion.surface import rim_planes

    pts, far = _cut_tube_cloud(tilt_deg=tilt)
    line = np.stack([np.full(25, 32.0), np.full(25, 32.0), np.linspace(18.0, 42.0, 25)], 1)
    (p0, n0), (p1, n1) = rim_planes(line, pts)
    assert np.degrees(np.arccos(n0 @ [0, 0, 1.0])) < 3.0 and abs(p0[2] - 10.0) < 1.0
    assert np.degrees(np.arccos(n1 @ -far)) < 3.0 and abs((p1 - [32, 32, 50.0]) @ far) < 1.0
    # where the line reaches the cut, its own planes are kept
    full = np.stack([np.full(41, 32.0), np.full(41, 32.0), np.linspace(10.5, 49.5, 41)], 1)
    (q0, m0), _ = rim_planes(full, _cut_tube_cloud()[0])
    assert np.allclose(q0, full[0]) and np.allclose(m0, [0, 0, 1.0], atol=1e-6)


def test_an_end_without_a_rim_keeps_the_line_plane_pushed_out_to_the_cloud():
    # the last 15 voxels before the far cut seen on one side only: no rim there, so the end keeps the
    # centerline's plane; the cloud runs on 8 voxels past the line's end (to z = 50), and every observed
    # point belongs to the segment, so the plane moves out to it (steps 7) and the coverage is the
    # analytic one of the tube between z = 10 and 50: (25 + 15 / 3) / 40 = 0.75 (0.85 at the line's end)
    from colonbench.completion.surface import end_planes, pushed_out, rim_planes

    pts, _ = _cut_tube_cloud()
    pts = pts[(pts[:, 2] < 35.0) | (pts[:, 0] > 32.0 + 10.0)]
    line = np.stack([np.full(25, 32.0), np.full(25, 32.0), np.linspace(18.0, 42.0, 25)], 1)
    rims, ends = rim_planes(line, pts), end_planes(line)
    assert abs(rims[0][0][2] - 10.0) < 1.0
    assert np.allclose(rims[1][1], ends[1][1]) and np.allclose(rims[1][0][:2], ends[1][0][:2])
    assert abs(rims[1][0][2] - 50.0) < 0.5
    *_, hm = tube_heatmaps(straight(63.0), UNIT)
    assert complete(hm.target, line, pts).coverage == pytest.approx(0.75, abs=0.02)
    # a cloud that stops before the plane, or runs past it with fewer than 20 points, leaves it where it is
    point, normal = ends[1]
    assert pushed_out(point, normal, pts[pts[:, 2] < 42.0])[0] is point
    assert pushed_out(point, normal, pts[pts[:, 2] < 42.05])[0] is point


def test_the_wall_gaps_run_on_past_the_line_to_a_pushed_out_plane():
    # the cloud of the test above, and a prediction whose wall fades (0.3, the network unsure) on the
    # unseen side (x < 32) past z = 43, where the line has ended: the stretch between the line's end (42)
    # and the pushed-out plane (50) is in the segment, its unseen half has no surface voxel, and the wall
    # gaps there come from stations on the line run on straight to the plane, in the lumen (steps 8). Coverage: the
    # analytic 0.75 of the tube between z = 10 and 50; with stations on the line alone that half is
    # simply left out (0.81)
    from colonbench.completion.surface import reach_planes, rim_planes

    pts, _ = _cut_tube_cloud()
    pts = pts[(pts[:, 2] < 35.0) | (pts[:, 0] > 32.0 + 10.0)]
    line = np.stack([np.full(25, 32.0), np.full(25, 32.0), np.linspace(18.0, 42.0, 25)], 1)
    *_, hm = tube_heatmaps(straight(63.0), UNIT)
    faint = hm.target.copy()
    faint[:32, :, 44:] = np.maximum(faint[:32, :, 44:], 0.3)
    planes = rim_planes(line, pts)
    run_on = reach_planes(line, planes)
    assert run_on[0, 2] == pytest.approx(10.0, abs=1.0) and run_on[-1, 2] == pytest.approx(50.0, abs=1.0)
    assert np.allclose(run_on[:, :2], 32.0, atol=0.3)               # straight on, along the tube
    assert np.array_equal(reach_planes(line, [planes[0]]), line)   # not one plane per end: as it is
    assert reach_planes(line, planes, faint)[-1, 2] == pytest.approx(50.0, abs=1.0)   # in the lumen all along
    walled = faint.copy()
    walled[:, :, 46:48] = 0.0                                       # a wall across the tube: the run-on stops there
    assert reach_planes(line, planes, walled)[-1, 2] == pytest.approx(45.0, abs=0.6)
    comp = complete(faint, line, pts)
    assert comp.coverage == pytest.approx(0.75, abs=0.02)
    gap_v, gap_f = wall_gaps(faint, line, planes)
    centroid = gap_v[gap_f].mean(axis=1)
    assert (centroid[:, 2] > 42.0).all() and (centroid[:, 0] < 33.5).all()   # past the line, on the unseen side
    assert triangle_areas(gap_v, gap_f).sum() == pytest.approx(np.pi * 20.0 * np.ptp(gap_v[:, 2]), rel=0.1)


@pytest.mark.parametrize("density", [0.5, 2.0, 8.0])
def test_a_cut_window_in_a_sparse_or_dense_cloud_is_a_hole_of_its_area(density):
    # the same window, the surface sampled uniformly at random at `density` points/mm^2 (a reconstruction's
    # cloud): the paper's fixed distance calls the gaps of a sparse cloud holes; the widened one does not
    from colonbench.meshes import sample_surface

    colon, grid, _, hm = tube_heatmaps(straight(63.0), UNIT)
    mesh = colon.mesh
    pts = sample_surface(np.random.default_rng(1), mesh.vertices, mesh.faces, density)
    theta = np.arctan2(pts[:, 1], pts[:, 0])
    window = (np.abs(theta) < 0.5) & (pts[:, 2] > 20) & (pts[:, 2] < 40)
    est = from_heatmap(hm.target, grid, pts[~window])
    wall = 2 * np.pi * R * (est.mesh_vertices[:, 2].max() - est.mesh_vertices[:, 2].min())
    assert 1 - est.coverage == pytest.approx(R * 1.0 * 20.0 / wall, abs=0.015)
    if density < 1:
        paper = complete(hm.target, extract_centerline(hm.target), grid.to_voxel(pts[~window]))
        hole = hole_vertices(paper.vertices, grid.to_voxel(pts[~window]), false_hole_rate=None)
        assert mesh_coverage(paper.vertices, paper.faces, hole) < est.coverage - 0.1


def test_dense_clouds_are_thinned_to_the_training_density():
    # a tube sampled at 2, 10 and 30 points/mm^2: the density is measured as sampled; clouds above 3 points/mm^2
    # come back at 2, the same points each time, in their order; a 2 points/mm^2 cloud comes back as it is
    from colonbench.completion.method import MIN_POINTS, THIN_TO, thin_dense
    from colonbench.completion.surface import cloud_density
    from colonbench.meshes import sample_surface

    colon, grid, _, hm = tube_heatmaps(straight(63.0), UNIT)
    mesh = colon.mesh
    clouds = {d: sample_surface(np.random.default_rng(1), mesh.vertices, mesh.faces, d) for d in (2.0, 10.0, 30.0)}
    for d, pts in clouds.items():
        assert cloud_density(pts) == pytest.approx(d, rel=0.1)
    assert thin_dense(clouds[2.0]) is clouds[2.0]
    for d in (10.0, 30.0):
        thin = thin_dense(clouds[d])
        assert cloud_density(thin) == pytest.approx(THIN_TO, rel=0.1)
        assert len(thin) == pytest.approx(len(clouds[d]) * THIN_TO / d, rel=0.1)
        assert np.array_equal(thin, thin_dense(clouds[d].copy()))                    # seeded by the cloud
        assert (np.diff(np.flatnonzero(np.isin(clouds[d][:, 0], thin[:, 0]))) > 0).all()   # in their order
        assert thin_dense(clouds[d], above=None) is clouds[d]
    pts = clouds[30.0]
    theta = np.arctan2(pts[:, 1], pts[:, 0])
    scrap = pts[(pts[:, 2] < 3.0) & (np.abs(theta) < 0.5)]   # 60 mm^2, 1800 points: never thinned below the minimum
    assert len(scrap) * THIN_TO / cloud_density(scrap) < MIN_POINTS < len(scrap)
    assert len(thin_dense(scrap)) == MIN_POINTS
    # a window cut into a dense noisy scan: noise carries points into it, so the dense cloud reads the window
    # smaller than it is; thinned, the estimate (on the exact heatmap) comes closer to its area
    window = (np.abs(theta) < 0.5) & (pts[:, 2] > 20) & (pts[:, 2] < 40)
    noisy = pts[~window] + np.random.default_rng(2).normal(scale=0.5, size=pts[~window].shape)
    raw, thinned = from_heatmap(hm.target, grid, noisy), from_heatmap(hm.target, grid, thin_dense(noisy))
    wall = 2 * np.pi * R * np.ptp(raw.mesh_vertices[:, 2])
    truth = 1 - R * 1.0 * 20.0 / wall
    assert raw.coverage - truth > 0.008 and abs(thinned.coverage - truth) < 0.5 * abs(raw.coverage - truth)


def test_gt_heatmap_as_prediction_bounds_the_error_after_the_network(smoke_dataset):
    out, _ = smoke_dataset
    ds = ShardDataset(out, geometry=True)
    errors = []
    for k in range(len(ds)):
        item = ds[k]
        shard, i = ds.locate(k)
        est = from_heatmap(item["target"][0], shard.grid(i), item["partial_points"])
        if item["outside_grid"] < 0.01:  # the grid holds the segment (it is fitted to the partial cloud)
            errors.append(est.coverage - item["coverage"])
        cl_d, _ = cKDTree(item["centerline"]).query(est.centerline)
        assert np.mean(cl_d < 2.0) > 0.95  # centerline precision at 2 mm
    errors = np.abs(errors)
    assert len(errors) >= 6
    # about a point from the truth (on paper.yaml's test split: MAE 1.3, median 0.9 points); the rest is
    # false holes where marching cubes cannot follow a fold thinner than a voxel (1.5 mm on these coarse colons)
    assert np.median(errors) < 0.015 and errors.mean() < 0.02 and errors.max() < 0.04, errors


@pytest.fixture(scope="module")
def tiny_run(smoke_dataset, tmp_path_factory):
    out, _ = smoke_dataset
    run = tmp_path_factory.mktemp("run")
    cfg = TrainConfig(epochs=1, batch_size=2, workers=0, augment_prob=0.5)
    result = train(out, run, cfg, device="cpu", progress=False)
    return out, run, cfg, result


def test_train_save_load_predict_round_trip(tiny_run):
    out, run, cfg, result = tiny_run
    assert result["epochs"] == 1 and result["steps"] == 2
    log = (run / "log.csv").read_text().splitlines()
    assert log[0].startswith("epoch,steps") and len(log) == 2
    net, config, meta = load_model(run / "best.safetensors")
    assert config == network_config("small") and meta["steps"] == 2 and meta["data_manifest_sha256"]
    again = run / "copy.safetensors"
    save_model(again, net, config, meta)
    net2, _, _ = load_model(again)
    for (k, a), (_, b) in zip(net.state_dict().items(), net2.state_dict().items()):
        assert torch_equal(a, b), k
    method = CompletionMethod(run / "best.safetensors")
    item = ShardDataset(out, split="test", geometry=True)[0]
    grid, h_in, pred = method.predict(item["partial_points"].astype(float))
    np.testing.assert_allclose(h_in, item["input"][0], atol=1e-3)  # voxelized exactly as in training
    assert pred.shape == (64, 64, 64) and 0 <= pred.min() and pred.max() <= 1
    import torch

    with torch.no_grad():
        eager = np.clip(net(torch.from_numpy(h_in[None, None]))[0, 0].numpy(), 0, 1)
    np.testing.assert_allclose(pred, eager, atol=1e-6)      # the first cloud: the eager network
    _, _, again = method.predict(item["partial_points"].astype(float) + 1e-9)   # not the cached prediction
    assert 64 in method.predictor._forward                     # from the second on: made fast for inference
    np.testing.assert_allclose(again, eager, atol=1e-4)
    est = method.estimate(item["partial_points"].astype(float))
    assert 0 <= est.coverage <= 1 or np.isnan(est.coverage)
    assert set(est.seconds) >= {"network", "centerline", "mesh_holes"}
    # the centerline with the ridge's own ends (steps before 6; the map's segment-only track): its version
    # says so, and its line is the one extract_centerline gives with end_level None
    ridge = CompletionMethod(run / "best.safetensors", end_level=None)
    assert ridge.version.endswith(",end_level=None") and "end_level" not in method.version
    p = ridge.predictor(check_cloud(item["partial_points"].astype(float)))
    est_ridge = ridge.estimate(item["partial_points"].astype(float))
    assert 0 <= est_ridge.coverage <= 1 or np.isnan(est_ridge.coverage)
    line = extract_centerline(p.heatmap, end_level=None)
    if len(line) >= 2 and len(est_ridge.centerline):       # the reported line: a piece of that one (between the planes)
        assert distance_to_polyline(est_ridge.centerline, p.grid.to_mm(line)).max() < 0.1


def torch_equal(a, b):
    import torch

    return torch.equal(a, b)


def test_fine_tuning_starts_from_the_given_model(tiny_run, tmp_path):
    import torch

    out, run, _, _ = tiny_run
    start, _, _ = load_model(run / "best.safetensors")
    cfg = TrainConfig(epochs=1, batch_size=2, workers=0, augment_prob=0.0, lr=1e-12, init=str(run / "best.safetensors"))
    train(out, tmp_path / "tuned", cfg, device="cpu", progress=False)
    tuned, _, meta = load_model(tmp_path / "tuned" / "best.safetensors")
    # a step of 1e-12 leaves the weights where the given model had them (random ones would differ entirely;
    # batch-norm running statistics, buffers, move with the data whatever the step)
    for (k, a), (_, b) in zip(start.named_parameters(), tuned.named_parameters()):
        assert torch.allclose(a, b, atol=1e-6), k
    assert meta["train_config"]["init"] == str(run / "best.safetensors")
    # a resumed run may name its starting weights otherwise (a shipped model renamed), not give others
    import dataclasses
    import shutil

    from colonbench.shards.schema import sha256_file

    renamed = tmp_path / "renamed.safetensors"
    shutil.copy(run / "best.safetensors", renamed)
    cfg = dataclasses.replace(cfg, init_sha256=sha256_file(renamed))
    train(out, tmp_path / "named", cfg, device="cpu", progress=False)
    more = train(out, tmp_path / "named", dataclasses.replace(cfg, epochs=2, init=str(renamed)), device="cpu",
                 progress=False)
    assert more["epochs"] == 2
    with pytest.raises(InputError, match="other settings"):
        train(out, tmp_path / "named", dataclasses.replace(cfg, epochs=3, init=str(renamed), init_sha256="0" * 64),
              device="cpu", progress=False)
    with pytest.raises(InputError, match="no such model file"):
        train(out, tmp_path / "other", TrainConfig(epochs=1, batch_size=2, workers=0, init=str(tmp_path / "none.safetensors")),
              device="cpu", progress=False)


def test_training_resumes_and_refuses_other_settings(tiny_run):
    out, run, cfg, _ = tiny_run
    import dataclasses

    # keeping every epoch's weights is a run-length setting: it may be switched on when resuming
    more = train(out, run, dataclasses.replace(cfg, epochs=2, keep_epochs=True), device="cpu", progress=False)
    assert more["epochs"] == 2 and more["steps"] == 4
    log = (run / "log.csv").read_text().splitlines()
    assert len(log) == 3
    assert sorted(p.name for p in run.glob("epoch-*.safetensors")) == ["epoch-001.safetensors"]
    _, _, meta = load_model(run / "epoch-001.safetensors")
    assert meta["epoch"] == 1 and meta["steps"] == 4 and f"{meta['val_l2']:.6f}" == log[2].split(",")[4]
    with pytest.raises(InputError, match="other settings"):
        train(out, run, dataclasses.replace(cfg, epochs=3, lr=0.5), device="cpu", progress=False)


def test_training_needs_train_and_validation_splits(tmp_path):
    from colonbench.shards.dataset import generate
    from conftest import MANIFESTS

    generate(MANIFESTS / "smoke.yaml", tmp_path / "d", splits=["test"], progress=False)
    with pytest.raises(InputError, match="no train and no validation split"):
        train(tmp_path / "d", tmp_path / "run", TrainConfig(epochs=1), device="cpu", progress=False)
    with pytest.raises(InputError, match="seed and workers"):
        train(tmp_path / "d", tmp_path / "run", TrainConfig(seed=-1), device="cpu", progress=False)
    with pytest.raises(InputError, match="neither dataset.lock.json nor pack.json"):
        train(tmp_path / "nothing", tmp_path / "run", TrainConfig(epochs=1), device="cpu", progress=False)


@pytest.mark.parametrize("cloud, message", [
    (np.zeros((0, 3)), "at least"),
    (np.random.default_rng(0).normal(size=(12, 3)) * 20, "only 12 point"),
    (np.full((500, 3), np.nan), "NaN"),
    (np.random.default_rng(0).normal(size=(5000, 3)) * 0.02, "metres"),
    # a 60 mm segment of a 15 mm-radius tube written in centimetres: 6.7 units across
    (np.c_[1.5 * np.cos(np.linspace(0, 60, 3000)), 1.5 * np.sin(np.linspace(0, 60, 3000)),
           np.linspace(0, 6, 3000)], "looks like centimetres"),
    (np.random.default_rng(0).normal(size=(5000, 3)) * 300, "far more than one colon segment"),
    (np.ones((500, 3)), "all 500 points coincide"),
    (np.repeat(np.random.default_rng(0).uniform(0, 50, (20, 3)), 30, axis=0),
     "only 20 point.s. once repeated points are dropped .600 given."),
    (np.linspace(0, 60, 500)[:, None] * [[1.0, 0.5, 0.0]], "lie on a line"),
    (np.c_[np.random.default_rng(0).uniform(0, 50, (500, 2)), np.full(500, 7.0)], "lie in one plane"),
])
def test_bad_clouds_get_clear_messages(cloud, message):
    with pytest.raises(InputError, match=message):
        check_cloud(cloud)


def test_the_smallest_segment_is_not_taken_for_centimetres():
    # the widened generator's smallest segment: 10 mm radius, 20 mm long (its diameter), a third of its wall seen
    theta, z = np.meshgrid(np.linspace(0, 2 * np.pi / 3, 40), np.linspace(0, 20, 30))
    wall = np.c_[10 * np.cos(theta).ravel(), 10 * np.sin(theta).ravel(), z.ravel()]
    assert len(check_cloud(wall)) == 1200


def test_a_nearly_flat_wall_is_a_cloud():
    # a 40 mm-wide strip of a 40 mm-radius wall bulges 5.4 mm: curved, not refused as flat
    theta, z = np.meshgrid(np.linspace(-0.5, 0.5, 40), np.linspace(0, 50, 50))
    wall = np.c_[40 * np.sin(theta).ravel(), 40 * np.cos(theta).ravel(), z.ravel()]
    assert len(check_cloud(wall)) == 2000


def test_estimate_command_writes_one_json_per_input(tiny_run, tmp_path, capsys):
    out, run, _, _ = tiny_run
    ds = ShardDataset(out, split="test", geometry=True)
    inputs = []
    for k in range(2):
        folder = tmp_path / f"seg{k}"
        folder.mkdir()
        inputs.append(write_points_ply(folder / "partial.ply", ds[k]["partial_points"]))
    np.save(tmp_path / "other.npy", ds[0]["partial_points"])
    res = tmp_path / "res"
    assert main(["estimate", *map(str, inputs), str(tmp_path / "other.npy"), "--model", str(run / "best.safetensors"),
                 "--out-dir", str(res), "--mesh"]) == 0
    for name in ("seg0", "seg1", "other"):
        data = json.loads((res / f"{name}.json").read_text())
        assert {"coverage", "holes", "centerline", "method"} <= set(data)
        assert data["method"] == "completion"
        assert all(len(p) == 3 for p in data["centerline"])
    assert (res / "seg0_mesh.ply").exists() and (res / "seg0_centerline.ply").exists()
    # one bad input among good ones: named, the others still written
    (tmp_path / "bad.xyz").write_text("1 2 3\n")
    assert main(["estimate", str(tmp_path / "bad.xyz"), str(tmp_path / "other.npy"), "--model",
                 str(run / "best.safetensors"), "--out-dir", str(tmp_path / "res2")]) == 2
    err = capsys.readouterr().err
    assert "bad.xyz" in err and "only 1 point" in err and "1 of 2 input(s) failed" in err
    assert "the others were written" in err
    # a reader's message names the file once, not twice
    np.save(tmp_path / "six.npy", np.zeros((300, 6)))
    assert main(["estimate", str(tmp_path / "six.npy"), "--model", str(run / "best.safetensors"),
                 "--out-dir", str(tmp_path / "res3")]) == 2
    err = capsys.readouterr().err
    assert err.count("six.npy") == 1 and "got an array of shape (300, 6)" in err
    assert "1 of 1 input(s) failed (see above); nothing was written" in err
    assert (tmp_path / "res2" / "other.json").exists()


def test_two_process_distributed_training(smoke_dataset, tmp_path):
    # PyTorch's own launcher and DistributedDataParallel, on the CPU (gloo)
    import subprocess
    import sys

    out, _ = smoke_dataset
    run = tmp_path / "ddp"
    proc = subprocess.run([sys.executable, "-m", "torch.distributed.run", "--nproc_per_node", "2",
                           "--master_port", "29517", "-m", "colonbench.cli", "train", str(out), "--out", str(run),
                           "--epochs", "1", "--batch-size", "1", "--workers", "0", "--device", "cpu", "--quiet"],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    _, _, meta = load_model(run / "best.safetensors")
    assert meta["world_size"] == 2 and meta["steps"] == 2 and meta["samples_seen"] == 4
    assert len((run / "log.csv").read_text().splitlines()) == 2


def test_network_shapes():
    import torch

    net = build_network(network_config("small"))
    assert net(torch.zeros(1, 1, 64, 64, 64)).shape == (1, 1, 64, 64, 64)


def test_the_network_made_fast_for_inference_gives_the_same_output():
    import torch

    from colonbench.completion.network import for_inference

    torch.manual_seed(0)
    net = build_network(network_config("small"))
    for m in net.modules():                # batch norms with statistics that folding must carry over
        if isinstance(m, torch.nn.BatchNorm3d):
            m.running_mean.uniform_(-0.5, 0.5)
            m.running_var.uniform_(0.5, 2.0)
    net.eval()
    fast = for_inference(net, 32, torch.device("cpu"))
    x = torch.rand(1, 1, 32, 32, 32)
    with torch.inference_mode():
        np.testing.assert_allclose(fast(x).numpy(), net(x).numpy(), atol=1e-4)


def test_sigterm_stops_training_cleanly_and_it_resumes(smoke_dataset, tmp_path):
    import os
    import signal
    import subprocess
    import sys
    import time

    import torch

    out, _ = smoke_dataset
    run = tmp_path / "run"
    cmd = [sys.executable, "-m", "colonbench.cli", "train", str(out), "--out", str(run), "--epochs", "50",
           "--batch-size", "1", "--workers", "1", "--device", "cpu", "--quiet"]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True)
    deadline = time.time() + 120
    while not (run / "log.csv").exists() and time.time() < deadline and proc.poll() is None:
        time.sleep(0.2)
    time.sleep(3)  # into the first epochs, a DataLoader worker running
    os.killpg(proc.pid, signal.SIGTERM)  # to the whole process group, as a shell's Ctrl-C or a scheduler does
    stdout, stderr = proc.communicate(timeout=120)
    assert proc.returncode == 0, stderr[-2000:]
    assert "stopped on request" in stdout
    # the closing line names the model only when one was written (not before the first epoch ends)
    assert ("Model: " in stdout) == (run / "best.safetensors").exists()
    assert ("No model yet" in stdout) != (run / "best.safetensors").exists()
    saved = torch.load(run / "last.pt", weights_only=False)
    assert saved["state"]["steps"] > 0 and saved["state"]["epoch"] < 50
    # and it goes on from there
    more = train(out, run, TrainConfig(epochs=saved["state"]["epoch"] + 2, batch_size=1, workers=1), device="cpu",
                 progress=False)
    assert more["steps"] > saved["state"]["steps"] and more["stopped"] == "done"


def test_several_datasets_train_together(smoke_dataset, tmp_path):
    import yaml

    from colonbench.shards.dataset import generate
    from colonbench.shards.reader import ShardDataset

    from conftest import MANIFESTS

    out, lock = smoke_dataset
    manifest = yaml.safe_load((MANIFESTS / "smoke.yaml").read_text())
    manifest.update(name="smoke-b", seed=8)
    manifest["splits"] = {"train": {"colons": {"first": 5, "count": 1}, "segments_per_length": 1, "permutations": 1},
                          "validation": {"colons": {"first": 6, "count": 1}, "segments_per_length": 1,
                                         "permutations": 1}}
    (tmp_path / "b.yaml").write_text(yaml.safe_dump(manifest))
    lock_b = generate(tmp_path / "b.yaml", tmp_path / "b", workers=1, progress=False)
    cfg = TrainConfig(epochs=1, batch_size=1, workers=0, augment_prob=0.0)
    result = train([out, tmp_path / "b"], tmp_path / "run", cfg, device="cpu", progress=False)
    n_train = len(ShardDataset(out, split="train")) + len(ShardDataset(tmp_path / "b", split="train"))
    assert result["steps"] == n_train  # one epoch of batch 1 over both train splits
    _, _, meta = load_model(tmp_path / "run" / "best.safetensors")
    assert meta["data_manifests"] == [lock["manifest_sha256"], lock_b["manifest_sha256"]]
    assert meta["data_dir"] == f"{out.name}+b"
    with pytest.raises(InputError, match="is a run on other data"):  # the same run folder, one dataset fewer
        train([out], tmp_path / "run", cfg, device="cpu", progress=False)

    manifest.update(name="smoke-c", grid={"size": 32, "margin": 2, "min_extent_mm": 70.0})
    (tmp_path / "c.yaml").write_text(yaml.safe_dump(manifest))
    generate(tmp_path / "c.yaml", tmp_path / "c", workers=1, progress=False)
    with pytest.raises(InputError, match="need the same grid"):
        train([out, tmp_path / "c"], tmp_path / "run-c", cfg, device="cpu", progress=False)


@pytest.mark.parametrize("density", [2.0, 10.0])
def test_the_estimate_is_the_same_whatever_the_order_of_the_points(density):
    # a tube with a window, sampled like a reconstruction (more points than the grid's normals and the density
    # estimate use): shuffled, and with a fifth of its points repeated, the shipped model must give the same
    # answer (to the rounding of sums over points); at 10 points/mm^2 the cloud is thinned at random first,
    # and that draw depended on the order of the points (steps 10)
    from colonbench.meshes import sample_surface
    from colonbench.grid import even_subsample

    colon = tube_colon(straight(63.0), R, ring_spacing_mm=0.5, n_around=256)
    pts = sample_surface(np.random.default_rng(2), colon.mesh.vertices, colon.mesh.faces, density)
    theta = np.arctan2(pts[:, 1], pts[:, 0])
    pts = pts[~((np.abs(theta) < 0.5) & (pts[:, 2] > 20) & (pts[:, 2] < 40))]
    rng = np.random.default_rng(3)
    repeated = np.concatenate([pts, pts[rng.choice(len(pts), len(pts) // 5)]])
    shuffled = repeated[rng.permutation(len(repeated))]
    assert len(pts) > 3000
    a = np.sort(even_subsample(pts, 1000).view("f8,f8,f8"), axis=0)
    b = np.sort(even_subsample(pts[rng.permutation(len(pts))], 1000).view("f8,f8,f8"), axis=0)
    assert len(a) <= 1000 and np.array_equal(a, b)
    method = CompletionMethod()
    one, other = method.estimate(pts), method.estimate(shuffled)
    assert one.coverage == pytest.approx(other.coverage, abs=1e-6)
    assert 1 - one.coverage == pytest.approx(R * 1.0 * 20.0 / (2 * np.pi * R * 63.0), abs=0.03)  # the window
    assert one.centerline.shape == other.centerline.shape and one.holes.shape == other.holes.shape
    np.testing.assert_allclose(one.centerline, other.centerline, atol=1e-3)   # mm: float32 rounding
    np.testing.assert_allclose(one.holes, other.holes, atol=1e-3)


def test_the_methods_built_on_the_network_share_its_prediction_of_a_dense_cloud():
    # a tube scanned at 10 points/mm^2: completion thins it before the network; thresholding and unwrapping
    # take the same prediction (one network run) and report its line, while counting on every point
    from colonbench.baselines.threshold import ThresholdMethod
    from colonbench.baselines.unwrap import UnwrapMethod
    from colonbench.completion.method import method_cloud, shared_predictor
    from colonbench.completion.surface import cloud_density
    from colonbench.meshes import sample_surface

    colon = tube_colon(straight(63.0), R, ring_spacing_mm=0.5, n_around=256)
    pts = sample_surface(np.random.default_rng(4), colon.mesh.vertices, colon.mesh.faces, 10.0)
    theta = np.arctan2(pts[:, 1], pts[:, 0])
    pts = pts[~((np.abs(theta) < 0.5) & (pts[:, 2] > 20) & (pts[:, 2] < 40))]
    assert cloud_density(pts) > 8 and len(method_cloud(pts)) < len(pts) / 4
    predictor = shared_predictor()
    predictor._cache.clear()
    full = CompletionMethod().estimate(pts)
    unwrap, thresholding = UnwrapMethod().estimate(pts), ThresholdMethod().estimate(pts)
    assert len(predictor._cache) == 1                                  # the network ran once
    np.testing.assert_allclose(unwrap.centerline, full.centerline, atol=0.05)   # the line completion reports
    window = R * 1.0 * 20.0 / (2 * np.pi * R * 63.0)
    for est in (full, unwrap):                                         # (thresholding errs on its own)
        assert 1 - est.coverage == pytest.approx(window, abs=0.04)
    assert np.isfinite(thresholding.coverage)
    assert "thin_above=3" in UnwrapMethod().version and "thin_above=3" in ThresholdMethod().version


def test_the_orientation_probe_cycles_the_grid_axes_and_reproduces_the_method_on_the_fitted_grid():
    # scripts/probe_orientation.py: a straight tube along z with a window of known area; on the grid as fitted
    # the probe's estimate is the method's, and the cycled grids put the tube's axis third, then second
    import importlib.util
    from pathlib import Path

    from colonbench.completion.method import method_cloud
    from colonbench.meshes import sample_surface

    spec = importlib.util.spec_from_file_location(
        "probe_orientation", Path(__file__).resolve().parents[1] / "scripts" / "probe_orientation.py")
    probe = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(probe)
    colon = tube_colon(straight(63.0), R, ring_spacing_mm=0.5, n_around=256)
    pts = sample_surface(np.random.default_rng(2), colon.mesh.vertices, colon.mesh.faces, 2.0)
    theta = np.arctan2(pts[:, 1], pts[:, 0])
    pts = method_cloud(pts[~((np.abs(theta) < 0.5) & (pts[:, 2] > 20) & (pts[:, 2] < 40))])
    method = CompletionMethod()
    options = method.predictor.grid_options
    for shift, row in ((0, 0), (1, 2), (2, 1)):
        rot = probe.cycled_grid(pts, options, shift).rotation
        assert abs(rot[row] @ [0.0, 0.0, 1.0]) > 0.999 and np.allclose(rot @ rot.T, np.eye(3))
    fitted = probe.estimate_on_cycled_grid(method, pts, 0)
    assert fitted.coverage == pytest.approx(method.estimate(pts).coverage, abs=1e-3)
    assert 1 - fitted.coverage == pytest.approx(R * 1.0 * 20.0 / (2 * np.pi * R * 63.0), abs=0.03)  # the window
    assert all(0.0 <= probe.estimate_on_cycled_grid(method, pts, k).coverage <= 1.0 for k in (1, 2))
