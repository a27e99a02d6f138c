"""Training the completion network: L2 on the paper's heatmaps, resumable, on CPU, one GPU or several.

``colonbench train DATA --out RUN`` reads the shards of a generated dataset
(its ``train`` and ``validation`` splits), applies the augmentations
(:mod:`colonbench.augment`) to a share of the samples, validates after every
epoch and writes into ``RUN``:

``log.csv``
    one row per epoch: epoch, steps, samples seen, train and validation L2,
    learning rate, wall seconds (cumulative over resumed runs);
``last.pt``
    everything needed to resume (weights, optimizer, scheduler, position in the
    epoch, best validation loss), rewritten every ``checkpoint_minutes`` and on
    stopping;
``best.safetensors``
    the weights with the lowest validation loss, with the network
    configuration and a description of the run in the file's metadata
    (:func:`colonbench.completion.network.save_model`);
``epoch-NNN.safetensors``
    with ``keep_epochs``: every epoch's weights, the same metadata, so that a
    checkpoint can be chosen afterwards by the coverage error on the
    validation split (``colonbench evaluate RUN_DATA --split validation
    --model RUN/epoch-NNN.safetensors``) rather than by the L2 alone.

Running the same command again resumes from ``last.pt`` exactly where it
stopped (the epoch's sample order is drawn from the seed, so the remaining
batches are the same ones). ``max_minutes`` stops cleanly after a time budget,
which is how a long CPU training is spread over several sessions; so does
Ctrl-C or SIGTERM in a single-process run (the batch is finished and
``last.pt`` written first).

Several GPUs: launch with ``torchrun --nproc_per_node N -m colonbench.cli
train ...``; each process takes every N-th sample of the epoch's order and
PyTorch's DistributedDataParallel averages the gradients.
"""

from __future__ import annotations

import csv
import os
import signal
import threading
import time
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np
import torch

from colonbench._version import __version__
from colonbench.augment import AugmentConfig
from colonbench.completion.epochs import data_locks, epoch_order, epoch_slots, per_dataset
from colonbench.completion.network import (NETWORKS, build_network, network_config, resolve_device,
                                           save_model)
from colonbench.completion.packdata import PackBatches, apply_flips, apply_transposes, flips, transpose
from colonbench.errors import InputError


#: Arithmetic of the training steps: ``fp32``, or ``bf16`` (the forward pass under
#: ``torch.autocast`` in bfloat16, weights, gradients, loss and validation in float32).
#: bf16 pays where the hardware has it: 2.5x the small network's steps on this project's CPU
#: (AMX; ``python scripts/bench_train.py``), and on an H100's tensor cores; a CPU without
#: bfloat16 instructions emulates it, slower than fp32.
PRECISIONS = ("fp32", "bf16")
#: The hole-weighted loss (``hole_weight``) weighs the voxels on the complete surface (target below
#: :data:`HOLE_TARGET`, within about a voxel of it) where the input holds no partial point within 2 voxels (input
#: heatmap above :data:`HOLE_INPUT`): the missing wall the network is to put back.
HOLE_TARGET = 0.2
HOLE_INPUT = 0.379949      # tanh(0.2 * 2)


