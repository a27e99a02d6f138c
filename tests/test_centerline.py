import numpy as np
import pytest

from colonbench.errors import InputError
from colonbench.polyline import Centerline
from shapes import arc


def helix(radius=30.0, pitch=40.0, turns=3.0, spacing=0.5):
    c = pitch / (2 * np.pi)
    f = lambda t: np.stack([radius * np.cos(t), radius * np.sin(t), c * t], 1)  # noqa: E731
    return Centerline.from_function(f, 0.0, 2 * np.pi * turns, spacing), 2 * np.pi * turns * np.hypot(radius, c)


def test_helix_length_is_exact():
    cl, exact = helix()
    assert cl.length == pytest.approx(exact, rel=1e-8)
    # samples are uniform in arc length, at most 0.5 mm apart
    assert np.diff(cl.arclength).max() <= 0.5 + 1e-12
    chord = np.linalg.norm(np.diff(cl.points, axis=0), axis=1)
    assert np.allclose(chord, np.diff(cl.arclength), rtol=1e-4)


def test_helix_curvature_and_resample():
    radius, pitch = 30.0, 40.0
    cl, exact = helix(radius, pitch)
    c = pitch / (2 * np.pi)
    kappa = radius / (radius**2 + c**2)
    assert np.allclose(cl.curvature()[5:-5], kappa, rtol=1e-3)
    again = cl.resample(0.25)
    assert again.length == pytest.approx(exact, rel=1e-6)


def test_rotation_minimising_frames_on_a_circle():
    cl = arc(50.0, np.pi)
    t, n, b = cl.frames()
    assert np.allclose(np.einsum("ij,ij->i", t, n), 0, atol=1e-9)
    assert np.allclose(np.linalg.norm(n, axis=1), 1)
    assert np.allclose(np.cross(n, b), t, atol=1e-9)
    # on a planar curve the RMF does not twist: the angle between the normal and
    # the plane normal (z) stays constant
    assert np.ptp(n[:, 2]) < 1e-6


def test_point_and_window():
    cl = arc(50.0, np.pi / 2)
    p = cl.point_at([cl.length / 2])[0]
    assert np.allclose(p, 50 * np.array([np.cos(np.pi / 4), np.sin(np.pi / 4), 0]), atol=1e-3)
    w = cl.window(10.0, 20.0)
    assert np.linalg.norm(np.diff(w, axis=0), axis=1).sum() == pytest.approx(10.0, abs=1e-3)


def test_bad_centerlines():
    with pytest.raises(InputError, match="NaN"):
        Centerline.from_points([[0, 0, 0], [np.nan, 0, 1], [0, 0, 2]])
    with pytest.raises(InputError, match="two distinct"):
        Centerline.from_points([[1, 1, 1], [1, 1, 1]])
    with pytest.raises(InputError, match=r"\(n, 3\)"):
        Centerline.from_points(np.zeros((5, 2)))
