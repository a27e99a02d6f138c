"""colonbench map on tubes with known answers: centerline, planes, segment coverage, interruptions, bad input."""

import json

import numpy as np
import pytest
from scipy.spatial import cKDTree
from shapes import helix, straight

from colonbench.benchmark.colon_metrics import map_metrics
from colonbench.benchmark.registry import load_method
from colonbench.cli import main
from colonbench.completion.method import CompletionMethod
from colonbench.datagen.colon import tube_colon
from colonbench.mapping.colonmap import map_colon
from colonbench.mapping.reconstruction_centerline import colon_centerline
from colonbench.meshes import sample_surface

RADIUS = 15.0


def tube_cloud(centerline, density=2.0, seed=0, radius=RADIUS):
    """Points on a tube of ``radius`` around ``centerline``, with each point's arc length and angle."""
    colon = tube_colon(centerline, radius, ring_spacing_mm=1.0, n_around=96)
    rng = np.random.default_rng(seed)
    pts = sample_surface(rng, colon.mesh.vertices, colon.mesh.faces, density=density)
    _, i = cKDTree(centerline.points).query(pts)
    return pts, centerline.arclength[i], centerline


def test_helical_tube_centerline_and_planes(tmp_path):
    line, length = helix(radius=40.0, pitch=70.0, turns=1.6)
    pts, s, _ = tube_cloud(line)
    pieces = colon_centerline(pts)
    assert len(pieces) == 1
    found = pieces[0]
    d, _ = cKDTree(line.points).query(found.points)
    # within a voxel along the lumen; the open ends are extrapolated over about a radius (docs/mapping.md)
    assert np.median(d) < 1.5 and np.percentile(d, 80) < 2.5 and d.max() < 12.0
    assert abs(found.length - length) < 0.03 * length
    # the map's planes: perpendicular to the known tangent, through the known centerline
    np.save(tmp_path / "helix.npy", pts)
    traj = line.points[::-40]  # a withdrawal ending at arc length 0: the map starts there
    np.save(tmp_path / "traj.npy", traj)
    assert main(["map", str(tmp_path / "helix.npy"), "--out", str(tmp_path / "map"), "--trajectory",
                 str(tmp_path / "traj.npy"), "--segment-length", "60", "--no-figure", "--quiet"]) == 0
    segs = json.loads((tmp_path / "map" / "segments.json").read_text())["segments"]
    assert len(segs) == round(length / 60)
    tangents = line.tangents()
    for k, seg in enumerate(segs):
        for plane in ("plane_start", "plane_end")[k == 0:(1 if k == len(segs) - 1 else 2)]:  # the inner planes
            p, n = np.array(seg[plane]["point"]), np.array(seg[plane]["normal"])
            dist, i = cKDTree(line.points).query(p)
            assert dist < 2.5
            assert np.degrees(np.arccos(min(abs(n @ tangents[i]), 1.0))) < 5.0
            assert n @ tangents[i] > 0  # along increasing arc length, which runs with the known one here
        # the plane sits where the known arc length says (from the rectum end: known arc length 0)
        _, i = cKDTree(line.points).query(seg["plane_end"]["point"])
        # the open end is extrapolated and a tight bend cut a little short (docs/mapping.md)
        assert abs(line.arclength[i] - seg["end_mm"]) < 5.0 + 0.03 * seg["end_mm"]
    cl = np.load(tmp_path / "map" / "centerline.npy")
    assert cl.shape[1] == 3 and np.linalg.norm(cl[0] - line.points[0]) < 12.0


