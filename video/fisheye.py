"""The spherical omnidirectional (fisheye) camera of C3VD: Scaramuzza's model, pixel rays and their inverse.

Model (Scaramuzza, Martinelli and Siegwart, IROS 2006, as C3VD's renderer ``rendergt`` applies it)
--------------------------------------------------------------------------------------------------
- A pixel ``(u, v)`` (column, row; the top-left pixel's centre is (0, 0)) is moved to the principal point and
  un-stretched: ``(u'', v'') = inv(S) (u - cx, v - cy)`` with the stretch matrix ``S = [[c, e], [d, 1]]``.
  C3VD's renderer builds ``S`` as ``glm::mat2(c, d, e, 1)``, and glm fills a matrix column by column, so ``d``
  sits below ``c``; the dataset's example loader writes ``[[c, d], [e, 1]]`` instead, which moves a pixel at
  the image's edge by under 3 pixels with C3VD's ``d`` and ``e`` (about 0.003 each). The depth frames were
  rendered with the renderer's, so this module uses it.
- The pixel's ray in the camera frame is ``(u'', v'', a0 + a1 r + a2 r^2 + a3 r^3 + a4 r^4)``, ``r = |(u'', v'')|``
  (C3VD's ``a1`` is 0). Camera axes as OpenCV's (and :mod:`colonbench.video.withdrawal`'s): x to the right of
  the image, y down, z forward.
- A depth frame holds z, the distance along the camera's z axis: the pixel's point is ``z * ray / ray_z``.
  Rays with ``ray_z <= 0`` (past 90 degrees from the axis, outside the lens's image circle) have no point.

:func:`read_intrinsics` reads a ``camera_intrinsics.txt``; :meth:`Fisheye.project` is the inverse of the rays
(a camera-frame direction to its pixel), by a table of the ray's angle from the axis against ``r``.
"""

from __future__ import annotations

import re
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from colonbench.errors import InputError

#: The parameters of a ``camera_intrinsics.txt``, in the order a file of bare numbers gives them.
NAMES = ("width", "height", "cx", "cy", "a0", "a1", "a2", "a3", "a4", "c", "d", "e")
#: Other spellings accepted for a parameter's name (C3VD's README writes ``ao``).
ALIASES = {"ao": "a0", "w": "width", "h": "height"}


@dataclass(frozen=True)
class Fisheye:
    """Scaramuzza intrinsics (pixels; see the module's description)."""

    width: int
    height: int
    cx: float
    cy: float
    a0: float
    a1: float
    a2: float
    a3: float
    a4: float
    c: float
    d: float
    e: float

    @property
    def stretch(self) -> np.ndarray:
        """The 2 x 2 stretch matrix ``S = [[c, e], [d, 1]]`` (pixel offset = ``S (u'', v'')``)."""
        return np.array([[self.c, self.e], [self.d, 1.0]])

    def poly(self, r) -> np.ndarray:
        """The ray's z component at un-stretched radius ``r`` (pixels)."""
        r = np.asarray(r, float)
        return self.a0 + r * (self.a1 + r * (self.a2 + r * (self.a3 + r * self.a4)))

    def rays(self, u, v) -> np.ndarray:
        """Camera-frame rays of pixels, scaled to ``z = 1``; (k, 3), NaN where the ray has no forward z.

        Parameters
        ----------
        u, v : (k,) float
            Column and row, pixels.
        """
        offset = np.stack([np.asarray(u, float).ravel() - self.cx, np.asarray(v, float).ravel() - self.cy])
        uv = np.linalg.solve(self.stretch, offset)                       # (2, k): (u'', v'')
        z = self.poly(np.hypot(uv[0], uv[1]))
        with np.errstate(divide="ignore", invalid="ignore"):
            out = np.stack([uv[0] / z, uv[1] / z, np.ones_like(z)], axis=1)
        out[~(z > 0)] = np.nan
        return out

    def pixel_grid(self, step: int = 1) -> tuple[np.ndarray, np.ndarray]:
        """Columns and rows of every ``step``-th pixel in each direction, as two (h', w') int arrays."""
        v, u = np.mgrid[0:self.height:step, 0:self.width:step]
        return u, v

    def points(self, depth, step: int = 1) -> tuple[np.ndarray, np.ndarray]:
        """The camera-frame points of a depth frame's valid pixels (every ``step``-th in each direction).

        Parameters
        ----------
        depth : (height, width) float
            z, mm; 0 (or NaN) where invalid.
        step : int

        Returns
        -------
        points : (k, 3) float, mm, camera frame
        pixels : (k, 2) int
            Their (u, v).
        """
        depth = np.asarray(depth, float)
        if depth.shape != (self.height, self.width):
            raise InputError(f"a depth frame of {depth.shape[1]} x {depth.shape[0]} pixels; the camera's "
                             f"intrinsics are for {self.width} x {self.height}")
        u, v = self.pixel_grid(step)
        z = depth[v, u].ravel()
        rays = self.rays(u.ravel(), v.ravel())
        ok = (z > 0) & np.isfinite(z) & np.isfinite(rays[:, 0])
        return rays[ok] * z[ok, None], np.stack([u.ravel()[ok], v.ravel()[ok]], axis=1)

    def _angle_table(self, samples: int = 4096) -> tuple[np.ndarray, np.ndarray]:
        """Un-stretched radius against the ray's angle from the axis, over the image, while the angle grows."""
        corners = np.array([[0, 0], [self.width - 1, 0], [0, self.height - 1], [self.width - 1, self.height - 1]])
        uv = np.linalg.solve(self.stretch, (corners - [self.cx, self.cy]).T)
        r = np.linspace(0.0, 1.05 * float(np.hypot(uv[0], uv[1]).max()), samples)
        angle = np.arctan2(r, self.poly(r))
        grows = np.flatnonzero(np.diff(angle) <= 0)
        end = grows[0] + 1 if len(grows) else samples
        return angle[:end], r[:end]

    def project(self, directions) -> np.ndarray:
        """Pixel coordinates (u, v) of camera-frame directions; (k, 2), NaN where the lens shows no such ray."""
        p = np.asarray(directions, float).reshape(-1, 3)
        lateral = np.hypot(p[:, 0], p[:, 1])
        angle = np.arctan2(lateral, p[:, 2])
        table_angle, table_r = self._angle_table()
        r = np.interp(angle, table_angle, table_r, right=np.nan)
        with np.errstate(invalid="ignore", divide="ignore"):
            unit = np.where(lateral[:, None] > 0, p[:, :2] / lateral[:, None], 0.0)
        uv = (unit * r[:, None]) @ self.stretch.T + [self.cx, self.cy]
        return uv

    def scaled(self, factor: float, width: int | None = None, height: int | None = None) -> "Fisheye":
        """The same lens on an image scaled by ``factor`` (pixel coordinates times ``factor``)."""
        s = float(factor)
        return Fisheye(int(width if width is not None else round(self.width * s)),
                       int(height if height is not None else round(self.height * s)), self.cx * s, self.cy * s,
                       self.a0 * s, self.a1, self.a2 / s, self.a3 / s ** 2, self.a4 / s ** 3, self.c, self.d, self.e)

    def half_angles(self) -> tuple[float, float]:
        """The largest angles from the axis (radians) seen at the middles of the image's left or right and top or
        bottom edges."""
        u = np.array([0.0, self.width - 1.0, self.cx, self.cx])
        v = np.array([self.cy, self.cy, 0.0, self.height - 1.0])
        rays = self.rays(u, v)
        ang = np.where(np.isfinite(rays[:, 0]), np.arctan(np.hypot(rays[:, 0], rays[:, 1])), np.pi / 2)
        return float(ang[:2].max()), float(ang[2:].max())

    def to_dict(self) -> dict:
        return {k: (int(v) if k in ("width", "height") else float(v)) for k, v in asdict(self).items()}

    def text(self) -> str:
        """The intrinsics as ``camera_intrinsics.txt`` lines ``name value`` (what :func:`read_intrinsics` reads)."""
        return "".join(f"{k} {v!r}\n" for k, v in self.to_dict().items())


