"""The 3D UNet of the paper, its configurations, and saving / loading it.

Training builds MONAI's ``UNet``; inference rebuilds the same network in plain
PyTorch (:mod:`colonbench.completion.unet`: the same weights, the same
outputs), so that ``colonbench estimate`` starts without importing MONAI.
PyTorch and MONAI are optional dependencies of colonbench (``pip install
'colonbench[model]'``): data generation does not need them. Importing this
module without PyTorch raises an ImportError that says how to install it.

A saved model is one ``.safetensors`` file: the weights, plus in its metadata
the network configuration (``colonbench_network``) and what made it
(``colonbench_meta``: data manifest hash, training command, steps, ...), so a
file is enough to rebuild the network.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass
from pathlib import Path

from colonbench.errors import InputError

try:
    import torch
except ImportError as exc:  # pragma: no cover - exercised only without the extra
    raise ImportError("the completion model needs PyTorch: pip install 'colonbench[model]' "
                      f"(CPU: pip install torch==2.13.0 first). Original error: {exc}") from exc


@dataclass(frozen=True)
class NetworkConfig:
    """A MONAI ``UNet(spatial_dims=3, in_channels=..., out_channels=1, ...)``.

    Attributes
    ----------
    in_channels : int
        1: the input heatmap (the paper's network); 2: the input heatmap and the segment's slab, the
        in-context model (:mod:`colonbench.slab`).
    channels : tuple of int
        Feature channels per level, finest first.
    strides : tuple of int
        Down-sampling stride between levels (one fewer than ``channels``).
    num_res_units : int
        Residual units per block (0 = plain convolutions).
    norm : str
        MONAI normalisation name ("batch", "instance").
    dropout : float
    """

    channels: tuple = (16, 32, 64, 128)
    strides: tuple = (2, 2, 2)
    num_res_units: int = 1
    norm: str = "batch"
    dropout: float = 0.0
    in_channels: int = 1

    def to_json(self) -> str:
        d = asdict(self)
        if self.in_channels == 1:  # the paper's network: its files stay as they were
            del d["in_channels"]
        return json.dumps(d)

    @classmethod
    def from_json(cls, text: str) -> "NetworkConfig":
        d = json.loads(text)
        return cls(channels=tuple(d["channels"]), strides=tuple(d["strides"]), num_res_units=int(d["num_res_units"]),
                   norm=str(d["norm"]), dropout=float(d["dropout"]), in_channels=int(d.get("in_channels", 1)))


#: Named configurations: ``small`` trains on a CPU in hours (0.6 M parameters,
#: about 0.04 s per sample per training step (docs/training.md) and 0.09 s per inference on one
#: 2-core CPU); ``large`` is for a GPU (19 M parameters, one more level).
NETWORKS = {
    "small": NetworkConfig(),
    "large": NetworkConfig(channels=(32, 64, 128, 256, 512), strides=(2, 2, 2, 2), num_res_units=2),
}


def network_config(name_or_config) -> NetworkConfig:
    """A :class:`NetworkConfig` from a name in :data:`NETWORKS` or a config."""
    if isinstance(name_or_config, NetworkConfig):
        return name_or_config
    if name_or_config not in NETWORKS:
        raise InputError(f"unknown network {name_or_config!r}; known: {sorted(NETWORKS)}")
    return NETWORKS[name_or_config]


def build_network(config: NetworkConfig, plain: bool = False) -> "torch.nn.Module":
    """The UNet; maps (B, C, S, S, S) inputs (C = ``config.in_channels``) to (B, 1, S, S, S) target heatmaps
    (linear output).

    Parameters
    ----------
    config : NetworkConfig
    plain : bool
        False: MONAI's ``UNet`` (training). True: the same network in plain PyTorch
        (:class:`colonbench.completion.unet.UNet`, inference), which loads the same weights.
    """
    if plain and config.num_res_units >= 1:
        from colonbench.completion.unet import UNet as PlainUNet

        return PlainUNet(config.in_channels, 1, tuple(config.channels), tuple(config.strides), config.num_res_units,
                         config.norm, config.dropout)
    try:
        from monai.networks.nets import UNet
    except ImportError as exc:  # pragma: no cover - exercised only without the extra
        raise ImportError("training the completion model needs MONAI: pip install 'colonbench[model]'. "
                          f"Original error: {exc}") from exc
    return UNet(spatial_dims=3, in_channels=config.in_channels, out_channels=1, channels=tuple(config.channels),
                strides=tuple(config.strides), num_res_units=config.num_res_units, norm=config.norm,
                dropout=config.dropout)


def widen_inputs(state: dict, in_channels: int) -> dict:
    """A 1-input-channel network's weights for ``in_channels`` inputs: the new channels' weights are zero.

    The weights whose input dimension reads the network's input (the first convolution and, with residual
    units, the first block's residual projection: those with 1 input channel) gain zero-filled input
    channels, so the widened network computes exactly what the original did until training moves them.
    An in-context model starts so from a segment model (``colonbench train --init``).
    """
    out = {}
    for key, w in state.items():
        if w.ndim == 5 and w.shape[1] == 1 and key.startswith("model.0."):
            extra = torch.zeros((w.shape[0], in_channels - 1) + tuple(w.shape[2:]), dtype=w.dtype)
            w = torch.cat([w, extra], dim=1)
        out[key] = w
    return out


def save_model(path, net: "torch.nn.Module", config: NetworkConfig, meta: dict | None = None) -> Path:
    """Write weights (float32) and configuration to one ``.safetensors`` file, atomically."""
    from safetensors.torch import save_file

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    module = net.module if hasattr(net, "module") else net
    state = {k: v.detach().to("cpu").contiguous() for k, v in module.state_dict().items()}
    tmp = path.with_name(path.name + ".tmp")
    save_file(state, str(tmp), metadata={"colonbench_network": config.to_json(),
                                         "colonbench_meta": json.dumps(meta or {})})
    tmp.replace(path)
    return path


def load_model(path, device: str = "cpu", plain: bool = True) -> tuple["torch.nn.Module", NetworkConfig, dict]:
    """Rebuild a network saved by :func:`save_model`, in eval mode on ``device``.

    ``plain`` (default): the plain-PyTorch network, for inference; False: MONAI's, for training on.

    Returns
    -------
    net : torch.nn.Module
    config : NetworkConfig
    meta : dict
    """
    from safetensors import safe_open
    from safetensors.torch import load_file

    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: no such model file")
    try:
        with safe_open(str(path), framework="pt") as fh:
            md = fh.metadata() or {}
        state = load_file(str(path), device="cpu")
    except Exception as exc:  # noqa: BLE001 - safetensors raises several types for a bad file
        raise InputError(f"{path}: not a readable safetensors model ({exc})") from None
    if "colonbench_network" not in md:
        raise InputError(f"{path}: not a colonbench model (no network configuration in its metadata)")
    config = NetworkConfig.from_json(md["colonbench_network"])
    net = build_network(config, plain=plain)
    net.load_state_dict(state)
    net.to(device).eval()
    return net, config, json.loads(md.get("colonbench_meta", "{}"))


def for_inference(net: "torch.nn.Module", size: int, device: "torch.device"):
    """``net`` as a callable for (1, C, size, size, size) inputs, made faster for inference where it can be.

    On the CPU the network is traced and passed through
    ``torch.jit.optimize_for_inference``, which folds each batch norm into its
    convolution and runs the convolutions with oneDNN: 0.13 -> 0.09 s per
    64^3 heatmap for the small network on one thread of this project's CPU,
    the output equal to the eager network's to 1e-5. Folding the batch norms alone, eagerly, gains
    nothing: the gain is oneDNN's prepacked convolutions, which PyTorch reaches
    only through TorchScript today. TorchScript is deprecated in favour of
    ``torch.compile``, which needs a C++ compiler at run time; its
    deprecation warnings are silenced here, and where it fails
    (a PyTorch without it or without oneDNN) or on a GPU, this returns the
    eager network in eval mode.
    """
    if device.type != "cpu":
        return net
    import warnings

    try:
        with torch.inference_mode(), warnings.catch_warnings():
            warnings.simplefilter("ignore", DeprecationWarning)
            x = torch.zeros((1, getattr(net, "in_channels", 1)) + (int(size),) * 3, device=device)
            fast = torch.jit.optimize_for_inference(torch.jit.trace(net, x, check_trace=False))
            fast(x)
    except Exception:  # noqa: BLE001 - any failure leaves the eager network, which is always right
        return net
    return fast


def resolve_device(name: str = "auto") -> "torch.device":
    """``auto`` -> CUDA when available, else CPU; otherwise the named device, checked."""
    if name == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    if name.startswith("cuda") and not torch.cuda.is_available():
        raise InputError(f"--device {name}: no CUDA device is available here")
    try:
        return torch.device(name)
    except RuntimeError:
        raise InputError(f"--device {name!r} is not a device PyTorch knows (cpu, cuda, cuda:1, ...)") from None
