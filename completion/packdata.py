"""Training batches from a pack (:mod:`colonbench.shards.pack`): heatmaps made on the training device.

A pack holds per sample the occupancy grids of the partial surface, the
complete surface and the centerline. A batch is unpacked on the device, its
three exact Euclidean distance transforms are taken there, and the input and
target heatmaps follow from :func:`colonbench.heatmaps.input_heatmap` and
:func:`colonbench.heatmaps.target_heatmap`, the formulas data generation uses.

Distance transform
------------------
On a CUDA device the squared distance is computed separably and exactly,
``d^2(x, y, z) = min_x' [(x - x')^2 + min_y' [(y - y')^2 + min_z' [(z - z')^2 + F]]]``
with ``F`` 0 on occupied voxels and infinite elsewhere, one brute-force
min-plus product per axis (``S^4`` operations per axis and grid: trivial
work for a GPU, and all integers in float32, so exact). On the CPU the
``edt`` package does the same job faster. Both equal
:func:`colonbench.heatmaps.distance_to` (a test checks it).

Augmentation
------------
Flipping a grid axis maps the occupancies, and with them both heatmaps, onto
another valid sample (the grid's principal axes have no preferred sign), so
flips are exact augmentations. So are transposes, which exchange grid axes
(``colonbench train --transposes P``; with the flips, every symmetry of the
cube): the grid is cubic and its voxels isotropic, so a distance transform of
transposed occupancies is the transposed distance transform. These are the
only geometric augmentations a pack allows. Transposes answer a bias of the
networks trained without them: the grid's first axis is always the tube's
(:func:`colonbench.grid.tube_axes`), and they learn to draw the tube along it
whatever the cloud says; where a bent segment's tube runs along another axis
they draw it across the colon (docs/training.md).

Erasing (``colonbench train --erase P``) takes 1-3 ball-shaped patches out of a
share of the samples' partial surfaces before their input heatmaps are made
(:func:`erase_patches`): the same colon with larger or more holes. The target
does not depend on the partial surface, so it stays exact. It trains the
completion of the large unobserved areas that camera holes leave on real
colons, where the network's surface fades (docs/training.md).
"""

from __future__ import annotations

import os

import numpy as np
import torch

from colonbench import seeding
from colonbench.errors import InputError
from colonbench.heatmaps import heatmaps_from_occupancy, input_heatmap
from colonbench.shards.pack import GRIDS, SLAB, is_pack, read_pack, read_shard_bits

#: Elements of the broadcast (n, S, S, S, S) tensor of one min-plus step, at most.
_CHUNK_ELEMENTS = 1 << 28