@pytest.mark.slow
def test_straight_tube_segments_get_their_known_coverage(tmp_path, capsys):
    line = straight(300.0)
    pts, s, _ = tube_cloud(line, seed=1)
    theta = np.arctan2(pts[:, 1], pts[:, 0])
    # two windows of known area: a quarter of the wall over 70-100 mm, half of it over 190-230 mm
    cut = ((s > 70) & (s < 100) & (theta > 0) & (theta < np.pi / 2)) | ((s > 190) & (s < 230) & (theta > 0))
    # and two rows of invalid depth, left out with a note
    np.save(tmp_path / "tube.npy", np.concatenate([pts[~cut], [[np.nan, 0.0, 0.0], [0.0, np.inf, 1.0]]]))
    traj = np.stack([np.zeros(31), np.zeros(31), np.linspace(300, 0, 31)], axis=1)  # withdrawal to z = 0
    np.savetxt(tmp_path / "traj.txt", np.concatenate([np.arange(31)[:, None], traj,
                                                      np.tile([0, 0, 0, 1.0], (31, 1))], axis=1))
    assert main(["map", str(tmp_path / "tube.npy"), "--out", str(tmp_path / "map"), "--trajectory",
                 str(tmp_path / "traj.txt"), "--quiet"]) == 0
    assert "2 point(s) that are NaN or infinite left out" in capsys.readouterr().err
    segs = json.loads((tmp_path / "map" / "segments.json").read_text())["segments"]
    assert [round(x["start_mm"]) for x in segs] == [0, 60, 120, 180, 240]
    truth = [1.0, 1 - 30 / (4 * 60), 1.0, 1 - 40 / (2 * 60), 1.0]
    inside = 0
    for seg, t in zip(segs, truth):
        low, high = seg["coverage_interval"]     # the method's 90 % interval for a segment whose ends are known
        inside += low <= t <= high               # a 90 % interval may miss, here never by more than 2 points
        assert low - 0.02 <= t <= high + 0.02 and high - low < 0.25 and isinstance(seg["review"], list)
        assert seg["plane_start"]["point"][2] == pytest.approx(seg["start_mm"], abs=4.0)
        assert abs(seg["plane_start"]["normal"][2]) > np.cos(np.radians(5))
        assert seg["coverage"] == pytest.approx(t, abs=0.08), (seg, t)
    assert inside >= 3              # (0166's: 5 points wide; the first ends 0.0001, the last 0.014 short of 1)
    assert segs[3]["largest_hole_mm2"] > 0.5 * 40 * np.pi * RADIUS
    summary = json.loads((tmp_path / "map" / "summary.json").read_text())
    whole = 1 - (30 * RADIUS * np.pi / 2 + 40 * RADIUS * np.pi) / (2 * np.pi * RADIUS * 300)
    assert summary["coverage"] == pytest.approx(whole, abs=0.05)
    assert summary["interruptions"] == [] and summary["orientation"].startswith("from the rectum")
    version = json.loads((tmp_path / "map" / "segments.json").read_text())["version"]    # the calibration used
    shipped = CompletionMethod()
    assert summary["version"] == version == shipped.version
    assert f",intervals={shipped.intervals.source['id']}" in version
    for name in ("segments.csv", "centerline.npy", "map.ply", "map.glb", "map.png"):
        assert (tmp_path / "map" / name).stat().st_size > 0
    # with the neighbours' points as context, coverage counted between the planes only
    traj_xyz = np.loadtxt(tmp_path / "traj.txt")[:, 1:4]
    ctx = map_colon(pts[~cut], load_method("completion"), positions=traj_xyz, progress=False, context_mm=15.0)
    for seg, t in zip(ctx["segments"][1:4], truth[1:4]):
        assert seg.coverage == pytest.approx(t, abs=0.08)
        z = seg.mesh[0][:, 2]  # the completed surface, clipped at the segment's planes
        assert z.min() > seg.plane_start["point"][2] - 2 and z.max() < seg.plane_end["point"][2] + 2
    # the whole-colon score: each segment's region of the true surface has its known coverage
    tube = tube_colon(line, RADIUS, ring_spacing_mm=0.5, n_around=256)
    c = tube.mesh.vertices[tube.mesh.faces].mean(axis=1)
    ang = np.arctan2(c[:, 1], c[:, 0])
    window = ((c[:, 2] > 70) & (c[:, 2] < 100) & (ang > 0) & (ang < np.pi / 2)) | (
        (c[:, 2] > 190) & (c[:, 2] < 230) & (ang > 0))
    score = map_metrics(segs, summary["coverage"], np.load(tmp_path / "map" / "centerline.npy"),
                        tube.mesh.vertices, tube.mesh.faces, ~window, line)
    inner = score["segment_truth"][1:4]  # the end segments' regions reach past the extrapolated ends
    assert inner == pytest.approx(truth[1:4], abs=0.02)
    assert score["whole_truth"] == pytest.approx(whole, abs=0.005)
    assert score["segment_mae"] < 3.0 and score["centerline_recall"] > 0.85  # the far end stops ~6 mm short


