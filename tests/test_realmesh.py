"""Importing a user's colon mesh: the real CT colon, and bad files."""

import numpy as np
import pytest
import trimesh

from colonbench.datagen.camera import SurfaceScene
from colonbench.datagen.colon import tube_colon
from colonbench.datagen.generate import GeneratorConfig, colon_samples
from colonbench.datagen.realmesh import check_centerline_inside, import_colon, load_centerline, load_mesh
from colonbench.errors import InputError
from colonbench.polyline import Centerline
from shapes import straight

MESH = "gca00090_large_intestine_mm.ply"
PATH = "gca00090_path_mm.npy"


def test_real_colon_with_its_midline(real_dir):
    colon = import_colon(real_dir / MESH, real_dir / PATH)
    assert colon.centerline.length == pytest.approx(1249.0, abs=2.0)
    samples = list(colon_samples(colon, GeneratorConfig(), 0, 0, 60.0, 1, "spheres", [5, 10]))
    for _, _, s in samples:
        assert 0.0 < s.coverage <= 1.0
        assert s.complete.area > 1000.0
        assert len(s.partial_points) > 0


def test_real_colon_computed_centerline_follows_the_given_one(real_dir):
    given = import_colon(real_dir / MESH, real_dir / PATH).centerline
    computed = import_colon(real_dir / MESH).centerline
    from scipy.spatial import cKDTree

    d, _ = cKDTree(given.points).query(computed.points)
    # the scan is uninflated and its rectum collapsed, so the ends may differ;
    # along the rest the two agree to a few millimetres
    assert np.median(d) < 2.0
    assert np.mean(d < 8.0) > 0.9
    assert computed.length > 0.85 * given.length


def write_ply_text(path, vertices, faces):
    lines = ["ply", "format ascii 1.0", f"element vertex {len(vertices)}", "property float x",
             "property float y", "property float z", f"element face {len(faces)}",
             "property list uchar int vertex_indices", "end_header"]
    lines += [" ".join(str(x) for x in v) for v in vertices]
    lines += ["3 " + " ".join(str(i) for i in f) for f in faces]
    path.write_text("\n".join(lines) + "\n")


def test_bad_mesh_files(tmp_path):
    with pytest.raises(InputError, match="no such file"):
        load_mesh(tmp_path / "missing.ply")
    (tmp_path / "empty.ply").write_bytes(b"")
    with pytest.raises(InputError, match="empty"):
        load_mesh(tmp_path / "empty.ply")
    (tmp_path / "junk.stl").write_text("this is not a mesh at all\n" * 3)
    with pytest.raises(InputError, match="junk.stl"):
        load_mesh(tmp_path / "junk.stl")
    (tmp_path / "mesh.vtk").write_text("x")
    with pytest.raises(InputError, match="unsupported mesh format"):
        load_mesh(tmp_path / "mesh.vtk")
    trimesh.PointCloud(np.random.default_rng(0).normal(size=(50, 3)) * 30).export(tmp_path / "cloud.ply")
    with pytest.raises(InputError, match="no triangles"):
        load_mesh(tmp_path / "cloud.ply")
    write_ply_text(tmp_path / "nan.ply", [(0, 0, 0), (10, 0, 0), ("nan", 10, 0)], [(0, 1, 2)])
    with pytest.raises(InputError, match="NaN"):
        load_mesh(tmp_path / "nan.ply")
    write_ply_text(tmp_path / "metres.ply", [(0, 0, 0), (0.03, 0, 0), (0, 0.03, 0)], [(0, 1, 2)])
    with pytest.raises(InputError, match="metres"):
        load_mesh(tmp_path / "metres.ply")


def test_bad_centerline_files(tmp_path):
    np.save(tmp_path / "flat.npy", np.zeros((10, 2)))
    with pytest.raises(InputError, match=r"\(n, 3\)"):
        load_centerline(tmp_path / "flat.npy")
    (tmp_path / "words.txt").write_text("a b c\nd e f\n")
    with pytest.raises(InputError, match="words.txt: line 2 is not"):
        load_centerline(tmp_path / "words.txt")


