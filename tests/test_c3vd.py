"""Suites from a C3VD download, tested without the data: a synthetic sequence in C3VD's layout, made here by casting
each fisheye pixel's ray against a folded tube, is imported, checked, scored, and refused where it is wrong."""

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
import trimesh

from colonbench.datagen.camera import SurfaceScene
from colonbench.errors import InputError
from colonbench.video import c3vd
from colonbench.video.c3vd_synth import (C3VD_CAMERA, phantom_tube, pose_lines, withdrawal_poses, write_obj,
                                         write_sequence)
from colonbench.video.fisheye import Fisheye, read_intrinsics

CAMERA = C3VD_CAMERA.scaled(0.1)          # 135 x 108 pixels: C3VD's lens on a small image
FRAMES = 24


@pytest.fixture(scope="module")
def tube():
    mesh, line = phantom_tube()
    return mesh, line, withdrawal_poses(line, FRAMES)


def _download(root, tube, name="c1_cecum_t1_v1", **kw):
    mesh, _, poses = tube
    seen = write_sequence(root / name, mesh, poses, CAMERA, **kw)
    return root, seen


@pytest.fixture(scope="module")
def download(tmp_path_factory, tube):
    return _download(tmp_path_factory.mktemp("c3vd"), tube)


@pytest.fixture(scope="module")
def built(download, tmp_path_factory):
    from colonbench.benchmark.c3vd_suite import build

    root = tmp_path_factory.mktemp("suites")
    suite, new = build(download[0], root, progress=False)         # the defaults: every 2nd frame fused
    assert new
    return suite, root


def _nothing_left(root):
    return not root.exists() or not any(root.iterdir())


# --------------------------------------------------------------------------------------------- the camera model

def test_fisheye_rays_project_back_to_their_pixels_and_scale():
    u, v = C3VD_CAMERA.pixel_grid(17)
    rays = C3VD_CAMERA.rays(u.ravel(), v.ravel())
    ok = np.isfinite(rays[:, 0])
    assert ok.mean() > 0.98                                   # only the far corners lie past 90 degrees
    back = C3VD_CAMERA.project(rays[ok] * 7.0)               # any length along the ray
    assert np.abs(back - np.stack([u.ravel(), v.ravel()], 1)[ok]).max() < 1e-3
    # the principal point looks along z; a pixel a0 to the right of it at about 45 degrees (a0 is the focal length)
    centre = C3VD_CAMERA.rays([C3VD_CAMERA.cx], [C3VD_CAMERA.cy])[0]
    assert np.allclose(centre, [0, 0, 1], atol=1e-12)
    # the same lens on a tenth of the image gives the same rays at the same places
    assert np.allclose(CAMERA.rays(u.ravel() * 0.1, v.ravel() * 0.1)[ok], rays[ok], atol=1e-9)
    # a depth frame's points lie at their z along their rays
    depth = np.full((CAMERA.height, CAMERA.width), 40.0)
    pts, px = CAMERA.points(depth)
    assert np.allclose(pts[:, 2], 40.0) and len(pts) == len(px)


