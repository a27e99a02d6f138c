"""Training augmentations, applied on the fly to the geometry a shard stores.

The paper trains with scale, rotation, deformation and noise augmentations.
Here each one acts where it means something, and the heatmaps are then made
anew by :func:`colonbench.heatmaps.sample_heatmaps` exactly as for stored
samples:

- **deformation**: one smooth random displacement field (a sum of random
  Fourier modes) moves the partial points, the complete mesh and the
  centerline alike, in mm;
- **noise**: Gaussian noise of a drawn sigma on the partial points only (the
  ground truth stays clean);
- **rotation**: the grid axes, normally the principal axes of the partial
  points, are turned by a random rotation before the grid is fitted, so the
  network sees segments in orientations the principal axes would not give;
- **scale**: the fitted voxel size is multiplied by a drawn factor, so the
  segment fills more or less of the grid.

Everything draws from the generator passed in; :func:`augmented_heatmaps` with
the same generator state gives the same arrays.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from colonbench.grid import Grid, fit_grid, grid_axes
from colonbench.heatmaps import Heatmaps, sample_heatmaps
from colonbench.params import draw, param


@dataclass(frozen=True)
class AugmentConfig:
    """Ranges of the on-the-fly training augmentations (set a range to a single value to fix it)."""

    scale: tuple = param((0.95, 1.15), 0.5, 2.0, "factor", "voxel size multiplier (> 1 shrinks the segment in the grid)")
    rotation_deg: float = param(30.0, 0.0, 180.0, "degree",
                             "largest rotation of the grid axes away from the principal axes (180 = any orientation)")
    deform_mm: tuple = param((0.0, 2.0), 0.0, 10.0, "mm", "amplitude of the smooth displacement field")
    deform_wavelength_mm: tuple = param((30.0, 80.0), 5.0, 500.0, "mm", "wavelength of its Fourier modes")
    deform_modes: int = param(4, 0, 64, "count", "Fourier modes summed per displacement field")
    noise_mm: tuple = param((0.0, 0.5), 0.0, 5.0, "mm", "Gaussian noise sigma on the partial points")


def random_rotation(rng, max_deg: float) -> np.ndarray:
    """(3, 3) rotation by an angle uniform in ``[0, max_deg]`` about a uniformly random axis."""
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    angle = np.deg2rad(rng.uniform(0.0, max_deg))
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * (k @ k)


def displacement_field(rng, amplitude_mm: float, wavelength_mm: tuple, modes: int):
    """A smooth random displacement ``x -> x + u(x)``, as a function of (n, 3) points in mm.

    ``u`` is a sum of ``modes`` sinusoids with random directions, wavelengths
    drawn from ``wavelength_mm`` and random phases, scaled so that its largest
    possible value is ``amplitude_mm``. With ``amplitude < wavelength / (2 pi)``
    the map is one-to-one.
    """
    if modes == 0 or amplitude_mm == 0:
        return lambda x: np.asarray(x, dtype=float)
    k = rng.normal(size=(modes, 3))
    k /= np.linalg.norm(k, axis=1, keepdims=True)
    lam = rng.uniform(*wavelength_mm, size=modes) if isinstance(wavelength_mm, tuple) else np.full(modes, wavelength_mm)
    k *= (2 * np.pi / lam)[:, None]
    phase = rng.uniform(0, 2 * np.pi, size=modes)
    direction = rng.normal(size=(modes, 3))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    direction *= amplitude_mm / modes

    def apply(x):
        x = np.asarray(x, dtype=float)
        return x + np.sin(x @ k.T + phase) @ direction

    return apply


def augmented_heatmaps(rng, partial, vertices, faces, centerline, config: AugmentConfig | None = None,
                       grid_options: dict | None = None) -> tuple[Grid, Heatmaps]:
    """One augmented draw of a stored sample: its grid and heatmaps.

    Parameters
    ----------
    rng : numpy.random.Generator
    partial : (n, 3) float
        Partial points, mm.
    vertices : (v, 3) float
    faces : (f, 3) int
        Complete segment surface, mm.
    centerline : (m, 3) float
        GT centerline, mm.
    config : AugmentConfig, optional
    grid_options : dict, optional
        ``size``, ``margin``, ``min_extent_mm`` and ``axes`` for
        :func:`colonbench.grid.fit_grid` (defaults: its own), e.g. from a
        shard's attributes so that no augmentation remakes its heatmaps.

    Returns
    -------
    grid : Grid
        Where the augmented heatmaps sit, in the (deformed) mm frame.
    heatmaps : Heatmaps
    """
    cfg = config or AugmentConfig()
    warp = displacement_field(rng, draw(rng, cfg.deform_mm), cfg.deform_wavelength_mm, cfg.deform_modes)
    partial = warp(partial)
    vertices = warp(vertices)
    centerline = warp(centerline)
    sigma = draw(rng, cfg.noise_mm)
    if sigma > 0:
        partial = partial + rng.normal(0.0, sigma, partial.shape)
    options = dict(grid_options or {})
    rotation = random_rotation(rng, cfg.rotation_deg) @ grid_axes(partial, options.pop("axes", "pca"))
    grid = fit_grid(partial, rotation=rotation, scale=draw(rng, cfg.scale), **options)
    return grid, sample_heatmaps(grid, partial, vertices, faces, centerline)