def test_interrupted_colon_is_split_and_reported(tmp_path):
    line = straight(360.0)
    pts, s, _ = tube_cloud(line, density=1.0)
    keep = (s < 150) | (s > 210)  # 60 mm of colon never reconstructed
    pieces = colon_centerline(pts[keep])
    assert len(pieces) == 2
    ends = sorted([p.points[:, 2].min() for p in pieces] + [p.points[:, 2].max() for p in pieces])
    assert ends[1] == pytest.approx(150, abs=5) and ends[2] == pytest.approx(210, abs=5)

    class Constant:  # every segment's estimate 0.5: this test is about the cut, not the method
        name = "half"

        def estimate(self, points):
            return {"coverage": 0.5, "holes": np.zeros((0, 3)), "centerline": np.zeros((0, 3))}

    result = map_colon(pts[keep], Constant(), segment_mm=60.0, progress=False)
    (gap,) = result["interruptions"]
    assert gap["gap_mm"] == pytest.approx(60, abs=6)
    for seg in result["segments"]:  # no segment spans the gap
        assert seg.end_mm <= gap["after_mm"] + 0.02 or seg.start_mm >= gap["after_mm"] + gap["gap_mm"] - 0.02
    assert {seg.piece for seg in result["segments"]} == {0, 1}


def test_a_trajectory_bridges_a_stretch_with_no_reconstruction():
    """60 mm of a straight tube missing and the scope's path through it: one piece, the stretch reported, and
    the segments over it count it unobserved (the method sees all of the rest: known coverage 0.5 and 0)."""
    line = straight(360.0)
    pts, s, _ = tube_cloud(line, density=1.0)
    keep = (s < 150) | (s > 210)
    # a withdrawal from z = 360 down to 0, pushed back in once, 2 mm off the axis
    z = np.concatenate([np.arange(360.0, 100.0, -2.0), np.arange(100.0, 130.0, 2.0), np.arange(130.0, 0.0, -2.0)])
    traj = np.stack([np.full_like(z, 2.0), np.zeros_like(z), z], axis=1)

    class Full:  # every reconstructed segment fully seen: this test is about the stretch without points
        name = "full"

        def estimate(self, points):
            return {"coverage": 1.0, "holes": np.zeros((0, 3)), "centerline": np.zeros((0, 3))}

    from colonbench.mapping.segments import whole_coverage

    result = map_colon(pts[keep], Full(), segment_mm=60.0, positions=traj, progress=False)
    assert result["interruptions"] == []
    (gap,) = result["unreconstructed"]
    # numbered from the rectum (z = 0): the missing stretch is z 150-210, from the rectum too
    assert gap["from_mm"] == pytest.approx(150, abs=6) and gap["to_mm"] == pytest.approx(210, abs=6)
    by_start = {round(seg.start_mm / 10) * 10: seg for seg in result["segments"]}
    assert len(by_start) == 6
    for start, truth in ((0, 1.0), (60, 1.0), (120, 0.5), (180, 0.5), (240, 1.0), (300, 1.0)):
        assert by_start[start].coverage == pytest.approx(truth, abs=0.1), start
    assert whole_coverage(result["segments"]) == pytest.approx(300 / 360, abs=0.06)
    # pieces apart where the wall is there (a narrow stretch the lumen search lost) are joined, not unseen
    from colonbench.mapping.lumen_paths import Piece
    from colonbench.mapping.scope_route import bridge_by_trajectory

    parts = [Piece(line.points[(line.arclength >= a) & (line.arclength <= b)], RADIUS) for a, b in ((0, 150),
                                                                                                    (210, 360))]
    (whole,) = bridge_by_trajectory(parts, traj[::-1], pts)
    assert whole.unseen == [] and whole.length == pytest.approx(360, abs=3)
    (gapped,) = bridge_by_trajectory(parts, traj[::-1], pts[keep])
    assert len(gapped.unseen) == 1 and gapped.unseen[0][1] - gapped.unseen[0][0] == pytest.approx(60, abs=8)
    # the trajectory, not the pieces' nearness, orders and turns them: rectum (its end) first
    from colonbench.mapping.colonmap import orient

    turned, how = orient([Piece(parts[0].points[::-1].copy(), RADIUS), parts[1]], traj)
    assert "ordered" in how
    # the withdrawal ends at z = 0: from there up to 150, then from 210 up to 360
    assert [(round(p.points[0][2]), round(p.points[-1][2])) for p in turned] == [(0, 150), (210, 360)]
    # with no trajectory the colon is split instead, and the stretch is left out of the map
    split = map_colon(pts[keep], Full(), segment_mm=60.0, progress=False)
    assert len(split["interruptions"]) == 1 and split["unreconstructed"] == []


