"""Centerlines with known geometry for the tests."""

import numpy as np

from colonbench.datagen.centerline import Centerline

def straight(length=240.0, spacing=0.5):
    """A straight centerline along +z from the origin."""
    return Centerline.from_function(lambda t: np.stack([0 * t, 0 * t, t], 1), 0.0, length, spacing)


def arc(radius, angle, spacing=0.5):
    """A planar circular arc of ``radius`` (mm) through ``angle`` (rad) in the x-y plane."""
    return Centerline.from_function(
        lambda t: np.stack([radius * np.cos(t), radius * np.sin(t), 0 * t], 1), 0.0, angle, spacing)
