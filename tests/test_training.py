"""Training the completion network: save, load, fine-tune, resume, several datasets, processes, signals."""


import numpy as np
import pytest

pytest.importorskip("torch")
pytest.importorskip("monai")

from colonbench.completion.heatmap_centerline import extract_centerline  # noqa: E402
from colonbench.completion.method import CompletionMethod, check_cloud  # noqa: E402
from colonbench.completion.network import build_network, load_model, network_config, save_model  # noqa: E402
from colonbench.completion.train import TrainConfig, train  # noqa: E402
from colonbench.errors import InputError  # noqa: E402
from colonbench.shards.reader import ShardDataset  # noqa: E402
from shapes import distance_to_polyline

R = 20.0


def torch_equal(a, b):
    import torch

    return torch.equal(a, b)


def test_train_save_load_predict_round_trip(tiny_run):
    out, run, cfg, result = tiny_run
    assert result["epochs"] == 1 and result["steps"] == 2
    log = (run / "log.csv").read_text().splitlines()
    assert log[0].startswith("epoch,steps") and len(log) == 2
    net, config, meta = load_model(run / "best.safetensors")
    assert config == network_config("small") and meta["steps"] == 2 and meta["data_manifest_sha256"]
    again = run / "copy.safetensors"
    save_model(again, net, config, meta)
    net2, _, _ = load_model(again)
    for (k, a), (_, b) in zip(net.state_dict().items(), net2.state_dict().items()):
        assert torch_equal(a, b), k
    method = CompletionMethod(run / "best.safetensors")
    item = ShardDataset(out, split="test", geometry=True)[0]
    grid, h_in, pred = method.predict(item["partial_points"].astype(float))
    np.testing.assert_allclose(h_in, item["input"][0], atol=1e-3)  # voxelized exactly as in training
    assert pred.shape == (64, 64, 64) and 0 <= pred.min() and pred.max() <= 1
    import torch

    with torch.no_grad():
        eager = np.clip(net(torch.from_numpy(h_in[None, None]))[0, 0].numpy(), 0, 1)
    # every cloud, the first too, runs the network made fast for inference (decision 0321), whose float32 sums differ
    # from the eager network's in their last bits: up to about 1e-5, and by how much depends on the CPU's kernels
    # (ATEN_CPU_CAPABILITY=default moved one voxel by 1.1e-6, past the 1e-6 this compared with)
    np.testing.assert_allclose(pred, eager, atol=1e-5)
    _, _, again = method.predict(item["partial_points"].astype(float) + 1e-9)   # not the cached prediction
    assert 64 in method.predictor._forward                     # from the second on: made fast for inference
    np.testing.assert_allclose(again, eager, atol=1e-4)
    est = method.estimate(item["partial_points"].astype(float))
    assert 0 <= est.coverage <= 1 or np.isnan(est.coverage)
    assert set(est.seconds) >= {"network", "centerline", "mesh_holes"}
    # the centerline with the ridge's own ends (steps before 6; the map's segment-only track): its version
    # says so, and its line is the one extract_centerline gives with end_level None
    ridge = CompletionMethod(run / "best.safetensors", end_level=None)
    assert ridge.version.endswith(",end_level=None") and "end_level" not in method.version
    p = ridge.predictor(check_cloud(item["partial_points"].astype(float)))
    est_ridge = ridge.estimate(item["partial_points"].astype(float))
    assert 0 <= est_ridge.coverage <= 1 or np.isnan(est_ridge.coverage)
    line = extract_centerline(p.heatmap, end_level=None)
    if len(line) >= 2 and len(est_ridge.centerline):       # the reported line: a piece of that one (between the planes)
        assert distance_to_polyline(est_ridge.centerline, p.grid.to_mm(line)).max() < 0.1


def test_fine_tuning_starts_from_the_given_model(tiny_run, tmp_path):
    import torch

    out, run, _, _ = tiny_run
    start, _, _ = load_model(run / "best.safetensors")
    cfg = TrainConfig(epochs=1, batch_size=2, workers=0, augment_prob=0.0, lr=1e-12, init=str(run / "best.safetensors"))
    train(out, tmp_path / "tuned", cfg, device="cpu", progress=False)
    tuned, _, meta = load_model(tmp_path / "tuned" / "best.safetensors")
    # a step of 1e-12 leaves the weights where the given model had them (random ones would differ entirely;
    # batch-norm running statistics, buffers, move with the data whatever the step)
    for (k, a), (_, b) in zip(start.named_parameters(), tuned.named_parameters()):
        assert torch.allclose(a, b, atol=1e-6), k
    assert meta["train_config"]["init"] == str(run / "best.safetensors")
    # a resumed run may name its starting weights otherwise (a shipped model renamed), not give others
    import dataclasses
    import shutil

    from colonbench.shards.schema import sha256_file

    renamed = tmp_path / "renamed.safetensors"
    shutil.copy(run / "best.safetensors", renamed)
    cfg = dataclasses.replace(cfg, init_sha256=sha256_file(renamed))
    train(out, tmp_path / "named", cfg, device="cpu", progress=False)
    more = train(out, tmp_path / "named", dataclasses.replace(cfg, epochs=2, init=str(renamed)), device="cpu",
                 progress=False)
    assert more["epochs"] == 2
    with pytest.raises(InputError, match="other settings"):
        train(out, tmp_path / "named", dataclasses.replace(cfg, epochs=3, init=str(renamed), init_sha256="0" * 64),
              device="cpu", progress=False)
    with pytest.raises(InputError, match="no such model file"):
        train(out, tmp_path / "other", TrainConfig(epochs=1, batch_size=2, workers=0, init=str(tmp_path / "none.safetensors")),
              device="cpu", progress=False)