def u_tube(limb=200.0, bend=16.0, spacing=0.5):
    """A U: two parallel 200 mm limbs 32 mm apart (their 15 mm walls 2 mm apart), joined by a half circle."""
    from colonbench.polyline import Centerline

    z = np.arange(0.0, limb, spacing)
    t = np.arange(0.0, np.pi, spacing / bend)
    p = np.concatenate([np.stack([0 * z, 0 * z, z], 1),
                        np.stack([bend - bend * np.cos(t), 0 * t, limb + bend * np.sin(t)], 1),
                        np.stack([0 * z + 2 * bend, 0 * z, limb - z], 1)])
    return Centerline(p, np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(p, axis=0), axis=1))]))


def test_the_trajectory_keeps_the_centerline_out_of_a_hole_between_touching_limbs():
    """Two limbs of a U touch, and a hole through both walls 40 mm from the open ends joins their lumens
    (as where a real colon's loops lie against each other). The lumen's longest path then cuts through the
    hole and leaves out the 370 mm around the bend; the scope's trajectory keeps the line on the colon."""
    line = u_tube()
    pts, _, _ = tube_cloud(line)
    pts = pts[np.linalg.norm(pts - [16.0, 0.0, 40.0], axis=1) > 9.0]
    length = line.arclength[-1]

    def recall(pieces):
        found = np.concatenate([p.points for p in pieces])
        return float(np.mean(cKDTree(found).query(line.points)[0] < 3.0))

    blind = colon_centerline(pts)
    assert sum(p.length for p in blind) < 0.7 * length and recall(blind) < 0.7  # the shortcut, without poses
    traj = line.points[::-20] + [0.0, 2.0, 0.0]  # a withdrawal, 2 mm off the axis
    guided = colon_centerline(pts, positions=traj)
    assert len(guided) == 1 and guided[0].length == pytest.approx(length, rel=0.03)
    assert recall(guided) > 0.9
    # where the lumen's own path leaves nothing of the trajectory out, a trajectory off the axis does not pull it
    line = straight(240.0)
    pts, _, _ = tube_cloud(line)
    (own,) = colon_centerline(pts)
    (kept,) = colon_centerline(pts, positions=line.points[::-10] + [10.0, 0.0, 0.0])  # 2/3 of the way to the wall
    assert np.median(np.hypot(kept.points[:, 0], kept.points[:, 1])) < 2.0  # within a voxel of the axis
    np.testing.assert_allclose(kept.points, own.points)