def read_intrinsics(path) -> Fisheye:
    """Read a ``camera_intrinsics.txt``: 12 numbers in the order of :data:`NAMES` (any separators), or lines
    ``name value`` (also ``name = value``, ``name: value``) naming each of them (``a1`` may be left out: 0).

    Raises
    ------
    InputError
        Naming the file: missing, unreadable, or not one of these forms.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: no such file (the camera's intrinsics)")
    try:
        text = path.read_text()
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"{path}: unreadable ({exc})") from None
    named = {}
    for line in text.splitlines():
        m = re.match(r"\s*([A-Za-z][A-Za-z0-9_]*)\s*[:=,\s]\s*([-+0-9.eE]+)\s*$", line)
        if m:
            key = ALIASES.get(m.group(1).lower(), m.group(1).lower())
            if key in NAMES:
                named[key] = m.group(2)
    try:
        if named:
            named.setdefault("a1", "0")
            missing = [k for k in NAMES if k not in named]
            if missing:
                raise InputError(f"{path}: names no {', '.join(missing)} (the camera's intrinsics need "
                                 f"{', '.join(NAMES)})")
            values = [float(named[k]) for k in NAMES]
        else:
            tokens = [t for t in re.split(r"[\s,;]+", text.strip()) if t]
            values = [float(t) for t in tokens]
            if len(values) != len(NAMES):
                raise InputError(f"{path}: {len(values)} numbers; C3VD's camera intrinsics are {len(NAMES)}: "
                                 f"{', '.join(NAMES)} (or lines 'name value')")
    except ValueError as exc:
        raise InputError(f"{path}: not the camera's intrinsics ({exc}); expected {len(NAMES)} numbers "
                         f"{', '.join(NAMES)} or lines 'name value'") from None
    if not all(np.isfinite(values)) or values[0] < 2 or values[1] < 2 or values[0] != int(values[0]) \
            or values[1] != int(values[1]) or values[4] <= 0:
        raise InputError(f"{path}: not usable intrinsics (width and height whole numbers of pixels, a0 > 0, all "
                         f"finite): {dict(zip(NAMES, values))}")
    intr = Fisheye(int(values[0]), int(values[1]), *values[2:])
    if abs(np.linalg.det(intr.stretch)) < 1e-6:
        raise InputError(f"{path}: the stretch matrix [[c, e], [d, 1]] is singular")
    return intr