def test_the_stretch_matrix_is_the_renderers_and_the_pinhole_reads_the_right_pixels():
    # C3VD's renderer: glm::mat2(c, d, e, 1) is filled column by column, S = [[c, e], [d, 1]], pixel = S (u'', v'')
    lens = Fisheye(200, 200, 100.0, 100.0, 100.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.1, 0.0)
    ray = lens.rays([110.0], [100.0])[0]
    assert np.allclose(ray[:2] * 100.0, np.linalg.solve([[1.0, 0.0], [0.1, 1.0]], [10.0, 0.0]))
    assert not np.allclose(ray[:2] * 100.0, np.linalg.solve([[1.0, 0.1], [0.0, 1.0]], [10.0, 0.0]))
    from colonbench.video.c3vd_fusion import resample, views_for

    intr, views = views_for(C3VD_CAMERA, 120)
    assert [view.name for view in views] == ["front", "right", "left", "down", "up"]
    assert (views[0].index >= 0).all()                        # the front view lies inside the image
    plane = np.full((C3VD_CAMERA.height, C3VD_CAMERA.width), 30.0, np.float32)
    for view in views:
        ok = view.index >= 0
        # each view pixel's ray and the ray of the fisheye pixel it reads differ by at most about a fisheye pixel
        u, v = view.index[ok] % C3VD_CAMERA.width, view.index[ok] // C3VD_CAMERA.width
        a = C3VD_CAMERA.rays(u, v)
        b = intr.rays()[ok] @ view.rotation.T
        cos = np.sum(a * b, 1) / np.linalg.norm(a, axis=1) / np.linalg.norm(b, axis=1)
        assert np.degrees(np.arccos(np.clip(cos, -1, 1))).max() < 0.15
        # a wall at z = 30 mm seen in a view: its depth, back along the view's rays, lies at the camera's z = 30
        z = resample(plane, intr, view).ravel()
        points = (intr.rays() * z[:, None]) @ view.rotation.T
        assert np.allclose(points[z > 0, 2], 30.0, atol=1e-3) and ((z > 0) == ok).all()
    # together they read the whole image up to 85 degrees from the axis, the corners too (one pinhole read 64 x 46)
    u, v = C3VD_CAMERA.pixel_grid(9)
    rays = C3VD_CAMERA.rays(u.ravel(), v.ravel())
    wide = np.isfinite(rays[:, 0]) & (np.degrees(np.arctan(np.hypot(rays[:, 0], rays[:, 1]))) < 85)
    read = np.zeros((C3VD_CAMERA.height, C3VD_CAMERA.width), bool).ravel()
    for view in views:
        read[view.index[view.index >= 0]] = True
    from scipy.ndimage import binary_dilation

    read = binary_dilation(read.reshape(C3VD_CAMERA.height, C3VD_CAMERA.width), iterations=12)
    assert read[v.ravel()[wide], u.ravel()[wide]].all()


def test_intrinsics_files(tmp_path):
    (tmp_path / "named.txt").write_text(CAMERA.text())
    assert read_intrinsics(tmp_path / "named.txt") == CAMERA
    values = [CAMERA.to_dict()[k] for k in ("width", "height", "cx", "cy", "a0", "a1", "a2", "a3", "a4", "c", "d", "e")]
    (tmp_path / "numbers.txt").write_text(", ".join(repr(x) for x in values))
    assert read_intrinsics(tmp_path / "numbers.txt") == CAMERA
    (tmp_path / "short.txt").write_text(" ".join(repr(x) for x in values[:-1]))
    with pytest.raises(InputError, match=r"short\.txt: 11 numbers"):
        read_intrinsics(tmp_path / "short.txt")
    (tmp_path / "missing.txt").write_text("width 1350\nheight 1080\ncx 1\n")
    with pytest.raises(InputError, match=r"missing\.txt: names no cy"):
        read_intrinsics(tmp_path / "missing.txt")
    with pytest.raises(InputError, match="nowhere.txt: no such file"):
        read_intrinsics(tmp_path / "nowhere.txt")


# --------------------------------------------------------------------------------------------- reading the layout

def test_the_reader_reads_what_c3vds_renderer_writes(download, tube):
    root, seen = download
    mesh, _, poses = tube
    (seq,), skipped = c3vd.find_sequences(root)
    assert seq.name == "c1_cecum_t1_v1" and seq.layout == "v2" and len(seq.depth) == FRAMES and not skipped
    assert seq.intrinsics == root / "camera_intrinsics.txt"
    v, f, observed = c3vd.read_coverage_mesh(seq.mesh)
    assert np.array_equal(observed, seen) and np.array_equal(f, mesh.faces)
    assert 0.3 < observed.mean() < 0.95                      # the folds hide part of the tube
    raw = c3vd.read_poses(seq.poses)
    assert np.allclose(raw[:, 3, :3], poses[:, :3, 3], atol=1e-5)      # C3VD's translation is in the last row
    assert np.allclose(c3vd.camera_to_world(raw, True), poses, atol=1e-5)
    # depth: z along the camera's axis, on the 100 mm / 65535 scale; pixels that see nothing are invalid
    z = c3vd.read_depth(seq.depth[3], CAMERA)
    pts, _ = CAMERA.points(z)
    world = pts @ poses[3, :3, :3].T + poses[3, :3, 3]
    assert np.median(SurfaceScene(v, f).distance(world)) < 0.01