@dataclass(frozen=True)
class TrainConfig:
    """Settings of a training run (all recorded in the checkpoint and the model's metadata)."""

    network: str = "small"
    batch_size: int = 4
    lr: float = 1e-3
    weight_decay: float = 0.0
    epochs: int = 100
    augment_prob: float = 0.3
    seed: int = 0
    workers: int = 1
    lr_patience: int = 3
    lr_factor: float = 0.5
    checkpoint_minutes: float = 10.0
    max_minutes: float | None = None
    keep_epochs: bool = False
    augment: dict = field(default_factory=dict)
    flips: bool = False
    transposes: float = 0.0
    erase: float = 0.0
    init: str | None = None
    init_sha256: str | None = None
    repeat: tuple = ()
    precision: str = "fp32"
    hole_weight: float = 0.0
    pool: int = 1

    def check(self):
        if self.network not in NETWORKS:
            raise InputError(f"unknown network {self.network!r}; known: {sorted(NETWORKS)}")
        for name in ("batch_size", "epochs"):
            if getattr(self, name) < 1:
                raise InputError(f"{name} must be >= 1")
        if not 0 <= self.augment_prob <= 1:
            raise InputError("augment_prob must be in [0, 1]")
        if not 0 <= self.erase <= 1:
            raise InputError("erase must be in [0, 1]")
        if not 0 <= self.transposes <= 1:
            raise InputError("transposes must be in [0, 1]")
        if self.lr <= 0:
            raise InputError("lr must be positive")
        if not self.hole_weight >= 0:
            raise InputError("hole_weight must be >= 0")
        if self.pool not in (1, 2, 4):
            raise InputError(f"pool must be 1, 2 or 4 (the pack's grid side divided by it), not {self.pool}")
        if self.seed < 0 or self.workers < 0:
            raise InputError("seed and workers must be >= 0")
        if self.precision not in PRECISIONS:
            raise InputError(f"precision {self.precision!r}; known: {', '.join(PRECISIONS)}")
        if any(not isinstance(r, int) or r < 1 for r in self.repeat):
            raise InputError(f"repeat: whole numbers >= 1, one per dataset, not {list(self.repeat)}")
        from colonbench.datagen.config import from_dict
        from_dict(AugmentConfig, self.augment)
        return self


LOG_FIELDS = ("epoch", "steps", "samples", "train_l2", "val_l2", "lr", "seconds")


def _dist():
    """(rank, world size), initialising torch.distributed when launched by torchrun."""
    world = int(os.environ.get("WORLD_SIZE", "1"))
    if world > 1 and not torch.distributed.is_initialized():
        backend = "nccl" if torch.cuda.is_available() else "gloo"
        torch.distributed.init_process_group(backend)
    rank = torch.distributed.get_rank() if world > 1 else 0
    return rank, world


def memory_format(device: torch.device) -> torch.memory_format:
    """How the network's weights and inputs are laid out in training on ``device``.

    On the CPU channels-last 3D tensors let oneDNN run the 3D convolutions
    without reordering them: about 2x the small network's fp32 steps on this
    project's CPU, the same arithmetic. GPUs keep the default layout.
    """
    return torch.channels_last_3d if device.type == "cpu" else torch.contiguous_format


def train_step(net, opt, x: torch.Tensor, y: torch.Tensor, precision: str = "fp32",
               hole_weight: float = 0.0) -> torch.Tensor:
    """One optimizer step of the L2 loss on a batch; returns the loss (a 0-d tensor).

    Parameters
    ----------
    net : torch.nn.Module
        In training mode, laid out as :func:`memory_format` says.
    opt : torch.optim.Optimizer
    x, y : (B, 1, S, S, S) float32 tensors
        Input and target heatmaps, on the network's device.
    precision : {"fp32", "bf16"}
        :data:`PRECISIONS`: with ``bf16`` the forward pass runs under autocast; the loss is float32.
    hole_weight : float
        Each voxel's squared error counts ``1 + hole_weight`` times where the wall is missing from the input
        (:data:`HOLE_TARGET`, :data:`HOLE_INPUT`); 0: the paper's plain L2.
    """
    opt.zero_grad(set_to_none=True)
    with torch.autocast(x.device.type, dtype=torch.bfloat16, enabled=precision == "bf16"):
        pred = net(x.contiguous(memory_format=memory_format(x.device)))
    err = (pred.float() - y) ** 2
    if hole_weight:
        err = err * (1.0 + hole_weight * ((y < HOLE_TARGET) & (x[:, :1] > HOLE_INPUT)).float())
    loss = torch.mean(err)
    loss.backward()
    opt.step()
    return loss


def _collate(items):
    return (torch.from_numpy(np.stack([it["input"] for it in items])),
            torch.from_numpy(np.stack([it["target"] for it in items])))


def _batch(dataset, indices, device) -> tuple[torch.Tensor, torch.Tensor]:
    """(input, target) (n, 1, S, S, S) on ``device`` of items ``indices`` of shards or a pack split."""
    if hasattr(dataset, "batch"):  # a PackSplit makes its heatmaps on the device
        return dataset.batch(indices)
    x, y = _collate([dataset[int(k)] for k in indices])
    return x.to(device), y.to(device)


