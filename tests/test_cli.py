"""The command line, run as a user runs it."""

import json
import subprocess
import sys

import numpy as np
import pytest
import trimesh
import yaml

CLI = [sys.executable, "-m", "colonbench.cli"]


def run(*args, cwd=None):
    return subprocess.run([*CLI, *map(str, args)], capture_output=True, text=True, cwd=cwd)


def test_help_lists_commands():
    r = run("--help")
    assert r.returncode == 0
    for cmd in ("colon", "segments", "picture", "demo"):
        assert cmd in r.stdout


def test_segments_writes_sample_folders(tmp_path):
    cfg = tmp_path / "cfg.yaml"
    cfg.write_text(yaml.safe_dump({"colon": {"ring_spacing_mm": 1.5, "edge_mm": 2.0}}))
    r = run("segments", "--seed", 2, "--config", cfg, "--segment", 3, "--permutations", 2,
            "--hole-model", "spheres", "--out", tmp_path / "out")
    assert r.returncode == 0, r.stderr
    folders = sorted((tmp_path / "out").iterdir())
    assert [f.name for f in folders] == ["colon0000_l60_s003_p00", "colon0000_l60_s003_p01"]
    gt = json.loads((folders[0] / "gt.json").read_text())
    complete = trimesh.load(folders[0] / "complete.ply", process=False)
    observed = np.load(folders[0] / "observed_faces.npy")
    assert abs(gt["coverage"] - complete.area_faces[observed].sum() / complete.area) < 1e-6
    partial = trimesh.load(folders[0] / "partial.ply")
    assert len(partial.vertices) > 1000
    assert np.load(folders[0] / "centerline.npy").shape[1] == 3
    assert gt["noise_mm"] == 0.0
    # the same sample with noise: same coverage, points off the surface by about sigma
    r = run("segments", "--seed", 2, "--config", cfg, "--segment", 3, "--hole-model", "spheres",
            "--noise", 0.5, "--out", tmp_path / "noisy")
    assert r.returncode == 0, r.stderr
    noisy = sorted((tmp_path / "noisy").iterdir())[0]
    gt_noisy = json.loads((noisy / "gt.json").read_text())
    assert gt_noisy["noise_mm"] == 0.5 and gt_noisy["coverage"] == gt["coverage"]
    d = np.abs(trimesh.proximity.signed_distance(complete, trimesh.load(noisy / "partial.ply").vertices[:2000]))
    assert 0.3 < np.sqrt(np.mean(d**2)) < 0.7
    r = run("segments", "--noise", -1, "--out", tmp_path / "bad")
    assert r.returncode == 2 and "noise_mm" in r.stderr


def test_bad_input_gives_a_message_not_a_traceback(tmp_path):
    cfg = tmp_path / "bad.yaml"
    cfg.write_text("camera:\n  fov_deg: 400\n")
    r = run("colon", "--config", cfg, "--out", tmp_path)
    assert r.returncode == 2
    assert "CameraConfig.fov_deg = 400 is out of range" in r.stderr
    assert "Traceback" not in r.stderr
    r = run("colon", "--mesh", tmp_path / "none.ply", "--out", tmp_path)
    assert r.returncode == 2 and "no such file" in r.stderr and "Traceback" not in r.stderr
    r = run("segments", "--length", "-5", "--out", tmp_path)
    assert r.returncode == 2 and "must be a positive number, got -5" in r.stderr
    # nan and inf parse as floats: refused by the argument types, not by a traceback further on
    r = run("map", tmp_path / "none.npy", "--segment-length", "nan", "--out", tmp_path)
    assert r.returncode == 2 and "must be a positive number, got nan" in r.stderr
    r = run("map", tmp_path / "none.npy", "--context-mm", "inf", "--out", tmp_path)
    assert r.returncode == 2 and "must be a finite number, got inf" in r.stderr
    r = run("evaluate", tmp_path, "--noise", "0,nan", "--out", tmp_path)
    assert r.returncode == 2 and "not a comma-separated list of finite numbers" in r.stderr
    r = run("video", "--out", tmp_path, "--gif-seconds", "-1")
    assert r.returncode == 2 and "--gif-seconds: must be 0 or more, got -1" in r.stderr
    r = run("segments", "--segment", "999", "--out", tmp_path)
    assert r.returncode == 2 and "segment 999 does not exist" in r.stderr