def test_conventions_found_from_the_data_and_wrong_depth_refused(tmp_path, tube, download):
    mesh = tube[0]
    scene = SurfaceScene(np.round(mesh.vertices, 6), mesh.faces)

    def check(root, name):
        (seq,), _ = c3vd.find_sequences(root)
        return c3vd.check_conventions(name, c3vd.read_poses(seq.poses), seq.depth, CAMERA, scene.distance)

    found = check(download[0], "c3vd")
    assert found["transposed"] and found["scale"] == 1.0 and found["median_mm"] < 0.01
    assert found["medians"][c3vd.CONVENTIONS[1][0]] is None   # as written, C3VD's matrices are not rigid
    plain, _ = _download(tmp_path / "plain", tube, as_written=True)
    assert check(plain, "plain")["convention"].startswith("as written") and check(plain, "plain")["scale"] == 1.0
    metres, _ = _download(tmp_path / "metres", tube, pose_scale=1e-3)
    got = check(metres, "metres")
    assert got["transposed"] and got["scale"] == 1000.0 and got["median_mm"] < 0.01
    halved, _ = _download(tmp_path / "halved", tube, depth_range_mm=50.0)
    with pytest.raises(InputError, match=r"sequence halved: its depth frames .* do not land on its mesh"):
        check(halved, "halved")


# --------------------------------------------------------------------------------------------- the suite

def _samples(folder):
    from colonbench.shards.reader import Shard

    for shard in sorted((folder / "test").glob("*.h5")):
        with Shard(shard) as s:
            for i in range(len(s)):
                yield shard.name, s.geometry(i)


def test_the_suite_holds_the_renderers_exact_truth(built, tube, download):
    suite, _ = built
    mesh = trimesh.Trimesh(np.round(tube[0].vertices, 6), tube[0].faces, process=False)
    seen = download[1]
    models, lengths = set(), set()
    rng = np.random.default_rng(0)
    for name, g in _samples(Path(suite.folder)):
        models.add(g["hole_model"])
        lengths.add(g["length_mm"])
        seg = trimesh.Trimesh(g["vertices"], g["faces"], process=False)
        # every clipped face carries its parent's flag: found here independently, by where the face lies
        _, _, parent = trimesh.proximity.closest_point(mesh, seg.triangles_center)
        assert np.array_equal(g["observed_faces"], seen[parent])
        # coverage: the observed share of the segment's area, here by uniform points on it
        pts, face = trimesh.sample.sample_surface(seg, 20000, seed=int(rng.integers(1 << 30)))
        assert abs(g["observed_faces"][face].mean() - g["coverage"]) < 0.015
        assert g["coverage"] == pytest.approx(seg.area_faces[g["observed_faces"]].sum() / seg.area, abs=1e-6)  # float32 vertices
        # hole points lie on unobserved faces of the phantom, camera partials on observed ones
        _, d, tri = trimesh.proximity.closest_point(mesh, g["hole_points"][:500].astype(float))
        assert d.max() < 1e-3 and not seen[tri].any()
        if g["hole_model"] == "camera":
            _, d, tri = trimesh.proximity.closest_point(mesh, g["partial_points"][:500].astype(float))
            assert d.max() < 1e-3 and seen[tri].all()
        else:   # the fused depth: on the phantom to the TSDF's voxel
            d = SurfaceScene(mesh.vertices, mesh.faces).distance(g["partial_points"])
            assert np.median(d) < 0.3
    assert models == {"camera", "video"} and lengths == {50.0, 60.0, 70.0}
    assert suite.samples == 8 and suite.id.startswith("c3vd-")


def _entry(suite):
    return json.loads((Path(suite.folder) / "built-suite.json").read_text())


