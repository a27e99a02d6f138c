"""Hole models on a cylinder, where the observed area is known exactly."""

import numpy as np
import pytest
from scipy.integrate import quad

from colonbench import seeding
from colonbench.datagen.camera import Poses, SurfaceScene, visible_faces
from colonbench.datagen.colon import tube_colon
from colonbench.datagen.config import SphereConfig
from colonbench.datagen.holes import inside_spheres
from colonbench.datagen.sample import hole_areas
from colonbench.datagen.segments import segment_surface
from colonbench.meshes import sample_surface
from shapes import straight

R = 20.0


@pytest.fixture(scope="module")
def cylinder():
    colon = tube_colon(straight(200.0), R, ring_spacing_mm=0.5, n_around=256)
    scene = SurfaceScene(colon.mesh.vertices, colon.mesh.faces)
    return colon, scene


def one_pose(position, direction, reach):
    return Poses(np.array([position], float), np.array([direction], float), np.array([reach], float),
                 np.array([position[2]], float))


def test_camera_sees_the_known_band(cylinder):
    # camera on the axis at z=10 looking along +z, 90 degree field of view,
    # reach 60 mm: the wall is seen from z = 10 + R (45 degrees) to
    # z = 10 + sqrt(60^2 - R^2) (reach), a band of area 2 pi R (sqrt(60^2-R^2) - R)
    colon, scene = cylinder
    seen = visible_faces(scene, one_pose([0, 0, 10.0], [0, 0, 1.0], 60.0), fov_deg=90.0)
    seg = segment_surface(scene, colon.centerline, 10.0, 100.0)
    observed = seen[seg.parent_face]
    band = 2 * np.pi * R * (np.sqrt(60.0**2 - R**2) - R)
    coverage = seg.mesh.area_faces[observed].sum() / seg.area
    assert coverage == pytest.approx(band / (2 * np.pi * R * 90.0), abs=0.005)
    # the holes: the two rings of wall before and after the band
    areas = hole_areas(seg.mesh, observed)
    assert len(areas) == 2
    assert areas.sum() == pytest.approx(seg.area - band, rel=0.01)


def test_fold_hides_the_wall_behind_it():
    # a sharp ring fold of depth h at z in [60, 61]; camera on the axis at z=0
    # looking along +z. The wall behind the fold is hidden from its back edge
    # to z = 61 R / (R - h), and seen again after that.
    h = 6.0
    radius = lambda s, th: np.where((s >= 60.0) & (s <= 61.0), R - h, R) + 0 * th  # noqa: E731
    colon = tube_colon(straight(200.0), radius, ring_spacing_mm=0.25, n_around=256)
    scene = SurfaceScene(colon.mesh.vertices, colon.mesh.faces)
    seen = visible_faces(scene, one_pose([0, 0, 0.0], [0, 0, 1.0], 1000.0), fov_deg=170.0)
    c = scene.centroids
    wall = np.abs(np.hypot(c[:, 0], c[:, 1]) - R) < 0.1
    z = c[:, 2]
    shadow_end = 61.0 * R / (R - h)
    assert not seen[wall & (z > 62.0) & (z < shadow_end - 1.0)].any()
    assert seen[wall & (z > shadow_end + 1.0) & (z < 150.0)].all()
    assert seen[wall & (z > 5.0) & (z < 59.0)].all()


def test_sphere_crop_removes_the_known_area(cylinder):
    # a sphere of radius a centred on the wall removes the part of the cylinder
    # within distance a of the centre: area = int 2 r sqrt(a^2 - 4 r^2 sin^2(phi/2)) dphi
    colon, scene = cylinder
    seg = segment_surface(scene, colon.centerline, 40.0, 100.0)
    a = 12.0
    center = np.array([[R, 0.0, 70.0]])
    removed = inside_spheres(seg.mesh.triangles_center, center, [a])
    phi_max = 2 * np.arcsin(a / (2 * R))
    exact, _ = quad(lambda p: 2 * R * np.sqrt(max(a**2 - 4 * R**2 * np.sin(p / 2) ** 2, 0.0)), -phi_max, phi_max)
    coverage = 1 - seg.mesh.area_faces[removed].sum() / seg.area
    assert coverage == pytest.approx(1 - exact / seg.area, abs=0.005)
    assert seg.mesh.area_faces[removed].sum() == pytest.approx(exact, rel=0.02)


def test_window_cut_gives_known_coverage(cylinder):
    # a window |theta| < 0.6 rad, z in [55, 80] removed from a 60 mm segment
    colon, scene = cylinder
    seg = segment_surface(scene, colon.centerline, 40.0, 100.0)
    c = seg.mesh.triangles_center
    theta = np.arctan2(c[:, 1], c[:, 0])
    cut = (np.abs(theta) < 0.6) & (c[:, 2] > 55.0) & (c[:, 2] < 80.0)
    coverage = seg.mesh.area_faces[~cut].sum() / seg.area
    exact = 1 - (R * 1.2 * 25.0) / (2 * np.pi * R * 60.0)
    assert coverage == pytest.approx(exact, abs=0.005)
    assert len(hole_areas(seg.mesh, ~cut)) == 1


def test_surface_sampling_density_and_determinism(cylinder):
    colon, scene = cylinder
    seg = segment_surface(scene, colon.centerline, 40.0, 100.0)
    p1 = sample_surface(seeding.rng(0, "points"), seg.mesh.vertices, seg.mesh.faces, density=2.0)
    p2 = sample_surface(seeding.rng(0, "points"), seg.mesh.vertices, seg.mesh.faces, density=2.0)
    assert np.array_equal(p1, p2)
    assert len(p1) == round(2.0 * seg.area)
    assert np.allclose(np.hypot(p1[:, 0], p1[:, 1]), R, atol=0.01)
    assert p1[:, 2].min() >= 40.0 and p1[:, 2].max() <= 100.0


def test_sphere_config_draws_within_ranges():
    from colonbench.datagen.holes import sample_spheres

    colon = tube_colon(straight(100.0), R, 1.0, 64)
    cfg = SphereConfig(spheres=(3, 3), radius_mm=(5.0, 6.0))
    centers, radii = sample_spheres(seeding.rng(1, "spheres"), colon.mesh.vertices, colon.mesh.faces, cfg)
    assert len(centers) == 3 and np.all((radii >= 5.0) & (radii <= 6.0))