def evaluate_l2(net, dataset, device, batch_size: int = 4, rank: int = 0, world: int = 1) -> float:
    """Mean squared error of the network's prediction over a dataset or pack split (all ranks combined)."""
    net.eval()
    total = torch.zeros(2, dtype=torch.float64, device=device)
    idx = np.arange(len(dataset))[rank::world]
    with torch.no_grad():
        for b in range(0, len(idx), batch_size):
            x, y = _batch(dataset, idx[b:b + batch_size], device)
            pred = net(x)
            total[0] += torch.sum((pred - y) ** 2).double()
            total[1] += y.numel()
    if world > 1:
        torch.distributed.all_reduce(total)
    net.train()
    return float(total[0] / total[1])


#: Settings a resumed run may change: how long it runs and how often it saves.
_RUN_LENGTH = ("max_minutes", "epochs", "checkpoint_minutes", "keep_epochs")


def _fixed_settings(train_config: dict) -> dict:
    """The settings a resumed run must share with the stored one (settings added since: their defaults)."""
    full = {**asdict(TrainConfig()), **train_config}
    return {k: v for k, v in full.items() if k not in _RUN_LENGTH}


def _ignore_stop_signals(worker_id: int):
    """DataLoader workers leave Ctrl-C and SIGTERM (sent to the whole process group) to the main process."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_IGN)


def _pack_worker(worker_id: int):
    """A worker making a CPU pack's batches: one thread (its distance transforms are single-threaded), no signals."""
    _ignore_stop_signals(worker_id)
    torch.set_num_threads(1)