def _min_plus_last(f: torch.Tensor, sq: torch.Tensor) -> torch.Tensor:
    """``out[..., i] = min_j f[..., j] + sq[i, j]`` over the last axis, in chunks of the first."""
    per_item = f[0].numel() * f.shape[-1]
    step = max(1, _CHUNK_ELEMENTS // per_item)
    return torch.cat([torch.amin(f[a:a + step].unsqueeze(-2) + sq, dim=-1) for a in range(0, len(f), step)])


def distance_to(occupied: torch.Tensor, method: str = "auto") -> torch.Tensor:
    """Exact Euclidean distance (voxels) from every voxel to the nearest occupied voxel of the same grid.

    Parameters
    ----------
    occupied : (n, S, S, S) bool tensor
        Each grid must hold an occupied voxel.
    method : {"auto", "edt", "min-plus"}
        ``auto``: the ``edt`` package on the CPU, min-plus products elsewhere.

    Returns
    -------
    (n, S, S, S) float32 tensor
        On the same device; 0 on occupied voxels.
    """
    if method == "auto":
        method = "edt" if occupied.device.type == "cpu" else "min-plus"
    if method == "edt":
        import edt
        return torch.from_numpy(np.stack([edt.edt(np.ascontiguousarray(~g), black_border=False, parallel=1)
                                          for g in occupied.numpy()]).astype(np.float32, copy=False))
    if method != "min-plus":
        raise ValueError(f"unknown distance transform method {method!r}")
    size = occupied.shape[-1]
    r = torch.arange(size, device=occupied.device, dtype=torch.float32)
    sq = (r[:, None] - r[None, :]) ** 2
    f = torch.where(occupied, 0.0, float("inf")).to(torch.float32)
    for _ in range(3):
        # transform the last axis, then rotate the axes so that each one comes last once
        f = _min_plus_last(f, sq).permute(0, 3, 1, 2).contiguous()
    return f.sqrt()


def pooled_distance(occupied: torch.Tensor, pool: int = 1) -> torch.Tensor:
    """:func:`distance_to` of grids pooled ``pool`` times (:func:`pooled`), counted in the pack's own voxels (the
    distance in mm over the pack's voxel size, as the full grid's heatmaps count it); (n, S, S, S) float32."""
    d = distance_to(occupied)
    return d * pool if pool > 1 else d


def heatmaps(s0: torch.Tensor, s1: torch.Tensor, c: torch.Tensor, pool: int = 1) -> tuple[torch.Tensor, torch.Tensor]:
    """Input and target heatmaps, (n, S, S, S) float32, from the partial-surface, surface and centerline grids;
    ``pool``: grids pooled that many times (:func:`pooled`), their distances counted in the pack's own voxels."""
    return heatmaps_from_occupancy(s0, s1, c, distance=lambda occ: pooled_distance(occ, pool))


def pooled(occupied: torch.Tensor, pool: int) -> torch.Tensor:
    """(n, S / pool, S / pool, S / pool) occupancy of (n, S, S, S) ones: a coarse voxel is occupied where any of its
    ``pool^3`` fine voxels is (the screening set-up of decision record 0326)."""
    if pool == 1:
        return occupied
    n, s = occupied.shape[0], occupied.shape[-1] // pool
    return occupied.reshape(n, s, pool, s, pool, s, pool).any(dim=6).any(dim=4).any(dim=2)


def flips(seed: int, epoch: int, index: int) -> tuple[int, ...]:
    """The grid axes (of 0, 1, 2) flipped for sample ``index`` in ``epoch``: each with probability 1/2.

    Drawn from stream ``("flip", epoch, index)`` under ``seed``, so a resumed
    run and every worker draw the same ones.
    """
    draw = seeding.rng(seed, "flip", epoch, index).random(3) < 0.5
    return tuple(int(a) for a in np.flatnonzero(draw))


#: The orders of the grid axes a transposed sample takes (every one but the identity), in a fixed order.
TRANSPOSES = ((0, 2, 1), (1, 0, 2), (1, 2, 0), (2, 0, 1), (2, 1, 0))


def transpose(seed: int, epoch: int, index: int, share: float) -> tuple[int, ...]:
    """The order of the grid axes for sample ``index`` in ``epoch``: ``(0, 1, 2)`` (left as it is) with probability
    ``1 - share``, else one of :data:`TRANSPOSES`, each as likely.

    Drawn from stream ``("transpose", epoch, index)`` under ``seed``, so a resumed run and every worker draw the
    same ones.
    """
    if share <= 0:
        return (0, 1, 2)
    rng = seeding.rng(seed, "transpose", epoch, index)
    return TRANSPOSES[int(rng.integers(len(TRANSPOSES)))] if rng.random() < share else (0, 1, 2)


#: Patches erased from a sample (count drawn uniformly between the two, inclusive).
ERASE_PATCHES = (1, 3)
#: Radius of an erased patch, voxels (uniform); at 1.1-1.6 mm voxels 5-25 mm, as large as the camera
#: holes of real colons.
ERASE_RADIUS = (4.0, 16.0)
#: Share of the partial surface's voxels an erased sample keeps at least (patches past it are left out).
ERASE_KEEP = 0.4


def erasure(seed: int, epoch: int, index: int, share: float) -> np.random.Generator | None:
    """The generator that erases patches of sample ``index`` in ``epoch``, or None (probability ``1 - share``).

    Drawn from stream ``("erase", epoch, index)`` under ``seed``, so a resumed
    run draws the same patches.
    """
    if share <= 0:
        return None
    rng = seeding.rng(seed, "erase", epoch, index)
    return rng if rng.random() < share else None


def erase_patches(s0: torch.Tensor, rng: np.random.Generator, patches: tuple = ERASE_PATCHES,
                  radius: tuple = ERASE_RADIUS, keep: float = ERASE_KEEP) -> torch.Tensor:
    """A copy of a partial-surface occupancy with ball-shaped patches taken out.

    Parameters
    ----------
    s0 : (S, S, S) bool tensor
        Voxels holding a partial point.
    rng : numpy Generator
        Draws the patch count, centres (occupied voxels, so that every patch
        removes surface) and radii.
    patches : (int, int)
        Fewest and most patches.
    radius : (float, float)
        Range of the patch radius, voxels.
    keep : float
        A patch that would leave fewer than this share of the occupied
        voxels is not taken out.

    Returns
    -------
    (S, S, S) bool tensor on ``s0``'s device.
    """
    occupied = torch.nonzero(s0).cpu().numpy()
    if len(occupied) == 0:
        return s0.clone()
    out = s0.clone()
    size = s0.shape[0]
    axis = torch.arange(size, device=s0.device, dtype=torch.float32)
    floor = keep * len(occupied)
    for _ in range(int(rng.integers(patches[0], patches[1] + 1))):
        c = occupied[rng.integers(len(occupied))].astype(np.float32)
        r = float(rng.uniform(*radius))
        d2 = ((axis - float(c[0])) ** 2)[:, None, None] + ((axis - float(c[1])) ** 2)[None, :, None] \
            + ((axis - float(c[2])) ** 2)[None, None, :]
        trial = out & (d2 > r * r)
        if int(trial.sum()) >= floor:
            out = trial
    return out


def apply_flips(x: torch.Tensor, y: torch.Tensor, axes: list) -> tuple[torch.Tensor, torch.Tensor]:
    """Flip the grid axes ``axes[k]`` of item ``k`` of (n, C, S, S, S) input and target batches."""
    if not any(axes):
        return x, y
    x, y = x.clone(), y.clone()
    for k, ax in enumerate(axes):
        if ax:
            dims = [a + 1 for a in ax]
            x[k] = torch.flip(x[k], dims)
            y[k] = torch.flip(y[k], dims)
    return x, y


def apply_transposes(x: torch.Tensor, y: torch.Tensor, orders: list) -> tuple[torch.Tensor, torch.Tensor]:
    """Reorder the grid axes of item ``k`` of (n, C, S, S, S) input and target batches as ``orders[k]``.

    ``orders[k]`` is a permutation of (0, 1, 2) (:func:`transpose`): new axis ``a`` is old axis ``orders[k][a]``.
    """
    if all(tuple(o) == (0, 1, 2) for o in orders):
        return x, y
    x, y = x.clone(), y.clone()
    for k, order in enumerate(orders):
        if tuple(order) != (0, 1, 2):
            dims = (0, *(a + 1 for a in order))
            x[k] = x[k].permute(dims).contiguous()
            y[k] = y[k].permute(dims).contiguous()
    return x, y


class PackSplit:
    """One split of a pack, or of a format-2 dataset's shards, held packed on the training device.

    Parameters
    ----------
    pack_dir : path or list of paths
        Packs or format-2 dataset folders (:func:`colonbench.shards.pack.read_shard_bits`); several (the
        same grid) are one split, in the order given.
    split : str
    device : torch.device
    cache : bool, optional
        Make every sample's heatmaps once and keep them on the device
        (2 MiB per sample at S = 64): flips act on finished heatmaps, so
        they need not be made again each epoch. Default: on a CUDA device
        when they take under half of its free memory.

    Attributes
    ----------
    info : dict
        The (first) pack's ``pack.json``.
    size : int
        Grid side S.
    sizes : list of int
        Samples of each pack, in the order given.
    """

    def __init__(self, pack_dir, split: str, device, cache: bool | None = None, pool: int = 1):
        dirs = [pack_dir] if isinstance(pack_dir, (str, os.PathLike)) else list(pack_dir)
        read = [read_pack(d, split) if is_pack(d) else read_shard_bits(d, split) for d in dirs]
        self.info = read[0][0]
        other = [str(d) for d, (info, _) in zip(dirs, read) if info["grid_options"] != self.info["grid_options"]]
        if other:
            raise InputError(f"{other[0]} has another grid than {dirs[0]}; packs trained together need the same grid")
        with_slab = [SLAB in bits for _, bits in read]
        if any(with_slab) and not all(with_slab):
            raise InputError(f"{dirs[with_slab.index(False)]} is a segment pack and {dirs[with_slab.index(True)]} a "
                             "context pack; an in-context model trains on context packs only")
        self.grid_names = GRIDS + ((SLAB,) if all(with_slab) else ())
        self.in_channels = 2 if all(with_slab) else 1
        self.pool, self.stored = int(pool), int(self.info["grid_options"]["size"])
        if self.pool < 1 or self.stored % self.pool:
            raise InputError(f"pool {pool}: the pack's grid of {self.stored} voxels must split into whole blocks")
        self.size = self.stored // self.pool
        if self.pool > 1 and self.in_channels > 1:
            raise InputError("pool: the screening set-up pools segment packs; an in-context model trains on the full "
                             "grid")
        self.sizes = [len(bits[GRIDS[0]]) for _, bits in read]
        self.device = torch.device(device)
        self.bits = torch.from_numpy(np.concatenate([np.stack([bits[g] for g in self.grid_names], axis=1)
                                                     for _, bits in read])).to(self.device)
        self._shifts = torch.arange(7, -1, -1, dtype=torch.uint8, device=self.device)
        self._cache = None
        if cache is None:               # on a GPU where they fit, and always for pooled (screening) grids
            need = len(self.bits) * 2 * 4 * self.size ** 3
            cache = (self.device.type == "cuda" and need < 0.5 * torch.cuda.mem_get_info(self.device)[0]) or (
                self.pool > 1 and need < 2 ** 31)
        if cache:
            parts = [self._make(np.arange(a, min(a + 64, len(self)))) for a in range(0, len(self), 64)]
            self._cache = (torch.cat([p[0] for p in parts]), torch.cat([p[1] for p in parts]))

    def __len__(self) -> int:
        return len(self.bits)

    def grids(self, indices) -> torch.Tensor:
        """(n, G, S, S, S) bool occupancies (``s0``, ``s1``, ``c``, and ``slab`` in a context pack) of samples
        ``indices``, on the device."""
        rows = self.bits[torch.as_tensor(np.asarray(indices, dtype=np.int64), device=self.device)]
        grids = ((rows.unsqueeze(-1) >> self._shifts) & 1).bool().reshape(len(rows) * len(self.grid_names),
                                                                           *(self.stored,) * 3)
        return pooled(grids, self.pool).reshape(len(rows), len(self.grid_names), *(self.size,) * 3)

    def _make(self, indices) -> tuple[torch.Tensor, torch.Tensor]:
        grids = self.grids(indices)
        h_in, h_t = heatmaps(grids[:, 0], grids[:, 1], grids[:, 2], self.pool)
        x = h_in.unsqueeze(1)
        if self.in_channels == 2:  # the in-context model's second channel: the segment's slab (colonbench.slab)
            x = torch.cat([x, grids[:, 3:4].float()], dim=1)
        return x, h_t.unsqueeze(1)

    def batch(self, indices, erase=None) -> tuple[torch.Tensor, torch.Tensor]:
        """(input, target) of samples ``indices``: (n, C, S, S, S) and (n, 1, S, S, S) float32 on the device
        (C = :attr:`in_channels`: the input heatmap, and the slab in a context pack).

        ``erase``: per sample None or a generator (:func:`erasure`); those
        samples' input heatmaps are made from their partial surface with
        patches taken out (:func:`erase_patches`).
        """
        if self._cache is None:
            x, y = self._make(indices)
        else:
            at = torch.as_tensor(np.asarray(indices, dtype=np.int64), device=self.device)
            x, y = self._cache[0][at], self._cache[1][at]
        todo = [k for k, rng in enumerate(erase or []) if rng is not None]
        if todo:
            s0 = self.grids([indices[k] for k in todo])[:, 0]
            radius = tuple(r / self.pool for r in ERASE_RADIUS)     # the same balls in mm on a pooled grid
            cut = torch.stack([erase_patches(s0[j], erase[k], radius=radius) for j, k in enumerate(todo)])
            x = x.clone()
            x[todo, :1] = input_heatmap(pooled_distance(cut, self.pool)).unsqueeze(1)
        return x, y


class PackBatches(torch.utils.data.Dataset):
    """The training batches of one epoch of a pack split: item ``k`` is the ``k``-th batch, its samples and
    their erased patches (:func:`erasure`).

    Training takes the items in order, in its own process on a GPU (the
    heatmaps are made on the device), and on the CPU in DataLoader worker
    processes (``colonbench train --workers N``): there a batch's distance
    transforms (``edt``, about 30 ms per sample on this project's CPU) take
    as long as the small network's training step, and made in a worker they
    overlap with it. The batches are the same either way.

    Parameters
    ----------
    split : PackSplit
    samples : (m,) int array
        The epoch's samples (pack indices), in training order.
    slots : (m,) int array
        Their slots in the epoch (what :func:`erasure` draws from).
    batch_size : int
    seed, epoch : int
    erase : float
        Share of samples with erased patches (:func:`erasure`).
    """

    def __init__(self, split: PackSplit, samples, slots, batch_size: int, seed: int, epoch: int, erase: float):
        self.split, self.samples, self.slots = split, np.asarray(samples), np.asarray(slots)
        self.batch_size, self.seed, self.epoch, self.erase = batch_size, seed, epoch, erase

    def __len__(self) -> int:
        return -(-len(self.samples) // self.batch_size)

    def __getitem__(self, k: int) -> tuple[torch.Tensor, torch.Tensor]:
        at = slice(k * self.batch_size, (k + 1) * self.batch_size)
        return self.split.batch(self.samples[at], [erasure(self.seed, self.epoch, int(i), self.erase)
                                                   for i in self.slots[at]])