def test_centerline_text_files_read_as_clouds_do(tmp_path):
    # a header line and semicolons, as a spreadsheet writes them: the same line as the .npy
    pts = np.stack([np.zeros(40), np.linspace(0, 5, 40), np.linspace(0, 200, 40)], 1)
    np.save(tmp_path / "line.npy", pts)
    np.savetxt(tmp_path / "line.csv", pts, delimiter=";", header="x;y;z", comments="")
    a, b = load_centerline(tmp_path / "line.npy"), load_centerline(tmp_path / "line.csv")
    assert np.allclose(a.points, b.points) and a.length == pytest.approx(b.length)
    (tmp_path / "four.csv").write_text("x,y,z,r\n0,0,0,15\n0,0,10,15\n")
    with pytest.raises(InputError, match=r"\(n, 3\) array of points, got shape \(2, 4\)"):
        load_centerline(tmp_path / "four.csv")


def test_centerline_that_leaves_the_mesh_is_refused(tmp_path):
    # a closed tube (capped cylinder) and a centerline that runs out of its side
    tube = trimesh.creation.cylinder(radius=15.0, height=200.0, sections=64)
    assert tube.is_watertight
    scene = SurfaceScene(tube.vertices, tube.faces)
    inside = Centerline.from_points(np.stack([np.zeros(50), np.zeros(50), np.linspace(-90, 90, 50)], 1))
    check_centerline_inside(scene, inside)
    leaving = Centerline.from_points(np.stack([np.linspace(0, 60, 50), np.zeros(50), np.linspace(-90, 90, 50)], 1))
    with pytest.raises(InputError, match="leaves the mesh"):
        check_centerline_inside(scene, leaving)
    tube.export(tmp_path / "tube.stl")
    np.savetxt(tmp_path / "cl.txt", leaving.points)
    with pytest.raises(InputError, match="leaves the mesh"):
        import_colon(tmp_path / "tube.stl", tmp_path / "cl.txt")


def test_computed_centerline_of_a_closed_straight_tube(tmp_path):
    tube = trimesh.creation.cylinder(radius=12.0, height=150.0, sections=64)
    tube.export(tmp_path / "tube.ply")
    colon = import_colon(tmp_path / "tube.ply")
    cl = colon.centerline
    off_axis = np.hypot(cl.points[:, 0], cl.points[:, 1])
    middle = (cl.arclength > 0.1 * cl.length) & (cl.arclength < 0.9 * cl.length)
    assert off_axis[middle].max() < 1.0          # on the axis
    assert off_axis.max() < 6.0 + 1.0             # the ends stop half a radius from the wall
    assert np.ptp(cl.points[:, 2]) > 150.0 - 2 * 12.0   # it runs end to end


def test_open_tube(tmp_path):
    colon = tube_colon(straight(100.0), 10.0, 1.0, 32)
    colon.mesh.export(tmp_path / "open.ply")
    with pytest.raises(InputError, match="watertight"):
        import_colon(tmp_path / "open.ply")
    # its own centerline is accepted, one through the wall is not
    np.save(tmp_path / "cl.npy", colon.centerline.points)
    assert import_colon(tmp_path / "open.ply", tmp_path / "cl.npy").centerline.length == pytest.approx(100.0)
    np.save(tmp_path / "out.npy", colon.centerline.points + [30.0, 0, 0])
    with pytest.raises(InputError, match="leaves the mesh"):
        import_colon(tmp_path / "open.ply", tmp_path / "out.npy")


def test_computed_centerline_of_a_closed_helical_tube(tmp_path):
    from scipy.spatial import cKDTree
    from shapes import capped, helix

    cl, exact = helix(radius=40.0, pitch=60.0, turns=1.5)
    mesh = capped(tube_colon(cl, 8.0, ring_spacing_mm=0.5, n_around=96))
    assert mesh.is_watertight
    mesh.export(tmp_path / "helix.ply")
    computed = import_colon(tmp_path / "helix.ply").centerline
    d, _ = cKDTree(cl.points).query(computed.points)
    s = computed.arclength
    middle = (s > 0.1 * s[-1]) & (s < 0.9 * s[-1])
    assert np.median(d) < 0.5 and d[middle].max() < 1.0   # within a voxel of the true helix
    assert d.max() < 8.0 / 2 + 1.0                          # the ends stop half a radius off the wall
    assert computed.length == pytest.approx(exact, abs=2 * 8.0 + 2.0)  # less at most the trimmed ends