def test_pieces_facing_each_other_across_touching_limbs_are_joined_around_the_bend_the_scope_took():
    """The U's bend and 30 mm either side not reconstructed: the two limbs' ends face each other 32 mm
    apart, their walls line the straight line between them, and the colon runs 110 mm around. Without a
    trajectory the ends are bridged straight; with a withdrawal (pushed back in 20 mm in the gap) the
    line goes around with the scope, and the 110 mm is reported as not reconstructed."""
    from colonbench.mapping.scope_route import bridge_by_trajectory, loop_erased
    from colonbench.mapping.colonmap import orient

    line = u_tube()
    pts, s, _ = tube_cloud(line)
    pts = pts[(s < 170) | (s > 280)]
    arc = np.concatenate([np.arange(450.0, 230.0, -2.0), np.arange(230.0, 250.0, 2.0), np.arange(250.0, 0.0, -2.0)])
    traj = line.point_at(arc) + [0.0, 2.0, 0.0]
    erased = loop_erased(traj)  # the push-back erased: each place passed once, in order
    assert len(erased) < len(traj) and np.all(np.diff(cKDTree(line.points).query(erased)[1]) <= 0)

    def mapped(positions):
        pieces, _ = orient(colon_centerline(pts, positions=positions), positions)
        return bridge_by_trajectory(pieces, positions, pts)

    (straight_across,) = mapped(None)
    assert straight_across.length < 0.85 * line.arclength[-1]
    (around,) = mapped(traj)
    assert around.length == pytest.approx(line.arclength[-1], rel=0.03)
    assert np.mean(cKDTree(around.points).query(line.points)[0] < 3.0) > 0.95
    ((u0, u1),) = around.unseen  # from the rectum end: known arc length 450 - 280 = 170 on, 110 mm long
    assert u0 == pytest.approx(170, abs=8) and u1 - u0 == pytest.approx(110, abs=12)


def test_a_shortcut_through_a_hole_where_the_bend_is_missing_is_cut_and_mapped_along_the_scope():
    """The U's limbs touch and a hole through both walls 40 mm from the open ends joins their lumens, and the
    bend with 30 mm either side is not reconstructed (as on the real colon gca00060, where the colon around
    a hole between touching limbs is collapsed). The lumen then has no way around: its path runs up one limb,
    through the hole and up the other, however the trajectory weighs it, and the colon it left out lies past
    two dead ends. Along such a line the place where the scope passed its nearest point jumps at the hole;
    the map cuts it there and joins the parts along the scope, around the bend, from the rectum."""
    from colonbench.mapping.colonmap import join_pieces, map_centerline

    line = u_tube()
    pts, s, _ = tube_cloud(line)
    pts = pts[(np.linalg.norm(pts - [16.0, 0.0, 40.0], axis=1) > 12.0) & ((s < 170) | (s > 280))]
    # a withdrawal from the far end (arc length 450) to the rectum (0), pushed back in 20 mm in the gap,
    # 2 mm off the axis towards the other limb and 2 mm sideways
    arc = np.concatenate([np.arange(450.0, 230.0, -2.0), np.arange(230.0, 250.0, 2.0), np.arange(250.0, 0.0, -2.0)])
    on = line.point_at(arc)
    inward = np.stack([np.full(len(on), 16.0), np.zeros(len(on)), np.minimum(on[:, 2], 200.0)], 1) - on
    traj = on + 2.0 * inward / np.linalg.norm(inward, axis=1, keepdims=True) + [0.0, 2.0, 0.0]
    tree = cKDTree(line.points)

    def true_arc(points):
        return line.arclength[tree.query(points)[1]]

    (blind,) = colon_centerline(pts, positions=traj)  # the lumen's path: one limb, the hole, the other limb
    assert blind.length < 0.65 * line.arclength[-1] and np.abs(np.diff(true_arc(blind.points))).max() > 200
    pieces, _ = map_centerline(pts, traj, pieces=[blind])
    joined = join_pieces(pieces)
    assert len(pieces) == 1 and joined.interruptions == []
    along = true_arc(joined.line[::10])
    # from the rectum's side of the hole round the bend to the other side, never back
    assert along[0] == pytest.approx(40, abs=8) and along[-1] == pytest.approx(410, abs=8)
    assert np.all(np.diff(along) > -5.0)
    assert joined.arc[-1] == pytest.approx(370, rel=0.05)
    ((u0, u1),) = joined.unseen  # the bend not reconstructed: arc length 170-280 of the U, 130-240 from the hole
    assert u0 == pytest.approx(130, abs=15) and u1 - u0 == pytest.approx(110, abs=25)