def test_a_ply_without_a_coordinate_is_refused_by_name(tmp_path):
    # a PLY whose vertices have x but no y or z: the message names the missing property, not trimesh's KeyError
    from colonbench.errors import InputError
    from colonbench.pointio import read_surface

    (tmp_path / "x_only.ply").write_text("ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nend_header\n1\n2\n")
    with pytest.raises(InputError, match="x_only.ply: could not read points: no vertex property 'y'"):
        read_surface(tmp_path / "x_only.ply")
    for name in ("empty.ply", "empty.npy", "empty.xyz"):       # not the reader's "Not a ply file!" or EOFError
        (tmp_path / name).write_bytes(b"")
        with pytest.raises(InputError, match=f"{name}: the file is empty"):
            read_surface(tmp_path / name)


def test_picture(tmp_path):
    from colonbench.datagen.colon import tube_colon
    from shapes import straight

    colon = tube_colon(straight(150.0), 15.0, 1.0, 64)
    # a closed copy for the importer: cap the open tube
    mesh = trimesh.creation.cylinder(radius=15.0, height=150.0, sections=64)
    mesh.export(tmp_path / "tube.ply")
    np.save(tmp_path / "cl.npy", colon.centerline.points - [0, 0, 75.0])
    r = run("picture", "--mesh", tmp_path / "tube.ply", "--centerline", tmp_path / "cl.npy",
            "--segment", 0, "--hole-model", "spheres", "--out", tmp_path / "seg.png")
    assert r.returncode == 0, r.stderr
    png = (tmp_path / "seg.png").read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n" and len(png) > 10000


def test_estimate_reads_a_mesh_on_its_faces_and_leaves_out_points_that_are_not_finite(tmp_path):
    # a 60 mm tube of radius 15: as a coarse .obj mesh it is sampled on its faces at the training density
    # (its 1440 vertices would be a sparse cloud); a NaN row of a cloud is left out with a note
    from shapes import straight

    from colonbench.datagen.colon import tube_colon
    from colonbench.pointio import MESH_DENSITY, read_surface

    mesh = tube_colon(straight(60.0), 15.0, ring_spacing_mm=2.5, n_around=60).mesh
    mesh.export(tmp_path / "tube.obj")
    pts, dropped = read_surface(tmp_path / "tube.obj")
    assert dropped == 0 and len(pts) == round(MESH_DENSITY * mesh.area)
    assert np.abs(np.linalg.norm(pts[:, :2], axis=1) - 15.0).max() < 0.2   # on the faces, not only the vertices
    for name in ("tube.stl", "tube.off"):   # what CT segmentation tools export; STL's triangle soup samples alike
        mesh.export(tmp_path / name)
        other, dropped = read_surface(tmp_path / name)
        assert dropped == 0 and len(other) == round(MESH_DENSITY * mesh.area), name
        assert np.abs(np.linalg.norm(other[:, :2], axis=1) - 15.0).max() < 0.2, name
    cloud = np.concatenate([pts, [[np.nan, 0.0, 0.0], [np.inf, 1.0, 2.0]]])
    np.savetxt(tmp_path / "cloud.xyz", cloud)
    again, dropped = read_surface(tmp_path / "cloud.xyz")
    assert dropped == 2 and np.allclose(again, pts)
    r = run("estimate", tmp_path / "cloud.xyz", tmp_path / "tube.obj", "--method", "unwrap-pca",
            "--out-dir", tmp_path / "o")
    assert r.returncode == 0, r.stderr
    assert "cloud.xyz: 2 point(s) that are NaN or infinite left out" in r.stderr
    assert json.loads((tmp_path / "o" / "tube.json").read_text())["coverage"] > 0.9
    (tmp_path / "empty.xyz").write_text("")
    r = run("estimate", tmp_path / "empty.xyz", "--out-dir", tmp_path / "o")
    assert r.returncode == 2 and "the file is empty" in r.stderr and "Warning" not in r.stderr
    (tmp_path / "header.xyz").write_text("# x y z\n")     # a file with no rows: no numpy warning either
    r = run("estimate", tmp_path / "header.xyz", "--out-dir", tmp_path / "o")
    assert r.returncode == 2 and "0 point(s)" in r.stderr and "Warning" not in r.stderr