def test_the_video_partials_reach_what_their_truth_calls_observed(built, tube, download):
    """The video check on the project's synthetic sequence, recorded per sequence: the fused frames (every 2nd, the
    fisheye's whole field) reach at least 95 % of their segments' observed area within 1.5 mm (one pinhole of
    the middle 64 x 46 degrees reached 94.4 %). Recomputed here from the shards by trimesh's own distances."""
    suite, _ = built
    check = _entry(suite)["source"]["sequences"]["c1_cecum_t1_v1"]["video_check"]
    assert check["passed"] and check["reach"] >= 0.95 and check["threshold"] == 0.95 and check["tolerance_mm"] == 1.5
    assert check["samples"] == 4 == len(check["segments"])
    fused = _fused(download[0])
    mesh = trimesh.Trimesh(fused["vertices"], fused["faces"], process=False)
    seen = reached = 0.0
    rng = np.random.default_rng(1)
    for _, g in _samples(Path(suite.folder)):
        if g["hole_model"] != "video":
            continue
        seg = trimesh.Trimesh(g["vertices"], g["faces"], process=False)
        obs = g["observed_faces"]
        pts, _ = trimesh.sample.sample_surface(seg.submesh([np.flatnonzero(obs)], append=True), 3000,
                                               seed=int(rng.integers(1 << 30)))
        _, d, _ = trimesh.proximity.closest_point(mesh, pts)
        area = seg.area_faces[obs].sum()
        seen, reached = seen + area, reached + area * np.mean(d <= 1.5)
    assert reached / seen == pytest.approx(check["reach"], abs=0.015)


def _fused(root, every=2):
    from colonbench.video.c3vd_fusion import fuse_sequence

    (seq,), _ = c3vd.find_sequences(root)
    return fuse_sequence(seq.depth, c3vd.camera_to_world(c3vd.read_poses(seq.poses), True), CAMERA, every=every)


def test_video_samples_whose_partial_misses_are_refused_with_the_figure(download, tmp_path):
    """Fused from every 12th frame (2 of 24), the partials miss much of what the map calls seen: the sequence's
    video samples are left out, the figure in the reason and the record; the camera samples stay."""
    from colonbench.benchmark.c3vd_suite import build

    suite, _ = build(download[0], tmp_path / "suites", frames_every=12, progress=False)
    seq = _entry(suite)["source"]["sequences"]["c1_cecum_t1_v1"]
    check = seq["video_check"]
    assert not check["passed"] and check["reach"] < 0.9
    assert {g["hole_model"] for _, g in _samples(Path(suite.folder))} == {"camera"} and suite.samples == 4
    refused = [s for s in seq["skipped_segments"] if s["reason"].startswith("video: the fused partials reach")]
    assert len(refused) == check["samples"] >= 3 and all(f"{check['reach']:.1%}" in s["reason"] for s in refused)


def test_a_sequence_without_depth_known_coverage(tmp_path):
    """A straight tube whose one half (by angle) is flagged observed: every segment is half covered; no depth
    frames, so no pose check and no fused sample."""
    from colonbench.benchmark.c3vd_suite import build

    mesh, line = phantom_tube(length_mm=120.0, bend_mm=0.0, fold_depth=0.0, around=48)
    angle = np.arange(len(mesh.faces)) // 2 % 48          # tube.grid_faces: two faces per (ring, angle)
    folder = tmp_path / "dl" / "straight"
    folder.mkdir(parents=True)
    write_obj(folder / "coverage_mesh.obj", mesh.vertices, mesh.faces, angle < 24)
    (folder / "pose.txt").write_text(pose_lines(withdrawal_poses(line, 5)))
    suite, _ = build(tmp_path / "dl", tmp_path / "suites", progress=False)
    rows = list(_samples(Path(suite.folder)))
    # its centerline stops about half a radius inside the open ends: 113 mm, less 10 mm at each end
    assert sorted(g["length_mm"] for _, g in rows) == [50.0, 60.0, 70.0]
    assert {g["hole_model"] for _, g in rows} == {"camera"}
    for _, g in rows:
        assert g["coverage"] == pytest.approx(0.5, abs=0.004)
    entry = json.loads((tmp_path / "suites" / suite.id / "built-suite.json").read_text())
    assert entry["source"]["sequences"]["straight"]["convention"] is None
    assert entry["source"]["sequences"]["straight"]["video_check"] is None         # no video sample to check


