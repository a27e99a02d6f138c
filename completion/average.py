"""Weight averages of saved models: a "model soup" of checkpoints from one fine-tuning lineage.

``colonbench average MODEL... --out OUT --bn-data PACK...`` averages the
weights of several ``.safetensors`` models of one network (uniformly, Stochastic
Weight Averaging over checkpoints a run already wrote: Izmailov et al. 2018;
Wortsman et al. 2022, "Model soups", for its robustness off the training
distribution) and then recomputes the batch-norm statistics, since the mean of
several models' running statistics is not the statistics of the averaged
network: forward passes in training mode over samples of the training packs,
each layer's running mean and variance the plain mean over those batches
(``momentum=None``, as ``torch.optim.swa_utils.update_bn``). No weight is
trained; the models must share the network and the grid options.

The result is an ordinary model file; its metadata is the last model's, with
the data description (manifests, mean training coverage) of the packs the
statistics were made on, and ``average``: each model's path and sha256, and
how the statistics were made, so a model card can say exactly how it was made
(docs/training.md).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

from colonbench.completion.network import NetworkConfig, build_network, load_model, save_model
from colonbench.errors import InputError
from colonbench.shards.schema import sha256_file

#: Samples and batch size of the batch-norm pass (250 batches of 4, the training batch size).
BN_SAMPLES = 1000
BN_BATCH = 4


def average_states(paths) -> tuple[dict, NetworkConfig, dict]:
    """The uniform mean of several saved models' weights.

    Parameters
    ----------
    paths : list of path
        ``.safetensors`` models (:func:`colonbench.completion.network.save_model`)
        of one network configuration and one set of grid options.

    Returns
    -------
    state : dict
        Floating-point tensors averaged in the order given; integer buffers
        (batch norm's ``num_batches_tracked``) from the last model.
    config : NetworkConfig
    meta : dict
        The last model's metadata.
    """
    paths = [Path(p) for p in paths]
    if len(paths) < 2:
        raise InputError("averaging needs at least two models")
    nets = [load_model(p) for p in paths]  # checks each file, with clear errors
    config, meta = nets[-1][1], nets[-1][2]
    for p, (_, c, m) in zip(paths, nets):
        if c != config:
            raise InputError(f"{p}: a {c} network, {paths[-1]} a {config} one; only one network's models average")
        if m.get("grid_options") != meta.get("grid_options"):
            raise InputError(f"{p}: grid options {m.get('grid_options')}, {paths[-1]} {meta.get('grid_options')}; "
                             "models made for other grids do not average")
    states = [net.state_dict() for net, _, _ in nets]
    w = 1.0 / len(states)
    state = {}
    for key, v in states[-1].items():
        state[key] = sum(w * s[key] for s in states) if v.is_floating_point() else v.clone()
    return state, config, meta


def recompute_batchnorm(net: torch.nn.Module, batches) -> int:
    """Set every batch-norm layer's running statistics to their mean over ``batches`` (in place).

    Parameters
    ----------
    net : torch.nn.Module
    batches : iterable of torch.Tensor
        Network inputs, ``(n, C, S, S, S)``.

    Returns
    -------
    int
        Batches seen. ``net`` is left in eval mode.
    """
    norms = [m for m in net.modules() if isinstance(m, torch.nn.modules.batchnorm._BatchNorm)]
    momenta = [m.momentum for m in norms]
    for m in norms:
        m.reset_running_stats()
        m.momentum = None  # a cumulative mean over the batches
    net.train()
    n = 0
    with torch.no_grad():
        for x in batches:
            net(x)
            n += 1
    for m, mom in zip(norms, momenta):
        m.momentum = mom
    net.eval()
    return n


def pack_batches(packs, repeat=(), samples: int = BN_SAMPLES, seed: int = 0, batch_size: int = BN_BATCH,
                 in_channels: int | None = None):
    """Input batches of training samples drawn from packs, for :func:`recompute_batchnorm`.

    ``samples`` epoch slots (:func:`colonbench.completion.epochs.epoch_slots`,
    each pack's samples ``repeat`` times, as the models were trained) are drawn
    without replacement with ``seed``, in ``batch_size`` batches. ``in_channels``, when given, is the
    network's: segment packs give 1 channel, context packs 2 (the in-context model's).
    """
    from colonbench.completion.packdata import PackSplit
    from colonbench.completion.epochs import epoch_slots, per_dataset

    per_dataset(repeat, len(packs))  # before any pack is read
    split = PackSplit(list(packs), "train", "cpu", cache=False)
    if in_channels is not None and split.in_channels != in_channels:
        kind = {1: "segment", 2: "context"}
        raise InputError(f"{packs[0]}: {kind.get(split.in_channels)} packs, for a network of {split.in_channels} input "
                         f"channel(s); these models take {in_channels} ({kind.get(in_channels)} packs)")
    slots = epoch_slots(split.sizes, tuple(repeat))
    if samples > len(slots):
        raise InputError(f"--bn-samples {samples}: the packs hold {len(slots)} training slots")
    pick = np.random.default_rng(seed).choice(slots, size=samples, replace=False)
    for a in range(0, len(pick), batch_size):
        yield split.batch(pick[a:a + batch_size])[0]


def average_models(paths, out, packs, repeat=(), samples: int = BN_SAMPLES, seed: int = 0,
                   command: str | None = None) -> Path:
    """Average ``paths`` (:func:`average_states`), recompute batch norm on ``packs``, write ``out``.

    The metadata's data description (manifests, the training coverage mean that the constant guess
    uses) becomes that of ``packs`` with ``repeat``, the data the statistics were made on.

    Returns
    -------
    Path
        ``out``, a model file like those ``colonbench train`` writes.
    """
    from colonbench.completion.epochs import data_locks, per_dataset

    per_dataset(repeat, len(packs))  # before any model or pack is read
    state, config, meta = average_states(paths)
    data = data_locks([Path(p) for p in packs], repeat)  # the constant guess's coverage, as training records it
    net = build_network(config)
    net.load_state_dict(state)
    batches = recompute_batchnorm(net, pack_batches(packs, repeat, samples, seed, in_channels=config.in_channels))
    meta = {**meta, "data_manifest_sha256": data["manifest_sha256"], "data_manifests": data["manifests"],
            "train_coverage_mean": data["train_coverage_mean"], "data_format": "pack",
            "data_dir": "+".join(Path(p).name for p in packs)}
    meta["average"] = {"models": [{"path": str(p), "sha256": sha256_file(p)} for p in paths],
                       "batchnorm": {"packs": [str(p) for p in packs], "repeat": list(repeat), "samples": samples,
                                     "seed": seed, "batches": batches}}
    meta["steps"] = f"avg{len(paths)}"
    if command:
        meta["average"]["command"] = command
    return save_model(out, net, config, meta)


def describe_batchnorm(bn: dict) -> str:
    """The samples an averaged model's batch-norm statistics were made on, from its ``average["batchnorm"]``."""
    return (f"{bn['samples']} training samples of {' + '.join(bn['packs'])}"
            + (f" (repeat {','.join(map(str, bn['repeat']))})" if bn["repeat"] else "") + f", seed {bn['seed']}")


def describe(meta: dict) -> str:
    """One line on how an averaged model was made (empty for a trained one)."""
    avg = meta.get("average")
    if not avg:
        return ""
    return (f"the uniform mean of {len(avg['models'])} models ({', '.join(m['path'] for m in avg['models'])}), "
            f"batch norm recomputed on {describe_batchnorm(avg['batchnorm'])}")