def test_limbs_joined_only_through_a_hole_away_from_the_scope_get_a_path_each():
    """The same U with a smaller hole (9 mm) and a withdrawal 2 mm sideways: the hole lies farther than
    15 mm from the trajectory, so the lumen around the scope falls apart into the two limbs, while the
    enclosed lumen is one piece through the hole. One path kept to one limb and the other was lost (165 of
    the U's 450 mm mapped). Each limb now gets its own path, and the map joins them round the bend."""
    from colonbench.mapping.colonmap import join_pieces, map_centerline

    line = u_tube()
    pts, s, _ = tube_cloud(line)
    pts = pts[(np.linalg.norm(pts - [16.0, 0.0, 40.0], axis=1) > 9.0) & ((s < 170) | (s > 280))]
    traj = line.point_at(np.arange(450.0, 0.0, -2.0)) + [0.0, 2.0, 0.0]
    pieces = colon_centerline(pts, positions=traj)
    assert len(pieces) == 2 and all(p.length == pytest.approx(165, abs=15) for p in pieces)
    mapped, _ = map_centerline(pts, traj, pieces=pieces)
    joined = join_pieces(mapped)
    assert len(mapped) == 1 and joined.arc[-1] == pytest.approx(line.arclength[-1], rel=0.03)
    assert np.mean(cKDTree(joined.line).query(line.points)[0] < 3.0) > 0.95
    ((u0, u1),) = joined.unseen  # from the rectum (arc length 0): the bend, 170-280
    assert u0 == pytest.approx(170, abs=10) and u1 - u0 == pytest.approx(110, abs=15)


def test_a_segment_without_an_estimate_is_reported_and_left_out_of_the_whole_colon():
    """A method that returns no coverage (NaN: an empty completed surface) for one segment: that segment
    says so, and the whole-colon coverage is the others', not NaN."""
    line = straight(360.0)
    pts, _, _ = tube_cloud(line, density=1.0)

    class NoSurfaceNearZero:
        name = "no-surface"

        def estimate(self, points):
            cov = float("nan") if np.mean(points[:, 2]) < 60 else 0.8
            return {"coverage": cov, "holes": np.zeros((0, 3)), "centerline": np.zeros((0, 3))}

    from colonbench.mapping.segments import whole_coverage

    result = map_colon(pts, NoSurfaceNearZero(), segment_mm=60.0, positions=line.points[::-20], progress=False)
    failed = [s for s in result["segments"] if s.coverage is None]
    assert len(failed) == 1 and "no coverage" in failed[0].error and failed[0].start_mm == 0.0
    assert whole_coverage(result["segments"]) == pytest.approx(0.8)


def test_a_long_narrow_stretch_apart_from_the_wide_lumen_is_kept():
    """A wide tube (radius 25 mm) and, apart from it, a long tube of half its radius: the narrow one's enclosed
    lumen is under half as deep, as a channel's would be, but it is long and lies apart: a stretch of colon."""
    wide, _, _ = tube_cloud(straight(300.0), radius=25.0)
    narrow, _, _ = tube_cloud(straight(200.0), radius=12.0, seed=2)
    narrow = narrow + [120.0, 0.0, 50.0]
    pieces = colon_centerline(np.concatenate([wide, narrow]))
    assert len(pieces) == 2
    for p in pieces:  # each follows its own axis
        axis = 120.0 if p.radius < 18 else 0.0
        assert np.median(np.hypot(p.points[:, 0] - axis, p.points[:, 1])) < 2.0
    assert sorted(p.length for p in pieces) == pytest.approx([200, 300], abs=12)


def test_bad_inputs_are_refused(tmp_path, capsys):
    line = straight(300.0)
    pts, _, _ = tube_cloud(line, density=0.5)
    np.save(tmp_path / "colon.npy", pts)
    np.save(tmp_path / "colon_m.npy", pts / 1000.0)
    np.save(tmp_path / "traj_m.npy", line.points[::-20] / 1000.0)
    short, _, _ = tube_cloud(straight(70.0), density=0.5)
    np.save(tmp_path / "segment.npy", short)
    cases = [(["colon_m.npy"], "metres"),
             (["colon.npy", "--trajectory", str(tmp_path / "traj_m.npy")], "another unit"),
             (["segment.npy"], "single segment"),
             (["missing.ply"], "no such file")]
    for args, message in cases:
        code = main(["map", str(tmp_path / args[0]), *args[1:], "--out", str(tmp_path / "out"), "--quiet",
                     "--no-figure"])
        assert code == 2, args
        assert message in capsys.readouterr().err, args
    assert not (tmp_path / "out" / "segments.json").exists()