def test_benchmark_scores_the_built_suite(built, tmp_path, capsys):
    """colonbench benchmark on the built suite, by its name, with the example program that answers 0.8: its MAE is
    the mean |0.8 - truth| over the suite's samples, at both noise levels."""
    import sys

    import pandas as pd

    from colonbench.cli import main

    suite, root = built
    out = tmp_path / "bench"
    program = Path(__file__).resolve().parents[1] / "examples" / "constant_method.py"
    assert main(["benchmark", "--suites", "c3vd", "--methods", f"exec:{sys.executable} {program}", "--data", str(root),
                 "--out", str(out), "--quiet", "--no-figures"]) == 0
    truth = np.array([g["coverage"] for _, g in _samples(Path(suite.folder))])
    run = json.loads((out / "runs" / suite.id / "run.json").read_text())
    assert run["suite"]["id"] == suite.id and run["suite"]["verified"] and run["suite"]["local"]
    assert run["suite"]["importer"] == {"name": "c3vd", "version": 2}
    files = run["suite"]["source"]["sequences"]["c1_cecum_t1_v1"]["files"]
    assert run["suite"]["source"]["digest"] and files == FRAMES + 3      # mesh, poses, intrinsics, every frame
    res = pd.read_csv(next((out / "runs" / suite.id / "results").glob("*.csv")))
    assert len(res) == 2 * len(truth) and (res["error"].isna() | (res["error"] == "")).all()
    mae = res.groupby("noise_mm")["coverage_error"].apply(lambda e: e.abs().mean()).tolist()
    assert mae == pytest.approx([np.abs(0.8 - truth).mean()] * 2, abs=1e-9)
    board = (out / "leaderboard.md").read_text()
    assert suite.id in board and f"{100 * np.abs(0.8 - truth).mean():.2f}" in board


def test_same_download_same_id_changed_file_other_id(built, download, tmp_path, tube):
    from colonbench.benchmark.c3vd_suite import build

    suite, _ = built
    copy = tmp_path / "elsewhere" / "unpacked"
    shutil.copytree(download[0], copy)
    again, new = build(copy, tmp_path / "s1", frames_every=2, progress=False)
    assert new and again.id == suite.id and again.signature == suite.signature
    assert build(copy, tmp_path / "s1", frames_every=2, progress=False)[1] is False   # already built: nothing done
    assert build(copy, tmp_path / "s2", frames_every=3, progress=False)[0].id != suite.id
    frame = copy / "c1_cecum_t1_v1" / "depth" / "0007_depth.tiff"
    import tifffile

    z = tifffile.imread(frame)
    z[0, 0] ^= 1
    tifffile.imwrite(frame, z)
    assert build(copy, tmp_path / "s3", frames_every=2, progress=False)[0].id != suite.id


# --------------------------------------------------------------------------------------------- refusals

def _refused(root, suites, match):
    from colonbench.benchmark.c3vd_suite import build

    with pytest.raises(InputError, match=match):
        build(root, suites, frames_every=4, progress=False)
    assert _nothing_left(suites)


