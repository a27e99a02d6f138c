"""Tubes, the self-intersection check and segment areas on shapes with exact answers."""

import numpy as np
import pytest
import trimesh

from colonbench.datagen.camera import SurfaceScene
from colonbench.datagen.colon import tube_colon
from colonbench.datagen.segments import segment_surface, windows
from colonbench.datagen.tube import disk_collisions, self_intersections
from colonbench.polyline import Centerline
from shapes import arc, straight

N_AROUND = 256


def polygon_area(r, l, n=N_AROUND):
    """Area of a prism over a regular n-gon inscribed in radius r: the mesh's exact area."""
    return n * 2 * r * np.sin(np.pi / n) * l


def test_straight_cylinder_segments_have_area_2_pi_r_l():
    r = 20.0
    colon = tube_colon(straight(300.0), r, ring_spacing_mm=0.7, n_around=N_AROUND)
    scene = SurfaceScene(colon.mesh.vertices, colon.mesh.faces)
    wins = windows(colon.centerline.length, 60.0, 5.0)
    assert len(wins) == 4
    for s0, s1 in wins:
        seg = segment_surface(scene, colon.centerline, s0, s1)
        assert seg.area == pytest.approx(polygon_area(r, s1 - s0), rel=1e-9)
        assert seg.area == pytest.approx(2 * np.pi * r * (s1 - s0), rel=1e-4)
        # every clipped vertex lies between the planes
        z = seg.mesh.vertices[:, 2]
        assert z.min() == pytest.approx(s0, abs=1e-9) and z.max() == pytest.approx(s1, abs=1e-9)
        # GT centerline inside the segment, <= 0.5 mm apart
        assert np.diff(seg.centerline[:, 2]).max() <= 0.5 + 1e-9


def test_curved_segment_area_by_pappus():
    # a tube around a circular arc: the surface between two normal planes has
    # area 2 pi r * (arc length) exactly (Pappus), whatever the bend
    r, bend = 15.0, 40.0
    colon = tube_colon(arc(bend, 1.5 * np.pi), r, ring_spacing_mm=0.25, n_around=N_AROUND)
    scene = SurfaceScene(colon.mesh.vertices, colon.mesh.faces)
    for s0, s1 in [(10.0, 60.0), (37.3, 107.3)]:
        seg = segment_surface(scene, colon.centerline, s0, s1)
        assert seg.area == pytest.approx(2 * np.pi * r * (s1 - s0), rel=2e-3)


def test_neighbouring_loop_never_leaks_into_a_segment():
    # a hairpin: up, a half turn of radius 32, back down. The legs are 64 mm
    # apart and the tubes 20 mm thick, so the wall gap is 24 mm: the planes of
    # a segment on one leg cut the other leg too.
    r, bend, leg = 20.0, 32.0, 150.0
    up = np.stack([np.full(300, -bend), np.zeros(300), np.linspace(0, leg, 300)], 1)
    th = np.linspace(np.pi, 0, 200)
    turn = np.stack([bend * np.cos(th), np.zeros(200), leg + bend * np.sin(th)], 1)
    down = np.stack([np.full(300, bend), np.zeros(300), np.linspace(leg, 0, 300)], 1)
    cl = Centerline.from_points(np.concatenate([up, turn[1:-1], down])).resample(0.5)
    colon = tube_colon(cl, r, ring_spacing_mm=0.5, n_around=N_AROUND)
    assert len(self_intersections(cl, colon.radius, clearance_mm=3.0)) == 0
    scene = SurfaceScene(colon.mesh.vertices, colon.mesh.faces)
    seg = segment_surface(scene, cl, 40.0, 100.0)
    assert seg.info["pieces_between_planes"] >= 2   # the other leg crosses the slab
    assert seg.info["pieces_kept"] == 1
    assert seg.area == pytest.approx(polygon_area(r, 60.0), rel=1e-6)
    assert np.all(seg.mesh.vertices[:, 0] < 0)       # nothing of the other leg (x > 0)


def test_disk_collisions_for_two_parallel_tubes():
    z = np.linspace(0, 100, 101)
    tangents = np.tile([0, 0, 1.0], (202, 1))
    for gap, expect in [(41.0, False), (39.0, True)]:
        centers = np.concatenate([np.stack([0 * z, 0 * z, z], 1), np.stack([0 * z + gap, 0 * z, z], 1)])
        pairs = disk_collisions(centers, tangents, np.full(202, 20.0), min_index_gap=1)
        assert (len(pairs) > 0) == expect


def test_self_intersection_is_found_and_agrees_with_open3d():
    import open3d as o3d

    def o3d_self_intersecting(colon):
        m = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(colon.mesh.vertices),
                                      o3d.utility.Vector3iVector(colon.mesh.faces))
        return m.is_self_intersecting()

    # a bend tighter than the tube: the inner wall folds over itself
    tight = tube_colon(arc(12.0, np.pi), 15.0, ring_spacing_mm=2.0, n_around=24)
    assert len(self_intersections(tight.centerline, tight.radius)) > 0
    assert o3d_self_intersecting(tight)
    # the same bend with a thin tube is clean, by both checks
    thin = tube_colon(arc(12.0, np.pi), 8.0, ring_spacing_mm=2.0, n_around=24)
    assert len(self_intersections(thin.centerline, thin.radius)) == 0
    assert not o3d_self_intersecting(thin)


def test_clipped_mesh_stays_welded():
    colon = tube_colon(straight(100.0), 10.0, ring_spacing_mm=1.0, n_around=64)
    scene = SurfaceScene(colon.mesh.vertices, colon.mesh.faces)
    seg = segment_surface(scene, colon.centerline, 20.3, 50.7)
    m = trimesh.Trimesh(seg.mesh.vertices, seg.mesh.faces, process=False)
    # one connected band with exactly two boundary loops (the cuts)
    assert m.body_count == 1
    edges = m.edges_sorted
    _, counts = np.unique(edges, axis=0, return_counts=True)
    boundary_edges = (counts == 1).sum()
    assert boundary_edges == 2 * 64 * 2  # each cut crosses 2 triangles per quad column


def test_helical_tube_length_and_segments():
    from shapes import helix

    cl, exact = helix()
    colon = tube_colon(cl, 8.0, ring_spacing_mm=0.5, n_around=128)
    assert colon.centerline.length == pytest.approx(exact, rel=1e-9)
    assert len(self_intersections(cl, colon.radius, clearance_mm=3.0)) == 0
    scene = SurfaceScene(colon.mesh.vertices, colon.mesh.faces)
    seg = segment_surface(scene, cl, 100.0, 160.0)
    # Pappus again: a constant-radius tube around any curve (curvature < 1/r)
    # has area 2 pi r l between two normal planes
    assert seg.area == pytest.approx(polygon_area(8.0, 60.0, 128), rel=2e-3)
    assert np.linalg.norm(np.diff(seg.centerline, axis=0), axis=1).sum() == pytest.approx(60.0, rel=1e-4)