def train(data_dir, out_dir, config: TrainConfig | None = None, device: str = "auto", progress: bool = True,
          command: str | None = None) -> dict:
    """Train (or resume training) the completion network on a generated dataset.

    Parameters
    ----------
    data_dir : path or list of paths
        Dataset folder with ``train`` and ``validation`` splits, or a pack of
        one (:mod:`colonbench.shards.pack`). From a pack, and from format-2
        shards without geometric augmentation (``augment_prob`` 0), the
        occupancy grids are read and the heatmaps made on the training device
        (flips, transposes and erasure augment); otherwise the shards' geometry
        is read and augmented on the CPU. Several dataset folders, or
        several packs (same grid), train together: their train splits are one
        training set, their validation splits one validation set; the
        config's ``repeat`` weighs their training samples (:func:`epoch_slots`).
    out_dir : path
        Run folder (log, checkpoints, best model). If it holds ``last.pt`` the
        run resumes; its settings must then match.
    config : TrainConfig
    device : str
        ``auto``, ``cpu``, ``cuda``, ``cuda:1``...
    progress : bool
        Progress bar on a terminal.
    command : str, optional
        The command line, recorded in the model's metadata.

    Returns
    -------
    dict
        ``epochs``, ``steps``, ``best_val_l2``, ``stopped`` ("done" or "time").
    """
    cfg = (config or TrainConfig()).check()
    data_dirs = [Path(d) for d in ([data_dir] if isinstance(data_dir, (str, os.PathLike)) else data_dir)]
    data_dir, out = data_dirs[0], Path(out_dir)
    per_dataset(cfg.repeat, len(data_dirs))  # before any data is read
    lock = data_locks(data_dirs, cfg.repeat)
    data_hash = lock["manifest_sha256"]
    train_coverage = lock["train_coverage_mean"]
    rank, world = _dist()
    dev = resolve_device(device)
    if dev.type == "cuda":
        torch.backends.cudnn.benchmark = True  # fixed input shapes: let cuDNN pick its fastest 3D convolutions
    if dev.type == "cuda" and world > 1:
        dev = torch.device("cuda", int(os.environ.get("LOCAL_RANK", "0")))
        torch.cuda.set_device(dev)
    out.mkdir(parents=True, exist_ok=True)
    # the grids alone, heatmaps made on the device: a pack, or format-2 shards when no geometry is deformed and
    # their grids (96 KiB a sample at S = 64, held packed) take under half the memory available; else streamed
    from colonbench.shards.reader import available_memory_mib

    grids_fit = lock["grid_mib"] < 0.5 * available_memory_mib()
    on_device = lock["pack"] or (lock["occupancies"] and cfg.augment_prob == 0 and grids_fit)
    if on_device:
        if cfg.augment_prob > 0:
            raise InputError(f"{data_dir} is a pack: it holds voxel occupancies, not the geometry the augmentations "
                             "deform, so train on it with --augment-prob 0 (and --flips, --transposes: its exact "
                             "augmentations), "
                             "or on the dataset's shards")
        from colonbench.completion.packdata import PackSplit
        train_ds, val_ds = (PackSplit(data_dirs, s, dev, pool=cfg.pool) for s in ("train", "validation"))
        grid_options = train_ds.info["grid_options"]
        sizes = train_ds.sizes
    else:
        from colonbench.shards.reader import ShardDataset, dataset_files
        aug = AugmentConfig(**{k: tuple(v) if isinstance(v, list) else v for k, v in cfg.augment.items()})
        if cfg.pool > 1:
            raise InputError(f"--pool pools the occupancy grids of a pack (or of format-2 shards held in memory): "
                             f"make a pack of {data_dir} first (colonbench pack) and train on it")
        if cfg.erase > 0:
            raise InputError(("--erase takes patches out of the partial-surface occupancies held in memory, and "
                              f"the grids of {lock['samples']} samples take more than half of it"
                              if cfg.augment_prob == 0 else "--erase takes patches out of the partial-surface "
                              "occupancies: train with --augment-prob 0 on format-2 shards or on a pack "
                              "(colonbench pack)")
                             if lock["occupancies"] else "--erase takes patches out of the partial-surface "
                             f"occupancies, which format-1 shards do not store; make a pack of {data_dir} first "
                             "(colonbench pack) and train on it")
        per_dir = {split: [dataset_files(d, split) for d in data_dirs] for split in ("train", "validation")}
        files = {split: [f for fs in per_dir[split] for f in fs] for split in per_dir}
        train_ds = ShardDataset(files["train"], augment=aug if cfg.augment_prob > 0 else None,
                                seed=cfg.seed, augment_prob=cfg.augment_prob)
        val_ds = ShardDataset(files["validation"])
        ends = np.cumsum([0] + [len(fs) for fs in per_dir["train"]])
        sizes = [int(train_ds.offsets[b] - train_ds.offsets[a]) for a, b in zip(ends[:-1], ends[1:])]
        grid_options = train_ds.shards[0].grid_options
        other = [str(sh.path) for sh in train_ds.shards + val_ds.shards if sh.grid_options != grid_options]
        if other:
            raise InputError(f"{other[0]} has another grid ({len(other)} shard(s)) than {train_ds.shards[0].path}; "
                             "datasets trained together need the same grid")

    slots = epoch_slots(sizes, cfg.repeat)
    torch.manual_seed(cfg.seed)
    # a context pack's samples carry the segment's slab: the in-context model's second input channel
    net_cfg = replace(network_config(cfg.network), in_channels=getattr(train_ds, "in_channels", 1))
    net = build_network(net_cfg).to(dev, memory_format=memory_format(dev))
    if cfg.init is not None and not (out / "last.pt").exists():
        from colonbench.completion.method import model_path
        from colonbench.completion.network import load_model

        from colonbench.completion.network import widen_inputs

        start, start_cfg, _ = load_model(model_path(cfg.init), "cpu")
        if (replace(start_cfg, in_channels=net_cfg.in_channels) != net_cfg
                or start_cfg.in_channels > net_cfg.in_channels):
            raise InputError(f"{cfg.init}: a {start_cfg} network, not the {cfg.network!r} network this run trains")
        weights = start.state_dict()
        if start_cfg.in_channels < net_cfg.in_channels:  # a segment model starts an in-context one
            weights = widen_inputs(weights, net_cfg.in_channels)
        net.load_state_dict(weights)
    opt = torch.optim.Adam(net.parameters(), lr=cfg.lr, weight_decay=cfg.weight_decay)
    sched = torch.optim.lr_scheduler.ReduceLROnPlateau(opt, factor=cfg.lr_factor, patience=cfg.lr_patience)
    state = {"epoch": 0, "position": 0, "steps": 0, "samples": 0, "best_val": float("inf"), "seconds": 0.0,
             "train_sum": 0.0, "train_n": 0}
    ckpt = out / "last.pt"
    settings = {"train_config": asdict(cfg), "data_sha256": data_hash, "world_size": world}
    if ckpt.exists():
        saved = torch.load(ckpt, map_location=dev, weights_only=False)
        if saved["settings"]["data_sha256"] != data_hash:
            raise InputError(f"{out} is a run on other data (dataset manifest differs); use another --out")
        old, new = _fixed_settings(saved["settings"]["train_config"]), _fixed_settings(asdict(cfg))
        if old["init_sha256"] is not None and old["init_sha256"] == new["init_sha256"]:
            new["init"] = old["init"]  # the same starting weights under another name (a shipped model renamed)
        if old != new or saved["settings"]["world_size"] != world:
            raise InputError(f"{out} holds a run with other settings ({old}, {saved['settings']['world_size']} "
                             "process(es)); resume with the same settings or use another --out")
        net.load_state_dict(saved["model"])
        opt.load_state_dict(saved["optimizer"])
        sched.load_state_dict(saved["scheduler"])
        state.update(saved["state"])
    if world > 1:
        net = torch.nn.parallel.DistributedDataParallel(net, device_ids=[dev.index] if dev.type == "cuda" else None)

    def save_checkpoint():
        if rank == 0:
            module = net.module if hasattr(net, "module") else net
            tmp = ckpt.with_name("last.pt.tmp")
            torch.save({"model": module.state_dict(), "optimizer": opt.state_dict(), "scheduler": sched.state_dict(),
                        "state": state, "settings": settings, "version": __version__}, tmp)
            tmp.replace(ckpt)

    log_path = out / "log.csv"
    if rank == 0 and not log_path.exists():
        with open(log_path, "w", newline="") as fh:
            csv.writer(fh).writerow(LOG_FIELDS)

    from colonbench.progress import bar as progress_bar

    # Ctrl-C or SIGTERM: finish the batch, write last.pt, stop (one process only: under DDP the ranks
    # would stop after different batches and hang in the next all-reduce, so torchrun keeps the default)
    stop_signal = []
    previous = {}
    if world == 1 and threading.current_thread() is threading.main_thread():
        for sig in (signal.SIGINT, signal.SIGTERM):
            previous[sig] = signal.signal(sig, lambda signum, frame: stop_signal.append(signum))
    threads = torch.get_num_threads()
    if dev.type == "cpu" and on_device and cfg.workers > 0:
        # the batch workers take a core each; the training step takes the rest (one at least)
        torch.set_num_threads(max(1, min(threads, len(os.sched_getaffinity(0)) - cfg.workers)))
    start = time.perf_counter()
    base_seconds = state["seconds"]
    last_ckpt = start
    stopped = "done"
    loader_kwargs = {"batch_size": cfg.batch_size, "collate_fn": _collate, "num_workers": cfg.workers,
                     "persistent_workers": False, "worker_init_fn": _ignore_stop_signals}
    net.train()
    bs = cfg.batch_size
    while state["epoch"] < cfg.epochs:
        epoch = state["epoch"]
        order = epoch_order(len(slots), cfg.seed, epoch)  # slots; with no --repeat, slot k is sample k
        n_batches = len(order) // (bs * world)
        if n_batches == 0:
            raise InputError(f"{data_dir}: {len(order)} training samples, fewer than one batch of {bs} per process")
        mine = order[: n_batches * bs * world][rank::world]
        todo = mine[state["position"] * bs:]
        if on_device:
            made = PackBatches(train_ds, slots[todo], todo, bs, cfg.seed, epoch, cfg.erase)
            if dev.type == "cpu" and cfg.workers > 0:  # made in worker processes while the step runs
                batches = torch.utils.data.DataLoader(made, batch_size=None, num_workers=cfg.workers,
                                                      worker_init_fn=_pack_worker, persistent_workers=False)
            else:  # on a GPU the heatmaps are made on the device, in this process
                batches = (made[k] for k in range(len(made)))
        else:
            train_ds.set_epoch(epoch)
            batches = torch.utils.data.DataLoader(torch.utils.data.Subset(train_ds, slots[todo].tolist()),
                                                  **loader_kwargs)
        bar = progress_bar(total=n_batches, initial=state["position"], desc=f"epoch {epoch}", unit="batch",
                           enabled=progress and rank == 0)
        for k, (x, y) in enumerate(batches):
            x, y = x.to(dev, non_blocking=True), y.to(dev, non_blocking=True)
            batch_slots = todo[k * bs:(k + 1) * bs]    # the slots of this batch (augmentations are drawn per slot)
            if cfg.transposes > 0:
                x, y = apply_transposes(x, y, [transpose(cfg.seed, epoch, int(i), cfg.transposes) for i in batch_slots])
            if cfg.flips:
                x, y = apply_flips(x, y, [flips(cfg.seed, epoch, int(i)) for i in batch_slots])
            loss = train_step(net, opt, x, y, cfg.precision, cfg.hole_weight)
            state["position"] += 1
            state["steps"] += 1
            state["samples"] += len(x) * world
            state["train_sum"] += float(loss.detach())
            state["train_n"] += 1
            bar.update(1)
            bar.set_postfix(l2=f"{state['train_sum'] / state['train_n']:.5f}")
            now = time.perf_counter()
            state["seconds"] = base_seconds + now - start
            if cfg.max_minutes is not None and now - start > cfg.max_minutes * 60:
                stopped = "time"
                break
            if stop_signal:
                stopped = "signal"
                break
            if now - last_ckpt > cfg.checkpoint_minutes * 60:
                save_checkpoint()
                last_ckpt = now
        bar.close()
        if stopped != "done":
            break
        val = evaluate_l2(net, val_ds, dev, cfg.batch_size, rank, world)
        sched.step(val)
        train_l2 = state["train_sum"] / max(state["train_n"], 1)
        state.update(epoch=epoch + 1, position=0, train_sum=0.0, train_n=0,
                     seconds=base_seconds + time.perf_counter() - start)
        if rank == 0:
            with open(log_path, "a", newline="") as fh:
                csv.writer(fh).writerow([epoch, state["steps"], state["samples"], f"{train_l2:.6f}", f"{val:.6f}",
                                         f"{opt.param_groups[0]['lr']:.3g}", f"{state['seconds']:.1f}"])
            meta = {"data_manifest_sha256": data_hash, "data_dir": "+".join(d.name for d in data_dirs),
                    **({"data_manifests": lock["manifests"]} if len(data_dirs) > 1 else {}),
                    "data_format": "pack" if lock["pack"] else "shards", "train_config": asdict(cfg),
                    "epoch": epoch, "steps": state["steps"], "samples_seen": state["samples"],
                    "val_l2": val, "train_seconds": round(state["seconds"], 1), "device": str(dev),
                    "world_size": world, "torch": torch.__version__, "colonbench": __version__,
                    "grid_options": grid_options, "command": command or "",
                    "train_coverage_mean": train_coverage}
            if cfg.keep_epochs:
                save_model(out / f"epoch-{epoch:03d}.safetensors", net, net_cfg, meta)
            if val < state["best_val"]:
                state["best_val"] = val
                save_model(out / "best.safetensors", net, net_cfg, meta)
        save_checkpoint()
        last_ckpt = time.perf_counter()
    if stopped != "done":
        save_checkpoint()
    for sig, handler in previous.items():
        signal.signal(sig, handler)
    torch.set_num_threads(threads)
    if world > 1:
        torch.distributed.barrier()
        torch.distributed.destroy_process_group()
    return {"epochs": state["epoch"], "steps": state["steps"], "best_val_l2": state["best_val"], "stopped": stopped,
            "seconds": state["seconds"]}