def test_refusals_name_the_file_and_leave_nothing(tmp_path, tube, download):
    good = download[0] / "c1_cecum_t1_v1"

    def copy(name):
        dst = tmp_path / name / "dl"
        shutil.copytree(download[0], dst)
        return dst, dst / "c1_cecum_t1_v1"

    # a wrongly scaled depth, next to a good sequence: the whole build is refused
    dl, _ = copy("scaled")
    _download(dl, tube, name="c2_sigmoid_t2_v1", depth_range_mm=50.0)
    _refused(dl, tmp_path / "scaled" / "suites", r"sequence c2_sigmoid_t2_v1: .* do not land on its mesh")
    dl, seq = copy("missing")
    (seq / "depth" / "0005_depth.tiff").unlink()
    _refused(dl, tmp_path / "missing" / "suites", r"0005_depth\.tiff: missing")
    dl, seq = copy("last")
    (seq / "depth" / f"{FRAMES - 1:04d}_depth.tiff").unlink()
    _refused(dl, tmp_path / "last" / "suites", rf"{FRAMES - 1:04d}_depth\.tiff: missing .* {FRAMES} poses")
    dl, seq = copy("novt")
    text = (seq / "coverage_mesh.obj").read_text()
    (seq / "coverage_mesh.obj").write_text(text.replace("/1 ", " ").replace("/2 ", " ").replace("/1\n", "\n")
                                           .replace("/2\n", "\n"))
    _refused(dl, tmp_path / "novt" / "suites", r"coverage_mesh\.obj, line \d+: a face without a texture index")
    dl, seq = copy("badtiff")
    (seq / "depth" / "0000_depth.tiff").write_bytes(b"not a tiff at all")
    _refused(dl, tmp_path / "badtiff" / "suites", r"0000_depth\.tiff: not a readable TIFF")
    dl, seq = copy("small")
    import tifffile

    tifffile.imwrite(seq / "depth" / "0004_depth.tiff", np.ones((10, 12), np.uint16))
    _refused(dl, tmp_path / "small" / "suites", r"0004_depth\.tiff: 12 x 10 pixels; the camera's intrinsics are for 135")
    dl, seq = copy("badpose")
    lines = (seq / "pose.txt").read_text().splitlines()
    (seq / "pose.txt").write_text("\n".join(lines[:3] + ["1,2,3"] + lines[4:]) + "\n")
    _refused(dl, tmp_path / "badpose" / "suites", r"pose\.txt, pose 4: not 16 finite numbers")
    dl, _ = copy("nointr")
    (dl / "camera_intrinsics.txt").unlink()
    _refused(dl, tmp_path / "nointr" / "suites", r"no camera_intrinsics\.txt .* --intrinsics")
    (tmp_path / "zips").mkdir()
    (tmp_path / "zips" / "c1_cecum_t1_v1.zip").write_bytes(b"PK")
    _refused(tmp_path / "zips", tmp_path / "zips" / "suites", r"no registered C3VD sequence or screening withdrawal found; .* unzip them")
    assert good.is_dir()


def test_layouts_v1_and_screening_withdrawals(tmp_path, tube):
    root, seen = _download(tmp_path / "v1", tube, name="cecum_t1_a", layout="v1", intrinsics_dir=tmp_path)
    (root / "cecum_t1_a" / "coverage_mesh.obj").rename(root / "cecum_t1_a" / "outputMesh.obj")
    screening = root / "c1_screening_v1"
    screening.mkdir()
    (screening / "pose.txt").write_text(pose_lines(tube[2][:3]))
    with pytest.raises(InputError, match="no camera_intrinsics.txt"):
        c3vd.find_sequences(root)
    (seq,), skipped = c3vd.find_sequences(root, intrinsics=tmp_path / "camera_intrinsics.txt")
    assert seq.layout == "v1" and seq.mesh.name == "outputMesh.obj" and len(seq.depth) == FRAMES
    assert skipped[0]["folder"] == "c1_screening_v1" and "not a registered sequence" in skipped[0]["reason"]
    # not a screening withdrawal either (not named cN_full_..., no whole-colon mesh): nothing of the download
    _, screening, skipped = c3vd.find_download(root, intrinsics=tmp_path / "camera_intrinsics.txt")
    assert screening == [] and "not named as a screening withdrawal" in skipped[0]["reason"]


def test_the_command_line(download, tmp_path, capsys):
    from colonbench.cli import main

    data = tmp_path / "suites"
    assert main(["suites", "build", "c3vd", "--from", str(download[0]), "--data", str(data), "--frames-every", "4",
                 "--quiet"]) == 0
    out = capsys.readouterr().out
    assert "c1_cecum_t1_v1: " in out and "poses transposed (C3VD's" in out and "built c3vd-" in out
    assert "its fused partials reach " in out and "of the observed area within 1.5 mm (95% needed" in out
    assert main(["suites", "--data", str(data)]) == 0
    assert "built here from a download" in capsys.readouterr().out
    assert main(["suites", "build", "c3vd", "--from", str(tmp_path / "nothing"), "--data", str(data)]) == 2
    assert "nothing: no such folder" in capsys.readouterr().err
    sid = next(p.name for p in data.iterdir())
    assert main(["suites", "--data", str(data), "card", sid, "--out", str(tmp_path)]) == 2
    assert "has no card" in capsys.readouterr().err
    assert Fisheye(**read_intrinsics(download[0] / "camera_intrinsics.txt").to_dict()) == CAMERA
