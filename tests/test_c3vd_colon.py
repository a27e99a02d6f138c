"""The whole-colon suite of a C3VD download, tested without the data: synthetic C3VDv2 screening withdrawals (a bent,
folded tube as the whole-colon phantom, a withdrawal through it in C3VD's pose convention) are found, checked,
seen, mapped and scored, and refused where their trajectory does not lie in the phantom."""

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
import trimesh

from colonbench.errors import InputError
from colonbench.video import c3vd, c3vd_screening
from colonbench.video.c3vd_synth import phantom_tube, pose_lines, withdrawal_poses, write_obj, write_screening

FRAMES, EVERY = 60, 2


@pytest.fixture(scope="module")
def colon():
    mesh, line = phantom_tube(length_mm=300.0, bend_mm=40.0, ring_mm=1.5, around=40)
    return mesh, line, withdrawal_poses(line, FRAMES)


def _registered(root: Path):
    """A registered sequence without depth frames (a straight tube, one half observed): the segment suite's."""
    mesh, line = phantom_tube(length_mm=120.0, bend_mm=0.0, fold_depth=0.0, around=48)
    folder = root / "c2_cecum_t1_v1"
    folder.mkdir(parents=True)
    write_obj(folder / "coverage_mesh.obj", mesh.vertices, mesh.faces, np.arange(len(mesh.faces)) // 2 % 48 < 24)
    (folder / "pose.txt").write_text(pose_lines(withdrawal_poses(line, 5)))


@pytest.fixture(scope="module")
def download(tmp_path_factory, colon):
    """Two withdrawals over one phantom (its full model beside them), a registered sequence, and a folder that is
    neither (pose.txt only: a deformation video)."""
    root = tmp_path_factory.mktemp("c3vdv2")
    mesh, _, poses = colon
    write_screening(root, "c1_full_t1_v1", mesh, poses)
    write_screening(root, "c1_full_t2_v1", mesh, poses[::-1][FRAMES // 3:], as_written=True)   # written row by row
    _registered(root)
    (root / "c1_sigmoid_t1_v4").mkdir()
    (root / "c1_sigmoid_t1_v4" / "pose.txt").write_text(pose_lines(poses[:3]))
    return root


@pytest.fixture(scope="module")
def built(download, tmp_path_factory):
    from colonbench.benchmark.c3vd_suite import build_all

    root = tmp_path_factory.mktemp("suites")
    result = build_all(download, root, frames_every=EVERY, progress=False)
    assert [new for _, new in result] == [True, True]
    return result, root


def _seen_independently(mesh, poses, faces, fov_deg=140.0, near=2.0, reach=100.0):
    """Whether each of ``faces`` is seen from any of ``poses``: its centroid in the view cone, 2-100 mm away, and
    the first hit of trimesh's own (not Embree's) ray towards it no nearer than it."""
    from trimesh.ray.ray_triangle import RayMeshIntersector

    rays = RayMeshIntersector(mesh)
    cents = mesh.triangles_center[faces]
    seen = np.zeros(len(faces), bool)
    for m in poses:
        d = cents - m[:3, 3]
        dist = np.linalg.norm(d, axis=1)
        unit = d / dist[:, None]
        ok = np.flatnonzero((dist >= near) & (dist <= reach) & (unit @ m[:3, 2] >= np.cos(np.radians(fov_deg / 2)))
                            & ~seen)
        if len(ok) == 0:
            continue
        loc, ray, _ = rays.intersects_location(np.repeat(m[None, :3, 3], len(ok), 0), unit[ok], multiple_hits=False)
        first = np.full(len(ok), np.inf)
        np.minimum.at(first, ray, np.linalg.norm(loc - m[:3, 3], axis=1))
        seen[ok] = first >= dist[ok] - 1e-3 * dist[ok] - 1e-3
    return seen


# --------------------------------------------------------------------------------------------- the layout

def test_screening_withdrawals_found_with_their_whole_colon_mesh(download, tmp_path, colon):
    sequences, screening, skipped = c3vd.find_download(download)
    assert [s.name for s in sequences] == ["c2_cecum_t1_v1"]
    assert [s.name for s in screening] == ["c1_full_t1_v1", "c1_full_t2_v1"]
    assert {s.mesh for s in screening} == {download / "c1_full_model" / "c1_full.obj"}
    assert skipped[0]["folder"] == "c1_sigmoid_t1_v4" and "not named as a screening withdrawal" in skipped[0]["reason"]
    # the mesh may lie in the sequence's folder; a withdrawal without one is skipped; two candidates are refused
    root = tmp_path / "dl"
    write_screening(root, "screening_t1", colon[0], colon[2], mesh_path="screening_t1/model.obj")
    write_screening(root, "c3_full_t1_v1", colon[0], colon[2], mesh_path="elsewhere/nothing.obj")
    _, screening, skipped = c3vd.find_download(root)
    assert [(s.name, s.mesh.name, s.colon) for s in screening] == [("screening_t1", "model.obj", "c0")]
    assert skipped[0]["folder"] == "c3_full_t1_v1" and "without its whole-colon mesh" in skipped[0]["reason"]
    write_screening(root, "c3_full_t1_v1", colon[0], colon[2], mesh_path="models/c3_full_lumen.obj")
    write_screening(root, "c3_full_t1_v1", colon[0], colon[2], mesh_path="models/c3_FULL_mold.ply")
    with pytest.raises(InputError, match=r"c3_full_t1_v1: a screening withdrawal with 2 candidate whole-colon meshes"):
        c3vd.find_download(root)
    v, f = c3vd_screening.read_mesh(download / "c1_full_model" / "c1_full.obj")
    assert np.array_equal(f, colon[0].faces) and np.abs(v - colon[0].vertices).max() < 1e-6


def test_the_cameras_limits_on_a_straight_tube():
    """One view down the axis of a straight 12 mm tube with nothing in the way: it sees the wall from where the
    140 degree cone meets it (12 / tan 70 = 4.4 mm ahead) to where it is 100 mm away (99.3 mm ahead), nothing
    else; a second view from the same place adds nothing, one 30 mm on adds 30 mm more."""
    from colonbench.datagen.camera import SurfaceScene

    mesh, _ = phantom_tube(length_mm=260.0, radius_mm=12.0, bend_mm=0.0, fold_depth=0.0, ring_mm=0.5, around=96)
    scene = SurfaceScene(mesh.vertices, mesh.faces)
    pose = np.eye(4)
    pose[:3, :3] = [[0, 0, 1], [0, 1, 0], [-1, 0, 0]]        # the camera's z along the tube's x
    pose[:3, 3] = [50.0, 0.0, 0.0]
    x = scene.centroids[:, 0] - 50.0
    seen, frames = c3vd_screening.trajectory_visibility(scene, np.stack([pose, pose]), every=1)
    assert list(frames) == [0, 1]
    sure = (x > 12 / np.tan(np.radians(70)) + 0.3) & (np.hypot(x, 12.0) < 100.0 - 0.3)
    unsure = ~sure & (x > 3.5) & (x < 100.0)            # the faces' centroids lie a little inside the 12 mm circle
    assert seen[sure].all() and not seen[~sure & ~unsure].any()
    further = pose.copy()
    further[0, 3] += 30.0
    more, _ = c3vd_screening.trajectory_visibility(scene, np.stack([pose, further]), every=1)
    assert more[(x > 35) & (x < 129)].all() and not more[x > 130].any()


# --------------------------------------------------------------------------------------------- the suite

def test_the_whole_colon_suite_holds_the_visibility_of_its_trajectory(built, colon):
    from colonbench.shards.colonshard import ColonShard

    (seg, _), (whole, _) = built[0]
    assert seg.id.startswith("c3vd-") and seg.task == "segments" and seg.samples == 3
    assert whole.id.startswith("c3vd-colon-") and whole.task == "colon" and whole.samples == 2
    assert whole.contexts_mm == (0.0, 2.5) and whole.segment_mm == 60.0 and whole.noise_mm == (0.0, 0.5)
    mesh, line, poses = colon
    shard = ColonShard(Path(whole.folder) / "test" / "c1_full.h5")
    truth = shard.colon()
    phantom = trimesh.Trimesh(np.round(mesh.vertices, 6), mesh.faces, process=False)
    assert np.array_equal(truth["faces"], mesh.faces) and shard.name == "c1_full"
    rng = np.random.default_rng(1)
    faces = rng.choice(len(mesh.faces), 400, replace=False)
    for i, trajectory in enumerate([poses, poses[::-1][FRAMES // 3:]]):
        s = shard.sample(i)
        # the real trajectory, every frame's camera centre in time order, is what the map is given
        assert np.abs(s["positions"] - trajectory[:, :3, 3]).max() < 1e-4
        # the truth: what the camera sees from every EVERY-th frame, found here with another ray caster
        expect = _seen_independently(phantom, trajectory[::EVERY], faces)
        assert 0.2 < expect.mean() < 0.98
        assert np.array_equal(s["observed_faces"][faces], expect)
        area = phantom.area_faces
        assert s["coverage"] == pytest.approx(area[s["observed_faces"]].sum() / area.sum(), abs=1e-6)
        _, d, tri = trimesh.proximity.closest_point(phantom, s["points"][:300])
        assert d.max() < 1e-3 and s["observed_faces"][tri].all()
        assert len(s["points"]) == pytest.approx(2.0 * area[s["observed_faces"]].sum(), rel=0.02)
    assert shard.sample(0)["coverage"] > shard.sample(1)["coverage"]        # the second saw a part of the colon
    # the true centerline starts where the withdrawals start (the tube's far end) and runs the tube's length
    cl = truth["centerline"]
    assert np.linalg.norm(cl.points[0] - poses[0, :3, 3]) < np.linalg.norm(cl.points[-1] - poses[0, :3, 3])
    assert abs(cl.length - line.length) < 20.0
    entry = json.loads((Path(whole.folder) / "built-suite.json").read_text())
    one, two = (entry["source"]["sequences"][n]["convention"] for n in ("c1_full_t1_v1", "c1_full_t2_v1"))
    assert one["transposed"] and one["inside_share"] == 1.0 and one["scale"] == 1.0
    assert not two["transposed"] and two["convention"].startswith("as written")     # corrected
    assert entry["options"]["settings"]["reach_mm"] == 100.0 and entry["protocol"] == "colon-v1"
    assert [s["folder"] for s in entry["source"]["skipped"]] == ["c1_sigmoid_t1_v4"]


def test_benchmark_maps_and_scores_it_as_colon_v1(built, tmp_path):
    """colonbench benchmark on the whole-colon suite by its name, with the constant guess: every map's truth is the
    shard's, both tracks are mapped, and the suite's cell is the mean |guess - truth| of the in-context segments."""
    import pandas as pd

    from colonbench.cli import main
    from colonbench.shards.colonshard import ColonShard

    whole = built[0][1][0]
    out = tmp_path / "bench"
    assert main(["benchmark", "--suites", "c3vd-colon", "--methods", "constant", "--data", str(built[1]),
                 "--out", str(out), "--quiet", "--no-figures"]) == 0
    run = json.loads((out / "runs" / whole.id / "run.json").read_text())
    assert run["task"] == "colon" and run["suite"]["id"] == whole.id and run["suite"]["verified"]
    assert run["suite"]["local"] and run["suite"]["importer"] == {"name": "c3vd-colon", "version": 2}
    colons = pd.read_csv(out / "runs" / whole.id / "results" / "colons.csv")
    segs = pd.read_csv(out / "runs" / whole.id / "results" / "segments.csv")
    assert len(colons) == 2 * 2 * 2 and colons["error"].isna().all()           # 2 maps x 2 noise levels x 2 tracks
    shard = ColonShard(Path(whole.folder) / "test" / "c1_full.h5")
    for i in (0, 1):
        assert np.allclose(colons[colons["index"] == i]["true_coverage"], shard.sample(i)["coverage"])
    assert set(segs["track"]) == {"segment-only", "context-2.5mm"} and (segs.groupby("index").size() >= 8).all()
    ctx = segs[(segs["track"] == "context-2.5mm") & (segs["noise_mm"] == 0.0)]
    mae = 100 * np.abs(ctx["coverage"] - ctx["true_coverage"]).mean()
    board = json.loads((out / "leaderboard.json").read_text())
    assert whole.id in json.dumps(board) and f"{mae:.2f}" in (out / "leaderboard.md").read_text()


# --------------------------------------------------------------------------------------------- refusals

def test_pose_conventions_corrected_or_refused_naming_the_sequence(tmp_path, colon):
    from colonbench.benchmark.c3vd_suite import build_all

    mesh, _, poses = colon

    def one(name, **kw):
        root = tmp_path / name / "dl"
        write_screening(root, "c1_full_t1_v1", mesh, kw.pop("poses", poses), **kw)
        return root, tmp_path / name / "suites"

    # metres, written row by row: found from the data, the same truth as C3VD's own convention
    truths = []
    for name, kw in (("c3vd", {}), ("metres", {"pose_scale": 1e-3, "as_written": True})):
        dl, suites = one(name, **kw)
        ((suite, _),) = build_all(dl, suites, frames_every=EVERY, progress=False)
        from colonbench.shards.colonshard import ColonShard

        truths.append(ColonShard(Path(suite.folder) / "test" / "c1_full.h5").sample(0)["observed_faces"])
        conv = json.loads((Path(suite.folder) / "built-suite.json").read_text())["source"]["sequences"][
            "c1_full_t1_v1"]["convention"]
        assert conv["scale"] == (1000.0 if name == "metres" else 1.0) and conv["transposed"] == (name == "c3vd")
    assert np.array_equal(*truths)
    # a trajectory beside the phantom (another colon's, say), and one that never moves: refused, nothing left
    shifted = poses.copy()
    shifted[:, 1, 3] += 60.0
    still = np.repeat(poses[FRAMES // 2][None], FRAMES, axis=0)
    half = poses.copy()
    half[::2, 1, 3] += 60.0                                  # half the centres outside: under the 90 % needed
    for name, p in (("shifted", shifted), ("still", still), ("half", half)):
        dl, suites = one(name, poses=p)
        with pytest.raises(InputError, match=r"sequence c1_full_t1_v1: its camera centres do not lie inside its "
                                             r"phantom's lumen in any pose convention"):
            build_all(dl, suites, frames_every=EVERY, progress=False)
        assert not suites.exists() or not any(suites.iterdir())


def test_a_withdrawal_over_a_phantom_too_short_for_the_map_is_skipped(tmp_path, capsys):
    """A screening withdrawal over a 130 mm phantom: the map's own line of what its camera saw (about 109 mm) is not
    two of colon-v1's 60 mm segments, so the map would take it for a single segment and every method would fail
    it. It is left out at build, with the map's reason, among the download's skipped folders: the segment suite
    of the download is built alone; a download holding nothing else is refused with the reason."""
    from colonbench.benchmark.c3vd_suite import build_all
    from colonbench.cli import main

    mesh, line = phantom_tube(length_mm=130.0, ring_mm=1.5, around=40)
    root = tmp_path / "dl"
    write_screening(root, "c3_full_t1_v1", mesh, withdrawal_poses(line, 30))
    only = tmp_path / "only"
    shutil.copytree(root, only)
    _registered(root)
    ((suite, new),) = build_all(root, tmp_path / "suites", frames_every=EVERY, progress=False)
    assert new and suite.task == "segments" and not any(p.name.startswith("c3vd-colon")
                                                        for p in (tmp_path / "suites").iterdir())
    (why,) = json.loads((Path(suite.folder) / "built-suite.json").read_text())["source"]["skipped"]
    assert why["folder"] == "c3_full_t1_v1"
    assert "the whole-colon map cannot map" in why["reason"] and "looks like a single segment" in why["reason"]
    assert main(["suites", "build", "c3vd", "--from", str(root), "--data", str(tmp_path / "cli"), "--frames-every",
                 str(EVERY), "--quiet"]) == 0
    out = capsys.readouterr().out
    assert "skipped c3_full_t1_v1: a screening withdrawal the whole-colon map cannot map (the centerline found" in out
    with pytest.raises(InputError, match=r"no suite can be made of the download \(c3_full_t1_v1: .*single segment"):
        build_all(only, tmp_path / "none", frames_every=EVERY, progress=False)
    assert not (tmp_path / "none").exists() or not any((tmp_path / "none").iterdir())


def test_a_refused_withdrawal_leaves_neither_suite_and_the_command_line(download, tmp_path, colon, capsys):
    from colonbench.cli import main

    bad = tmp_path / "bad"
    shutil.copytree(download, bad)
    shifted = colon[2].copy()
    shifted[:, 2, 3] += 80.0
    (bad / "c1_full_t2_v1" / "pose.txt").write_text(pose_lines(shifted))
    data = tmp_path / "suites"
    assert main(["suites", "build", "c3vd", "--from", str(bad), "--data", str(data), "--quiet"]) == 2
    assert "sequence c1_full_t2_v1: its camera centres do not lie inside" in capsys.readouterr().err
    assert not data.exists() or not any(data.iterdir())                    # the segment suite is not left either
    assert main(["suites", "build", "c3vd", "--from", str(download), "--data", str(data), "--frames-every",
                 str(EVERY), "--quiet"]) == 0
    out = capsys.readouterr().out
    assert "c1_full_t1_v1: a screening withdrawal of 60 poses over c1_full, camera centres 100.0% inside" in out
    assert "built c3vd-colon-" in out and "built c3vd-" in out and "skipped c1_sigmoid_t1_v4" in out
    assert main(["suites", "build", "c3vd", "--from", str(download), "--data", str(data), "--frames-every",
                 str(EVERY), "--quiet"]) == 0
    assert capsys.readouterr().out.count("nothing to do") == 2
    assert main(["suites", "--data", str(data)]) == 0
    assert "2 whole-colon reconstructions x noise 0, 0.5 mm; built here" in capsys.readouterr().out