def test_a_mesh_reconstruction_is_sampled_at_the_training_density(tmp_path):
    from colonbench.errors import InputError
    from colonbench.mapping.inputs import read_reconstruction
    from colonbench.pointio import MESH_DENSITY

    tube = tube_colon(straight(200.0), RADIUS, ring_spacing_mm=1.0, n_around=96)
    tube.mesh.export(tmp_path / "tube.obj")
    pts, dropped = read_reconstruction(tmp_path / "tube.obj")
    assert dropped == 0
    assert len(pts) == pytest.approx(MESH_DENSITY * tube.mesh.area, rel=0.01)
    assert np.abs(np.linalg.norm(pts[:, :2], axis=1) - RADIUS).max() < 0.1  # on the surface
    (tmp_path / "bad.obj").write_text("this is not a mesh\n")
    with pytest.raises(InputError):
        read_reconstruction(tmp_path / "bad.obj")


def test_whole_partials_hold_points_on_observed_faces_only():
    from colonbench.datagen.wholecolon import whole_partial
    from colonbench.errors import InputError

    line = straight(240.0)
    colon = tube_colon(line, RADIUS, ring_spacing_mm=1.0, n_around=96)
    centroids = colon.mesh.vertices[colon.mesh.faces].mean(axis=1)
    for holes in ("spheres", "camera"):
        part = whole_partial(colon, seed=3, holes=holes)
        assert 0.3 < part.observed.mean() < 1.0
        _, face = cKDTree(centroids).query(part.points)  # faces are ~1 mm: the nearest centroid is the face's
        assert part.observed[face].mean() > 0.98
        assert part.positions[0][2] < 5 and part.positions[-1][2] > 235  # caecum (arc length 0) to rectum
    with pytest.raises(InputError, match="hole model"):
        whole_partial(colon, holes="video")


def test_the_recorded_trajectory_drifts_off_the_centerline_within_the_wall():
    """On a straight tube of radius 15 mm (centerline the z axis) the recorded positions wander off the axis
    as a SLAM trajectory does, by at most trajectory_offset of the way to the wall, and smoothly; with
    trajectory_offset 0 they are the centerline's points."""
    from colonbench.datagen.config import WholeConfig
    from colonbench.datagen.wholecolon import trajectory, withdrawal

    line = straight(240.0)
    colon = tube_colon(line, RADIUS, ring_spacing_mm=1.0, n_around=96)
    pos = trajectory(colon, seed=5, config=WholeConfig(trajectory_offset=0.5))
    off = np.hypot(pos[:, 0], pos[:, 1])
    # the faceted wall is 0.1 % inside the true circle
    assert off.max() <= 0.5 * RADIUS + 0.05 and np.median(off) > 0.1 * RADIUS
    np.testing.assert_allclose(pos[:, 2], line.point_at(withdrawal(colon, 5))[:, 2], atol=1e-9)  # the withdrawal
    step = np.linalg.norm(np.diff(pos[:, :2], axis=0), axis=1)
    assert step.max() < 1.0  # 2 mm a pose along the tube, knots 40 mm apart: no jumps across it
    on_axis = trajectory(colon, seed=5, config=WholeConfig(trajectory_offset=0.0))
    np.testing.assert_allclose(on_axis[:, :2], 0.0, atol=1e-9)


def test_the_map_clips_at_its_own_planes_not_at_cut_rims():
    # the map splits a reconstruction by arc length, not by planes, so its segments' clouds end in no
    # planar rim: the completion method runs with its rim search off (a copy), the caller's own left as it is
    from colonbench.completion.heatmap_centerline import END_LEVEL

    class Spy(CompletionMethod):
        seen: list = []

        def estimate(self, points):
            self.seen.append((self.cut_rims, self.end_level))
            return super().estimate(points)

    pts, _, _ = tube_cloud(straight(200.0), density=1.0)
    spy = Spy()
    result = map_colon(pts, spy, segment_mm=60.0, progress=False, context_mm=15.0)
    assert len(result["segments"]) >= 3 and not any(seg.error for seg in result["segments"])
    assert spy.seen and set(spy.seen) == {(False, END_LEVEL)}
    # on a segment alone nothing clips a centerline that follows the lumen past the segment's ends:
    # there the line keeps the ends of its ridge
    spy.seen.clear()
    result = map_colon(pts, spy, segment_mm=60.0, progress=False, context_mm=0.0)
    assert not any(seg.error for seg in result["segments"])
    assert spy.seen and set(spy.seen) == {(False, None)}
    assert spy.cut_rims is True and spy.end_level == END_LEVEL