def test_training_resumes_and_refuses_other_settings(tiny_run):
    out, run, cfg, _ = tiny_run
    import dataclasses

    # keeping every epoch's weights is a run-length setting: it may be switched on when resuming
    more = train(out, run, dataclasses.replace(cfg, epochs=2, keep_epochs=True), device="cpu", progress=False)
    assert more["epochs"] == 2 and more["steps"] == 4
    log = (run / "log.csv").read_text().splitlines()
    assert len(log) == 3
    assert sorted(p.name for p in run.glob("epoch-*.safetensors")) == ["epoch-001.safetensors"]
    _, _, meta = load_model(run / "epoch-001.safetensors")
    assert meta["epoch"] == 1 and meta["steps"] == 4 and f"{meta['val_l2']:.6f}" == log[2].split(",")[4]
    with pytest.raises(InputError, match="other settings"):
        train(out, run, dataclasses.replace(cfg, epochs=3, lr=0.5), device="cpu", progress=False)


def test_training_needs_train_and_validation_splits(tmp_path):
    from colonbench.shards.dataset import generate
    from conftest import MANIFESTS

    generate(MANIFESTS / "smoke.yaml", tmp_path / "d", splits=["test"], progress=False)
    with pytest.raises(InputError, match="no train and no validation split"):
        train(tmp_path / "d", tmp_path / "run", TrainConfig(epochs=1), device="cpu", progress=False)
    with pytest.raises(InputError, match="seed and workers"):
        train(tmp_path / "d", tmp_path / "run", TrainConfig(seed=-1), device="cpu", progress=False)
    with pytest.raises(InputError, match="neither dataset.lock.json nor pack.json"):
        train(tmp_path / "nothing", tmp_path / "run", TrainConfig(epochs=1), device="cpu", progress=False)


def test_two_process_distributed_training(smoke_dataset, tmp_path):
    # PyTorch's own launcher and DistributedDataParallel, on the CPU (gloo)
    import subprocess
    import sys

    out, _ = smoke_dataset
    run = tmp_path / "ddp"
    proc = subprocess.run([sys.executable, "-m", "torch.distributed.run", "--nproc_per_node", "2",
                           "--master_port", "29517", "-m", "colonbench.cli", "train", str(out), "--out", str(run),
                           "--epochs", "1", "--batch-size", "1", "--workers", "0", "--device", "cpu", "--quiet"],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    _, _, meta = load_model(run / "best.safetensors")
    assert meta["world_size"] == 2 and meta["steps"] == 2 and meta["samples_seen"] == 4
    assert len((run / "log.csv").read_text().splitlines()) == 2


def test_network_shapes():
    import torch

    net = build_network(network_config("small"))
    assert net(torch.zeros(1, 1, 64, 64, 64)).shape == (1, 1, 64, 64, 64)


def test_the_network_made_fast_for_inference_gives_the_same_output():
    import torch

    from colonbench.completion.network import for_inference

    torch.manual_seed(0)
    net = build_network(network_config("small"))
    for m in net.modules():                # batch norms with statistics that folding must carry over
        if isinstance(m, torch.nn.BatchNorm3d):
            m.running_mean.uniform_(-0.5, 0.5)
            m.running_var.uniform_(0.5, 2.0)
    net.eval()
    fast = for_inference(net, 32, torch.device("cpu"))
    x = torch.rand(1, 1, 32, 32, 32)
    with torch.inference_mode():
        np.testing.assert_allclose(fast(x).numpy(), net(x).numpy(), atol=1e-4)


def test_sigterm_stops_training_cleanly_and_it_resumes(smoke_dataset, tmp_path):
    import os
    import signal
    import subprocess
    import sys
    import time

    import torch

    out, _ = smoke_dataset
    run = tmp_path / "run"
    cmd = [sys.executable, "-m", "colonbench.cli", "train", str(out), "--out", str(run), "--epochs", "50",
           "--batch-size", "1", "--workers", "1", "--device", "cpu", "--quiet"]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True)
    deadline = time.time() + 120
    while not (run / "log.csv").exists() and time.time() < deadline and proc.poll() is None:
        time.sleep(0.2)
    time.sleep(3)  # into the first epochs, a DataLoader worker running
    os.killpg(proc.pid, signal.SIGTERM)  # to the whole process group, as a shell's Ctrl-C or a scheduler does
    stdout, stderr = proc.communicate(timeout=120)
    assert proc.returncode == 0, stderr[-2000:]
    assert "stopped on request" in stdout
    # the closing line names the model only when one was written (not before the first epoch ends)
    assert ("Model: " in stdout) == (run / "best.safetensors").exists()
    assert ("No model yet" in stdout) != (run / "best.safetensors").exists()
    saved = torch.load(run / "last.pt", weights_only=False)
    assert saved["state"]["steps"] > 0 and saved["state"]["epoch"] < 50
    # and it goes on from there
    more = train(out, run, TrainConfig(epochs=saved["state"]["epoch"] + 2, batch_size=1, workers=1), device="cpu",
                 progress=False)
    assert more["steps"] > saved["state"]["steps"] and more["stopped"] == "done"


