"""pyrender, set up for headless rendering (EGL) and NumPy 2."""

from __future__ import annotations

import os

import numpy as np


def pyrender():
    """The ``pyrender`` module, imported with ``PYOPENGL_PLATFORM=egl`` unless another platform is set.

    pyrender 0.1.45 uses ``np.infty``, which NumPy 2 removed; it is restored
    as an alias of ``np.inf`` first.
    """
    os.environ.setdefault("PYOPENGL_PLATFORM", "egl")
    if not hasattr(np, "infty"):
        np.infty = np.inf
    import pyrender as module

    return module
