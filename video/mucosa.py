"""Colour frames of a colonoscopy: a procedural mucosa texture, lit by the scope's own light (pyrender, headless).

Texture
-------
Per-vertex colours from random Fourier fields of the 3D position (no UV map is
needed, and any mesh, procedural or imported, gets one):

- a pink base (linear RGB 0.86, 0.36, 0.32) that varies slowly (30 mm fields);
- vessels: the zero lines of a 12 mm field, drawn dark red, and fainter
  capillaries along the zero lines of a 4 mm field;
- a specular sheen from the material (metallic 0, roughness 0.35): the wet
  mucosa reflects the tip light in highlights.

Light
-----
A point light at the camera centre (the colonoscope's light guide), falling off
with the square of the distance, and a faint ambient term: near walls are bright,
the lumen far ahead is dark, as in real frames.
"""

from __future__ import annotations

import numpy as np

from colonbench import seeding

#: Linear RGB of the mucosa, of vessels and of capillaries.
BASE_RGB = (0.86, 0.36, 0.32)
VESSEL_RGB = (0.45, 0.05, 0.07)
CAPILLARY_RGB = (0.66, 0.16, 0.16)
#: Automatic exposure: the tip light's intensity is this times the frame's median depth squared (mm^2).
EXPOSURE = 8.0


def _field(rng, points, wavelength_mm: float, n: int = 16) -> np.ndarray:
    """A random Fourier field of unit variance with the given mean wavelength; (k,) float."""
    k = rng.normal(size=(n, 3))
    k /= np.linalg.norm(k, axis=1, keepdims=True)
    k *= (2 * np.pi / wavelength_mm) * rng.uniform(0.7, 1.3, n)[:, None]
    phase = rng.uniform(0, 2 * np.pi, n)
    return np.sqrt(2.0 / n) * np.cos(points @ k.T + phase).sum(axis=1)


def mucosa_colours(vertices, seed: int = 0) -> np.ndarray:
    """Per-vertex colours of the mucosa texture (see the module's description).

    Parameters
    ----------
    vertices : (n, 3) float, mm
    seed : int
        The texture draws from ``seeding.rng(seed, "video", "mucosa")``.

    Returns
    -------
    (n, 3) float
        Linear RGB in [0, 1].
    """
    rng = seeding.rng(seed, "video", "mucosa")
    p = np.asarray(vertices, float)
    base = np.asarray(BASE_RGB) * (1.0 + 0.08 * _field(rng, p, 30.0))[:, None]
    vessel = np.exp(-(_field(rng, p, 12.0) / 0.10) ** 2)[:, None]
    capillary = np.exp(-(_field(rng, p, 4.0) / 0.08) ** 2)[:, None]
    rgb = base * (1 - 0.6 * vessel) + 0.6 * vessel * np.asarray(VESSEL_RGB)
    rgb = rgb * (1 - 0.3 * capillary) + 0.3 * capillary * np.asarray(CAPILLARY_RGB)
    return np.clip(rgb, 0.0, 1.0)


class ColourRenderer:
    """Renders colour frames of a textured mesh with a light at the camera (pyrender, EGL).

    One renderer (one GL context) serves a whole run; :meth:`set_mesh` swaps
    the mesh it shows.

    Parameters
    ----------
    intrinsics : Intrinsics
    light_intensity : float
        Of the point light at the camera, pyrender units (mm^2 per unit radiance).
    far_mm : float
        Far clipping distance, mm.
    """

    def __init__(self, intrinsics, light_intensity: float = 900.0, far_mm: float = 1000.0):
        from colonbench.offscreen import pyrender as _load

        self._pyrender = pyrender = _load()
        self.intrinsics = intrinsics
        self.scene = pyrender.Scene(ambient_light=np.full(3, 0.03), bg_color=[0.0, 0.0, 0.0, 1.0])
        # pyrender's pixel centres sit at half-integers: shift the OpenCV principal point by half a pixel
        camera = pyrender.IntrinsicsCamera(intrinsics.fx, intrinsics.fy, intrinsics.cx + 0.5, intrinsics.cy + 0.5,
                                           znear=0.5, zfar=far_mm)
        self._camera = self.scene.add(camera)
        self._light = self.scene.add(pyrender.PointLight(color=np.ones(3), intensity=light_intensity))
        self._mesh = None
        self._renderer = pyrender.OffscreenRenderer(intrinsics.width, intrinsics.height)
        self._flags = pyrender.RenderFlags.SKIP_CULL_FACES

    def set_mesh(self, vertices, faces, colours, inward=None) -> None:
        """Show this mesh (replacing the last one).

        Parameters
        ----------
        vertices : (n, 3) float, mm
        faces : (m, 3) int
        colours : (n, 3) float
            Linear RGB per vertex (:func:`mucosa_colours`).
        inward : (n, 3) float, optional
            Vertex normals pointing into the lumen (default: the negated normals
            of the mesh, whose normals point out of the lumen).
        """
        import trimesh

        pyrender = self._pyrender
        vertices = np.asarray(vertices, np.float32)
        faces = np.asarray(faces, np.int64)
        if inward is None:
            inward = -trimesh.Trimesh(vertices, faces, process=False).vertex_normals
        material = pyrender.MetallicRoughnessMaterial(baseColorFactor=[1.0, 1.0, 1.0, 1.0], metallicFactor=0.0,
                                                      roughnessFactor=0.35, doubleSided=True)
        rgba = np.concatenate([np.asarray(colours, np.float32), np.ones((len(vertices), 1), np.float32)], axis=1)
        primitive = pyrender.Primitive(positions=vertices, normals=np.asarray(inward, np.float32), color_0=rgba,
                                       indices=faces, material=material, mode=pyrender.constants.GLTF.TRIANGLES)
        if self._mesh is not None:
            self.scene.remove_node(self._mesh)
        self._mesh = self.scene.add(pyrender.Mesh([primitive]))

    def render(self, pose, depth=None) -> np.ndarray:
        """The colour frame at a camera-to-world pose (OpenCV axes); (height, width, 3) uint8.

        With the frame's ``depth`` (mm, 0 where none) the light is set as a
        colonoscope's automatic exposure would: to the square of the median
        depth (mm^2) times :data:`EXPOSURE`, so that the median pixel is lit alike near a wall and in
        a wide lumen.
        """
        gl = np.asarray(pose, float) @ np.diag([1.0, -1.0, -1.0, 1.0])  # OpenCV -> OpenGL camera axes
        self.scene.set_pose(self._camera, gl)
        self.scene.set_pose(self._light, gl)
        if depth is not None:
            valid = np.asarray(depth)[np.asarray(depth) > 0]
            if len(valid):
                self._light.light.intensity = EXPOSURE * float(max(np.median(valid), 3.0) ** 2)
        colour, _ = self._renderer.render(self.scene, flags=self._flags)
        return np.asarray(colour)[..., :3].copy()

    def close(self) -> None:
        """Free the GL context."""
        self._renderer.delete()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