def test_several_datasets_train_together(smoke_dataset, tmp_path):
    import yaml

    from colonbench.shards.dataset import generate
    from colonbench.shards.reader import ShardDataset

    from conftest import MANIFESTS

    out, lock = smoke_dataset
    manifest = yaml.safe_load((MANIFESTS / "smoke.yaml").read_text())
    manifest.update(name="smoke-b", seed=8)
    manifest["splits"] = {"train": {"colons": {"first": 5, "count": 1}, "segments_per_length": 1, "permutations": 1},
                          "validation": {"colons": {"first": 6, "count": 1}, "segments_per_length": 1,
                                         "permutations": 1}}
    (tmp_path / "b.yaml").write_text(yaml.safe_dump(manifest))
    lock_b = generate(tmp_path / "b.yaml", tmp_path / "b", workers=1, progress=False)
    cfg = TrainConfig(epochs=1, batch_size=1, workers=0, augment_prob=0.0)
    result = train([out, tmp_path / "b"], tmp_path / "run", cfg, device="cpu", progress=False)
    n_train = len(ShardDataset(out, split="train")) + len(ShardDataset(tmp_path / "b", split="train"))
    assert result["steps"] == n_train  # one epoch of batch 1 over both train splits
    _, _, meta = load_model(tmp_path / "run" / "best.safetensors")
    assert meta["data_manifests"] == [lock["manifest_sha256"], lock_b["manifest_sha256"]]
    assert meta["data_dir"] == f"{out.name}+b"
    with pytest.raises(InputError, match="is a run on other data"):  # the same run folder, one dataset fewer
        train([out], tmp_path / "run", cfg, device="cpu", progress=False)

    manifest.update(name="smoke-c", grid={"size": 32, "margin": 2, "min_extent_mm": 70.0})
    (tmp_path / "c.yaml").write_text(yaml.safe_dump(manifest))
    generate(tmp_path / "c.yaml", tmp_path / "c", workers=1, progress=False)
    with pytest.raises(InputError, match="need the same grid"):
        train([out, tmp_path / "c"], tmp_path / "run-c", cfg, device="cpu", progress=False)


def test_the_hole_weighted_loss_weighs_only_the_missing_wall():
    """train_step's loss with --hole-weight A: the squared error counts 1 + A times on voxels of the complete surface
    the input holds no point near, once elsewhere; a network whose output is a constant gives it in closed form."""
    import torch

    from colonbench.completion.train import HOLE_INPUT, HOLE_TARGET, train_step

    class Constant(torch.nn.Module):
        def __init__(self):
            super().__init__()
            self.c = torch.nn.Parameter(torch.tensor(0.5))

        def forward(self, x):
            return self.c.expand_as(x[:, :1]).clone()

    y = torch.full((1, 1, 4, 4, 4), 0.6)
    x = torch.zeros(1, 1, 4, 4, 4)
    y[0, 0, 0, :, :] = 0.0                    # a wall of 16 voxels on the complete surface ...
    x[0, 0, 0, :2, :] = 0.9                   # ... 8 of them far from every partial point: the missing wall
    assert HOLE_TARGET > 0.0 and HOLE_INPUT < 0.9
    for weight in (0.0, 3.0):
        net = Constant()
        loss = train_step(net, torch.optim.SGD(net.parameters(), lr=0.0), x, y, hole_weight=weight)
        expected = (48 * 0.1 ** 2 + 8 * 0.5 ** 2 + 8 * (1 + weight) * 0.5 ** 2) / 64
        assert float(loss.detach()) == pytest.approx(expected, rel=1e-6)
    with pytest.raises(InputError, match="hole_weight"):
        TrainConfig(hole_weight=-1.0).check()
