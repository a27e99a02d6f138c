"""Test-time symmetry averaging: the network's heatmap averaged over symmetries of the grid that keep its tube axis.

The grid's first axis is the tube's (:func:`colonbench.grid.fit_grid`), and nothing about a colon prefers one
direction across it, nor one end of the tube. The symmetries of the cube that keep the first axis are the
rotations about it by quarter turns, the reversal of the tube (a flip of the first axis) and the mirror images
of those: 16 in all. ``tta=K`` runs the network on the input transformed by the first ``K`` of
:data:`SYMMETRIES`, transforms each prediction back and averages them (K = 1 is the network alone).
"""

from __future__ import annotations

import numpy as np

from colonbench.errors import InputError

#: (quarter turns about the first axis, reverse the tube, mirror across the second axis), in the order
#: ``tta=K`` takes them: K = 2 adds the half turn, K = 4 the quarter turns, K = 8 the reversed tube, K = 16
#: the mirror images.
SYMMETRIES = [(r, f, m) for m in (0, 1) for f in (0, 1) for r in (0, 2, 1, 3)]
#: The K accepted.
TTA_CHOICES = (1, 2, 4, 8, 16)


def check_tta(k) -> int:
    """``k`` as one of :data:`TTA_CHOICES`, or an :class:`~colonbench.errors.InputError` saying which are.

    Parameters
    ----------
    k : int
        A whole number (an integral float is taken; a bool, a fraction or text is not).

    Returns
    -------
    int
    """
    ok = not isinstance(k, bool) and isinstance(k, (int, float, np.integer, np.floating)) and float(k) in TTA_CHOICES
    if not ok:
        raise InputError(f"tta must be one of {', '.join(map(str, TTA_CHOICES))} (symmetries averaged over), "
                         f"got {k!r}")
    return int(k)


def transform(x, symmetry, inverse: bool = False):
    """A batch of grids moved by one of :data:`SYMMETRIES`, or moved back.

    Parameters
    ----------
    x : (N, C, S, S, S) torch.Tensor
        Dimension 2 is the grid's first axis (the tube's), 3 and 4 the axes across it.
    symmetry : tuple of int
        ``(quarter turns about dimension 2, reverse dimension 2, mirror dimension 3)``.
    inverse : bool
        Undo the symmetry instead.

    Returns
    -------
    (N, C, S, S, S) torch.Tensor
    """
    import torch

    turns, reverse, mirror = symmetry
    steps = []
    if mirror:
        steps.append(lambda t: torch.flip(t, dims=(3,)))
    if reverse:
        steps.append(lambda t: torch.flip(t, dims=(2,)))
    if turns:
        steps.append(lambda t, r=turns: torch.rot90(t, -r if inverse else r, dims=(3, 4)))
    for step in (reversed(steps) if inverse else steps):
        x = step(x)
    return x


def averaged(forward, x, k: int):
    """The mean of a network over the first ``k`` of :data:`SYMMETRIES`, each output moved back.

    Parameters
    ----------
    forward : callable
        ``(N, C, S, S, S) -> (N, C', S, S, S)`` tensors.
    x : (N, C, S, S, S) torch.Tensor
    k : int
        One of :data:`TTA_CHOICES`; 1 calls ``forward`` once.

    Returns
    -------
    (N, C', S, S, S) torch.Tensor
    """
    if k == 1:
        return forward(x)
    total = None
    for sym in SYMMETRIES[:k]:
        y = transform(forward(transform(x, sym).contiguous()), sym, inverse=True)
        total = y if total is None else total + y
    return total / k
