"""MONAI's residual 3D UNet in plain PyTorch, for inference: the same layers, parameter names and outputs.

``colonbench estimate`` spent 6.7 s of its start-up importing MONAI (its
package init loads every submodule) for one class. This module rebuilds
``monai.networks.nets.UNet(spatial_dims=3, ..., act="PRELU", adn_ordering="NDA")``
(MONAI 1.x) from ``torch.nn`` alone, with the same module tree, so a state
dict saved from MONAI's network loads into it unchanged and computes the same
outputs (``tests/test_unet.py`` checks it on random inputs and
weights). Training keeps MONAI's class (:func:`colonbench.completion.network.build_network`);
inference (:func:`colonbench.completion.network.load_model`) builds this one.

The tree, for channels (c0, c1, ..., cn) and strides (s0, ...)::

    model = Sequential(down(in, c0, s0), SkipConnection(inner), up(2 c0 or c0 + c1, out, s0, top=True))

with ``down`` a residual unit (``num_res_units`` convolutions, each Conv3d + BatchNorm + Dropout + PReLU,
plus a strided residual projection), ``up`` a transposed convolution followed by a one-convolution residual
unit, and the bottom a residual unit at stride 1; the skip connection concatenates along channels.
"""

from __future__ import annotations

import torch
from torch import nn


def _norm(name: str, channels: int) -> nn.Module:
    if name == "batch":
        return nn.BatchNorm3d(channels)
    if name == "instance":
        return nn.InstanceNorm3d(channels)
    raise ValueError(f"normalisation {name!r} is not one this UNet rebuilds (batch, instance)")


class Convolution(nn.Sequential):
    """``conv`` (Conv3d or ConvTranspose3d, kernel 3) then, unless ``conv_only``, ``adn``: norm, dropout, PReLU."""

    def __init__(self, cin: int, cout: int, stride: int, norm: str, dropout: float, transposed: bool = False,
                 conv_only: bool = False):
        super().__init__()
        if transposed:
            self.add_module("conv", nn.ConvTranspose3d(cin, cout, 3, stride, 1, output_padding=stride - 1))
        else:
            self.add_module("conv", nn.Conv3d(cin, cout, 3, stride, 1))
        if not conv_only:
            self.add_module("adn", nn.Sequential())
            self.adn.add_module("N", _norm(norm, cout))
            self.adn.add_module("D", nn.Dropout(dropout))
            self.adn.add_module("A", nn.PReLU())


class ResidualUnit(nn.Module):
    """``subunits`` convolutions (the first strided) plus a residual: identity, a 1-kernel channel projection, or
    a strided 3-kernel convolution."""

    def __init__(self, cin: int, cout: int, stride: int, subunits: int, norm: str, dropout: float,
                 last_conv_only: bool = False):
        super().__init__()
        self.conv = nn.Sequential()
        channels, s = cin, stride
        subunits = max(1, subunits)
        for k in range(subunits):
            self.conv.add_module(f"unit{k}", Convolution(channels, cout, s, norm, dropout,
                                                         conv_only=last_conv_only and k == subunits - 1))
            channels, s = cout, 1
        if stride != 1:
            self.residual = nn.Conv3d(cin, cout, 3, stride, 1)
        elif cin != cout:
            self.residual = nn.Conv3d(cin, cout, 1, 1, 0)
        else:
            self.residual = nn.Identity()

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        res = self.residual(x)
        return self.conv(x) + res


class SkipConnection(nn.Module):
    """``cat([x, submodule(x)], dim=1)``."""

    def __init__(self, submodule: nn.Module):
        super().__init__()
        self.submodule = submodule

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return torch.cat([x, self.submodule(x)], dim=1)


class UNet(nn.Module):
    """The residual UNet; (B, in_channels, S, S, S) -> (B, out_channels, S, S, S), linear output.

    Parameters
    ----------
    in_channels, out_channels : int
    channels : tuple of int
        Feature channels per level, finest first.
    strides : tuple of int
        One fewer than ``channels``.
    num_res_units : int
        Convolutions per down-path residual unit (at least 1: this class rebuilds the residual UNet only).
    norm : str
        ``batch`` or ``instance``.
    dropout : float
    """

    def __init__(self, in_channels: int, out_channels: int, channels, strides, num_res_units: int = 1,
                 norm: str = "batch", dropout: float = 0.0):
        super().__init__()
        if num_res_units < 1:
            raise ValueError("this UNet rebuilds MONAI's residual UNet (num_res_units >= 1)")
        if len(strides) != len(channels) - 1:
            raise ValueError(f"{len(channels)} levels need {len(channels) - 1} strides, got {len(strides)}")
        self.in_channels = in_channels
        self.units, self.norm, self.dropout = num_res_units, norm, dropout
        self.model = self._block(in_channels, out_channels, tuple(channels), tuple(strides), True)

    def _down(self, cin: int, cout: int, stride: int) -> nn.Module:
        return ResidualUnit(cin, cout, stride, self.units, self.norm, self.dropout)

    def _up(self, cin: int, cout: int, stride: int, top: bool) -> nn.Module:
        return nn.Sequential(Convolution(cin, cout, stride, self.norm, self.dropout, transposed=True),
                             ResidualUnit(cout, cout, 1, 1, self.norm, self.dropout, last_conv_only=top))

    def _block(self, cin: int, cout: int, channels: tuple, strides: tuple, top: bool) -> nn.Module:
        c, s = channels[0], strides[0]
        if len(channels) > 2:
            inner, up_in = self._block(c, c, channels[1:], strides[1:], False), 2 * c
        else:
            inner, up_in = self._down(c, channels[1], 1), c + channels[1]
        return nn.Sequential(self._down(cin, c, s), SkipConnection(inner), self._up(up_in, cout, s, top))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.model(x)
