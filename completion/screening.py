"""The screening set-up: a network trained and run on the grid pooled, inside the full grid (decision record 0326).

``colonbench train --pool P`` trains on a pack's occupancy grids pooled ``P`` times (a coarse voxel is occupied where
any of its ``P^3`` fine ones is, :func:`colonbench.completion.packdata.pooled`), their heatmaps made with distances in
the pack's own voxels, so that a pooled heatmap is the full one's in millimetres, sampled coarsely. At inference a
pooled model sees the cloud's input heatmap made the same way on the full grid's geometry, and its prediction is
interpolated back onto the full grid (trilinear, voxel centres aligned), where every step after the network runs
as for a full model. It is several times faster to train; it is for ranking recipes, not for shipping.
"""

from __future__ import annotations

import numpy as np

from colonbench.grid import Grid
from colonbench.heatmaps import input_heatmap, voxelize_points


def pool_of(meta: dict) -> int:
    """How many times a model's training pooled the grid (its ``train_config``'s ``pool``; 1 for a full model)."""
    return int((meta.get("train_config") or {}).get("pool", 1) or 1)


def pooled_input(grid: Grid, points: np.ndarray, pool: int) -> np.ndarray:
    """(S / pool,)^3 float32 input heatmap of a cloud (mm) on ``grid`` pooled ``pool`` times, distances in the full
    grid's voxels: made by the functions :class:`colonbench.completion.packdata.PackSplit` trains with."""
    import torch

    from colonbench.completion.packdata import pooled, pooled_distance

    occ, _ = voxelize_points(grid, points)
    coarse = pooled(torch.from_numpy(occ)[None], pool)
    return input_heatmap(pooled_distance(coarse, pool))[0].numpy().astype(np.float32, copy=False)


def upsampled(pred, pool: int, size: int):
    """A pooled prediction, (1, 1, s, s, s) torch tensor, interpolated onto the full grid's ``size^3`` voxels."""
    import torch

    if pool == 1:
        return pred
    return torch.nn.functional.interpolate(pred.float(), size=(size,) * 3, mode="trilinear", align_corners=False)