def test_trajectories_are_read_with_headers_commas_and_in_time_order(tmp_path):
    # TUM with its "# timestamp ..." header and lines out of time order, and (k, 3) positions as a .csv
    # with a header; a ragged row is named by its line in the file
    from colonbench.errors import InputError
    from colonbench.mapping.inputs import read_trajectory

    pos = np.c_[np.zeros(20), np.linspace(0, 10, 20), np.linspace(0, 200, 20)]
    tum = np.c_[np.arange(20) * 0.1, pos, np.zeros((20, 3)), np.ones(20)]
    np.savetxt(tmp_path / "poses.txt", tum[::-1], header="timestamp tx ty tz qx qy qz qw")
    np.savetxt(tmp_path / "poses.csv", pos, delimiter=",", header="x,y,z", comments="")
    assert np.allclose(read_trajectory(tmp_path / "poses.txt"), pos)
    assert np.allclose(read_trajectory(tmp_path / "poses.csv"), pos)
    (tmp_path / "ragged.txt").write_text("0 0 0\n0 0 1\n0 0 2 3\n")
    with pytest.raises(InputError, match="ragged.txt: line 3 is not a row of a TUM trajectory"):
        read_trajectory(tmp_path / "ragged.txt")


def test_a_trajectory_over_part_of_the_reconstruction_maps_that_part_and_says_so(tmp_path, capsys):
    """Poses of another run that pass the first 110 mm of a 360 mm tube: the centerline keeps to them, so the
    map covers a third of the reconstruction. The end segment, whose cloud holds the rest, is not estimated, with
    the trajectory named as the likely cause; summary.json and a warning say the whole-colon figure is partial."""
    line = straight(360.0)
    np.save(tmp_path / "tube.npy", tube_cloud(line, density=1.0)[0])
    for name, traj in (("part", line.points[line.arclength < 110][::-20]), ("whole", line.points[::-20])):
        np.save(tmp_path / f"{name}.npy", traj)
        assert main(["map", str(tmp_path / "tube.npy"), "--trajectory", str(tmp_path / f"{name}.npy"), "--out",
                     str(tmp_path / name), "--method", "constant", "--no-figure", "--quiet"]) == 0
        segs = json.loads((tmp_path / name / "segments.json").read_text())["segments"]
        summary = json.loads((tmp_path / name / "summary.json").read_text())
        warnings = [x for x in capsys.readouterr().err.splitlines() if x.startswith("colonbench: warning:")]
        if name == "whole":  # with the whole run's trajectory the same tube maps whole, and nothing warns
            assert summary["estimated_share"] == 1.0 and summary["reached"] == 1.0 and not warnings
            continue
        failed = [s for s in segs if s["coverage"] is None]
        assert len(failed) == 1 and failed[0]["index"] == len(segs) - 1
        assert "beyond the reach of the map's centerline" in failed[0]["error"] and "trajectory" in failed[0]["error"]
        done = sum(s["end_mm"] - s["start_mm"] for s in segs if s["coverage"] is not None)
        assert summary["estimated_mm"] == pytest.approx(done, abs=0.1)
        assert summary["estimated_share"] == pytest.approx(done / (segs[-1]["end_mm"] - segs[0]["start_mm"]), abs=1e-3)
        assert 0.3 < summary["reached"] < 0.8       # the points beyond the centerline's reach are counted
        (warning,) = warnings
        assert "part of the colon" in warning and "trajectory" in warning
        assert f"reaches {100 * summary['reached']:.0f} % of the reconstruction's points" in warning