def test_text_clouds_are_read_as_spreadsheets_and_cloudcompare_write_them(tmp_path):
    # the same points as a header-less .xyz, a .csv with a header, CloudCompare's "//X Y Z" .txt,
    # semicolons, and extra colour columns; a bad row is named by its line in the file
    from colonbench.errors import InputError
    from colonbench.pointio import read_surface

    pts = np.random.default_rng(0).normal(size=(50, 3)) * 20
    np.savetxt(tmp_path / "plain.xyz", pts)
    np.savetxt(tmp_path / "named.csv", pts, delimiter=",", header="x,y,z", comments="")
    np.savetxt(tmp_path / "cc.txt", pts, header="X Y Z", comments="//")
    np.savetxt(tmp_path / "semi.csv", pts, delimiter=";")
    np.savetxt(tmp_path / "rgb.xyz", np.c_[pts, np.full((50, 3), 200)], header="comment", comments="# ")
    for name in ("plain.xyz", "named.csv", "cc.txt", "semi.csv", "rgb.xyz"):
        got, dropped = read_surface(tmp_path / name)
        assert dropped == 0 and np.allclose(got, pts), name
    (tmp_path / "only.csv").write_text("x,y,z\n")
    assert read_surface(tmp_path / "only.csv")[0].shape == (0, 3)
    (tmp_path / "bad.csv").write_text("x,y,z\n1,2,3\n\n4,five,6\n")
    with pytest.raises(InputError, match=r"bad.csv: line 4 is not x, y, z numbers: '4,five,6'"):
        read_surface(tmp_path / "bad.csv")
    with pytest.raises(InputError, match="a folder, not a file"):
        read_surface(tmp_path)
    (tmp_path / "two.xyz").write_text("1 2\n3 4\n")
    with pytest.raises(InputError, match="line 1 is not x, y, z numbers"):
        read_surface(tmp_path / "two.xyz")


def test_estimate_that_writes_nothing_leaves_no_folder_it_made(tmp_path):
    out = tmp_path / "made" / "results"
    (tmp_path / "a folder").mkdir()
    for bad in (tmp_path / "missing.ply", tmp_path / "a folder"):
        r = run("estimate", bad, "--method", "constant", "--out-dir", out)
        assert r.returncode == 2 and "nothing was written" in r.stderr and "Traceback" not in r.stderr
        assert not (tmp_path / "made").exists()  # neither the folder asked for nor the parent made for it
    mine = tmp_path / "mine"
    mine.mkdir()  # a folder that was there before is left as it was, empty or not
    r = run("estimate", tmp_path / "missing.ply", "--method", "constant", "--out-dir", mine)
    assert r.returncode == 2 and mine.is_dir()
    np.save(tmp_path / "seg.npy", np.random.default_rng(0).normal(size=(500, 3)) * [15, 15, 30])
    r = run("estimate", tmp_path / "seg.npy", tmp_path / "missing.ply", "--method", "constant", "--out-dir", out)
    assert r.returncode == 2 and "the others were written" in r.stderr
    assert [p.name for p in out.iterdir()] == ["seg.json"]
