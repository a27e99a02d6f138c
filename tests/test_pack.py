"""Packs: occupancies written from real shards, heatmaps made again from them (CPU and min-plus), training on them."""

import dataclasses
import json

import numpy as np
import pytest

torch = pytest.importorskip("torch")
pytest.importorskip("monai")

from colonbench.cli import main  # noqa: E402
from colonbench.completion import packdata  # noqa: E402
from colonbench.completion.network import build_network, load_model, network_config  # noqa: E402
from colonbench.completion.train import TrainConfig, evaluate_l2, train
from colonbench.completion.epochs import epoch_slots  # noqa: E402
from colonbench.errors import InputError  # noqa: E402
from colonbench.heatmaps import distance_to as distance_np  # noqa: E402
from colonbench.shards.pack import read_pack  # noqa: E402
from colonbench.shards.reader import ShardDataset  # noqa: E402


def test_a_pack_remakes_every_stored_heatmap(smoke_pack):
    data, lock, out, info = smoke_pack
    assert info["manifest_sha256"] == lock["manifest_sha256"]
    for split in ("train", "validation"):
        ds = ShardDataset(data, split=split)
        assert info["splits"][split]["samples"] == len(ds) > 0
        x, y = packdata.PackSplit(out, split, "cpu").batch(np.arange(len(ds)))
        for k in range(len(ds)):
            item = ds[k]
            # stored as float16: equal to its rounding, never more
            np.testing.assert_allclose(x[k].numpy(), item["input"], atol=1e-3)
            np.testing.assert_allclose(y[k].numpy(), item["target"], atol=1e-3)
    assert info["splits"]["train"]["bytes"] / info["splits"]["train"]["samples"] < 12 * 1024
    cached = packdata.PackSplit(out, "validation", "cpu", cache=True)
    plain = packdata.PackSplit(out, "validation", "cpu", cache=False)
    for a, b in zip(cached.batch([1, 0, 1]), plain.batch([1, 0, 1])):
        assert torch.equal(a, b)


def test_a_centerline_voxel_on_the_surface_is_kept_from_the_shards_polyline():
    # a stalked polyp's head across the centerline: voxels that are both surface and centerline have
    # target 0, so the target alone loses them and remakes other targets; the polyline gives them back
    from colonbench.heatmaps import heatmaps_from_occupancy, pack_occupancy, unpack_occupancy
    from colonbench.shards.pack import CHECK_TOLERANCE

    s0 = np.zeros((32, 32, 32), bool)
    s1 = np.zeros((32, 32, 32), bool)
    c = np.zeros((32, 32, 32), bool)
    s1[:, 16, 6] = s1[:, 16, 26] = True         # two walls
    s0[:, 16, 6] = True
    c[4:28, 16, 16] = True                       # the centerline between them
    s1[14:18, 14:19, 14:19] = True               # a polyp's head across it
    x, y = heatmaps_from_occupancy(s0, s1, c)
    from_target = y == 1                          # the centerline read from the target alone
    assert (c & ~from_target).sum() == 4          # the centerline voxels inside the head are lost
    assert np.abs(heatmaps_from_occupancy(x == 0, y == 0, from_target)[1] - y).max() > CHECK_TOLERANCE
    # format 2 stores the centerline's own grid (a format-1 reader voxelizes the polyline again:
    # test_shard_format2): bit-packed and back, it remakes the target exactly
    again = unpack_occupancy(pack_occupancy(c), 32)
    assert pack_occupancy(c).shape == (32 ** 3 // 8,) and np.array_equal(again, c)
    _, y2 = heatmaps_from_occupancy(x == 0, y == 0, again)
    np.testing.assert_array_equal(y2, y)
    # a format-1 shard's grids are read off its heatmaps with the polyline's own voxels: the same target
    from colonbench.shards.reader import format1_occupancy

    read = format1_occupancy(x, y, c)
    np.testing.assert_array_equal(heatmaps_from_occupancy(read["s0"], read["s1"], read["c"])[1], y)


def test_min_plus_distance_transform_is_exact():
    rng = np.random.default_rng(3)
    occ = torch.from_numpy(rng.random((3, 32, 32, 32)) < 0.002)
    occ[2] = False
    occ[2, 5, 30, 0] = True  # one voxel: the distance is known in closed form
    fast = packdata.distance_to(occ, method="min-plus")
    ref = torch.from_numpy(np.stack([distance_np(g) for g in occ.numpy()]))
    assert torch.allclose(fast, ref, atol=1e-5)
    i, j, k = np.indices((32, 32, 32))
    exact = np.sqrt((i - 5) ** 2 + (j - 30) ** 2 + (k - 0) ** 2)
    np.testing.assert_allclose(fast[2].numpy(), exact, atol=1e-5)
    assert torch.equal(packdata.distance_to(occ), ref)  # the CPU path is the edt package itself
    with pytest.raises(ValueError, match="unknown"):
        packdata.distance_to(occ, method="scipy")


def test_flips_are_exact_and_reproducible(smoke_pack):
    *_, out, _ = smoke_pack
    split = packdata.PackSplit(out, "train", "cpu")
    grids = split.grids([0])
    assert grids.shape == (1, 3, 64, 64, 64) and grids.dtype == torch.bool
    # flipping the occupancies and remaking the heatmaps = flipping the heatmaps
    x, y = packdata.heatmaps(grids[:, 0], grids[:, 1], grids[:, 2])
    g = torch.flip(grids, [2, 4])
    fx, fy = packdata.heatmaps(g[:, 0], g[:, 1], g[:, 2])
    ax, ay = packdata.apply_flips(x.unsqueeze(1), y.unsqueeze(1), [(0, 2)])
    assert torch.allclose(ax[0, 0], fx[0], atol=1e-6) and torch.allclose(ay[0, 0], fy[0], atol=1e-6)
    draws = [packdata.flips(0, e, i) for e in range(4) for i in range(16)]
    assert draws == [packdata.flips(0, e, i) for e in range(4) for i in range(16)]
    assert len(set(draws)) > 4 and () in draws and (0, 1, 2) in draws


def test_transposes_are_exact_reproducible_and_move_the_tube_off_the_first_axis(smoke_pack):
    *_, out, _ = smoke_pack
    grids = packdata.PackSplit(out, "train", "cpu").grids([0])
    x, y = packdata.heatmaps(grids[:, 0], grids[:, 1], grids[:, 2])
    for order in packdata.TRANSPOSES:
        # exchanging the occupancies' axes and remaking the heatmaps = exchanging the heatmaps' axes
        g = grids.permute(0, 1, *(a + 2 for a in order))
        tx, ty = packdata.heatmaps(g[:, 0], g[:, 1], g[:, 2])
        ax, ay = packdata.apply_transposes(x.unsqueeze(1), y.unsqueeze(1), [order])
        assert torch.allclose(ax[0, 0], tx[0], atol=1e-6) and torch.allclose(ay[0, 0], ty[0], atol=1e-6)
    # a straight line along the first axis: after the order (2, 0, 1) it runs along the second
    line = torch.zeros((1, 1, 16, 16, 16))
    line[0, 0, :, 3, 7] = 1.0
    moved, _ = packdata.apply_transposes(line, line, [(2, 0, 1)])
    assert torch.equal(torch.nonzero(moved[0, 0])[:, 1], torch.arange(16)) and \
        set(torch.nonzero(moved[0, 0])[:, 0].tolist()) == {7} and set(torch.nonzero(moved[0, 0])[:, 2].tolist()) == {3}
    same, _ = packdata.apply_transposes(line, line, [(0, 1, 2)])
    assert same is line
    draws = [packdata.transpose(0, e, i, 0.5) for e in range(4) for i in range(40)]
    assert draws == [packdata.transpose(0, e, i, 0.5) for e in range(4) for i in range(40)]
    assert set(draws) == {(0, 1, 2), *packdata.TRANSPOSES}
    assert 0.3 < np.mean([d == (0, 1, 2) for d in draws]) < 0.7
    assert all(packdata.transpose(0, 0, i, 0.0) == (0, 1, 2) for i in range(40))
    assert all(packdata.transpose(0, 0, i, 1.0) != (0, 1, 2) for i in range(40))


def test_training_with_transposes_records_them_and_refuses_a_bad_share(smoke_pack, tmp_path):
    *_, out, _ = smoke_pack
    cfg = TrainConfig(epochs=1, batch_size=2, workers=0, augment_prob=0.0, flips=True, transposes=1.0)
    assert train(out, tmp_path / "run", cfg, device="cpu", progress=False)["steps"] == 2
    _, _, meta = load_model(tmp_path / "run" / "best.safetensors")
    assert meta["train_config"]["transposes"] == 1.0
    with pytest.raises(InputError, match="other settings"):
        train(out, tmp_path / "run", dataclasses.replace(cfg, epochs=2, transposes=0.5), device="cpu",
              progress=False)
    with pytest.raises(InputError, match="transposes must be in"):
        train(out, tmp_path / "bad", dataclasses.replace(cfg, transposes=1.5), device="cpu", progress=False)


def test_erased_patches_are_balls_of_the_drawn_radii_and_leave_the_target_alone(smoke_pack, tmp_path):
    # a plane of occupied voxels: one patch of radius 5 takes out exactly the plane's voxels within 5
    # voxels of its centre, an occupied voxel drawn after the patch count
    plane = torch.zeros((32, 32, 32), dtype=torch.bool)
    plane[:, :, 16] = True
    cut = packdata.erase_patches(plane, np.random.default_rng(3), patches=(1, 1), radius=(5.0, 5.0), keep=0.0)
    rng = np.random.default_rng(3)
    rng.integers(1, 2)
    occupied = torch.nonzero(plane).numpy()
    centre = occupied[rng.integers(len(occupied))]
    within = np.linalg.norm(occupied - centre, axis=1) <= 5.0
    assert not bool((cut & ~plane).any())                       # nothing added
    assert sorted(map(tuple, torch.nonzero(plane & ~cut).numpy())) == sorted(map(tuple, occupied[within]))
    assert 15 < within.sum() <= 81                                  # a disc of radius 5, whole or clipped at an edge
    assert bool(packdata.erase_patches(plane, np.random.default_rng(3), keep=1.0).equal(plane))
    # the same seed, epoch and sample draw the same patches; share 0 never erases
    assert packdata.erasure(0, 2, 7, 0.0) is None
    draws = [packdata.erasure(0, e, i, 0.5) is not None for e in range(4) for i in range(25)]
    assert 30 < sum(draws) < 70 and draws == [packdata.erasure(0, e, i, 0.5) is not None
                                              for e in range(4) for i in range(25)]
    *_, out, _ = smoke_pack
    split = packdata.PackSplit(out, "train", "cpu")
    x, y = split.batch([0, 1])
    ex, ey = split.batch([0, 1], [packdata.erasure(0, 0, 0, 1.0), None])
    assert torch.equal(ey, y) and torch.equal(ex[1], x[1])
    # the erased input is the input heatmap of the occupancy with the patches taken out
    s0 = packdata.erase_patches(split.grids([0])[0, 0], packdata.erasure(0, 0, 0, 1.0))
    assert not torch.equal(ex[0], x[0])
    assert torch.allclose(ex[0, 0], packdata.heatmaps(s0[None], s0[None], s0[None])[0][0])
    # training erases, on the pack and on the shards it was made of: the same grids, the same weights
    cfg = TrainConfig(epochs=1, batch_size=2, workers=0, augment_prob=0.0, erase=0.5)
    assert train(out, tmp_path / "run", cfg, device="cpu", progress=False)["steps"] == 2
    net, _, meta = load_model(tmp_path / "run" / "best.safetensors")
    assert meta["train_config"]["erase"] == 0.5
    data, *_ = smoke_pack
    assert train(data, tmp_path / "shards", cfg, device="cpu", progress=False)["steps"] == 2
    from_shards = load_model(tmp_path / "shards" / "best.safetensors")[0].state_dict()
    assert all(torch.equal(v, from_shards[k]) for k, v in net.state_dict().items())
    # geometric augmentation needs the geometry: erasing then is refused with what to do
    with pytest.raises(InputError, match="--augment-prob 0"):
        train(data, tmp_path / "aug", dataclasses.replace(cfg, augment_prob=0.5), device="cpu", progress=False)
    with pytest.raises(InputError, match="erase must be"):
        TrainConfig(erase=1.5).check()


def test_training_on_a_pack_matches_the_shards_and_resumes(smoke_pack, tmp_path):
    data, _, out, _ = smoke_pack
    net = build_network(network_config("small"))
    pack_l2 = evaluate_l2(net, packdata.PackSplit(out, "validation", "cpu"), "cpu")
    shard_l2 = evaluate_l2(net, ShardDataset(data, split="validation"), "cpu")
    assert pack_l2 == pytest.approx(shard_l2, rel=1e-3)

    run = tmp_path / "run"
    cfg = TrainConfig(epochs=1, batch_size=2, workers=0, augment_prob=0.0, flips=True)
    first = train(out, run, cfg, device="cpu", progress=False)
    assert first["epochs"] == 1 and first["steps"] == 2
    more = train(out, run, dataclasses.replace(cfg, epochs=2), device="cpu", progress=False)
    assert more["epochs"] == 2 and more["steps"] == 4
    _, _, meta = load_model(run / "best.safetensors")
    assert meta["data_format"] == "pack" and meta["train_config"]["flips"] is True
    assert meta["grid_options"]["size"] == 64 and 0 < meta["train_coverage_mean"] < 1
    with pytest.raises(InputError, match="other settings"):
        train(out, run, dataclasses.replace(cfg, epochs=3, flips=False), device="cpu", progress=False)
    with pytest.raises(InputError, match="--augment-prob 0"):
        train(out, tmp_path / "aug", dataclasses.replace(cfg, augment_prob=0.3), device="cpu", progress=False)


def test_several_packs_train_together_and_not_with_shards(smoke_pack, tmp_path):
    # e.g. the widened, real and video training packs of one GPU run; here one pack and a copy of it
    import shutil

    data, lock, out, _ = smoke_pack
    copy = tmp_path / "copy"
    shutil.copytree(out, copy)
    n_train = len(packdata.PackSplit(out, "train", "cpu"))
    both = packdata.PackSplit([out, copy], "train", "cpu")
    assert len(both) == 2 * n_train
    assert bool((both.grids([0]) == both.grids([n_train])).all())     # the second pack follows the first
    cfg = TrainConfig(epochs=1, batch_size=1, workers=0, augment_prob=0.0)
    result = train([out, copy], tmp_path / "run", cfg, device="cpu", progress=False)
    assert result["steps"] == 2 * n_train
    _, _, meta = load_model(tmp_path / "run" / "best.safetensors")
    assert meta["data_manifests"] == [lock["manifest_sha256"]] * 2 and meta["data_format"] == "pack"
    with pytest.raises(InputError, match="all shard folders or all packs"):
        train([out, data], tmp_path / "mixed", cfg, device="cpu", progress=False)


def test_repeat_weighs_each_dataset_by_its_count(smoke_pack, smoke_dataset, tmp_path):
    # e.g. two real colons' pack beside a large procedural one: --repeat 1,8
    import shutil

    assert epoch_slots([3, 2], (1, 3)).tolist() == [0, 1, 2, 3, 4, 3, 4, 3, 4]
    assert epoch_slots([3, 2]).tolist() == [0, 1, 2, 3, 4]      # no repeat: slot k is sample k
    data, lock, out, _ = smoke_pack
    copy = tmp_path / "copy"
    shutil.copytree(out, copy)
    n_train = len(packdata.PackSplit(out, "train", "cpu"))
    cfg = TrainConfig(epochs=1, batch_size=1, workers=0, augment_prob=0.0, flips=True, repeat=(1, 3))
    result = train([out, copy], tmp_path / "run", cfg, device="cpu", progress=False)
    assert result["steps"] == 4 * n_train
    _, _, meta = load_model(tmp_path / "run" / "best.safetensors")
    assert meta["train_config"]["repeat"] == [1, 3]
    shards = train(smoke_dataset[0], tmp_path / "shards", TrainConfig(epochs=1, batch_size=1, workers=0,
                                                                       augment_prob=0.0, repeat=(2,)),
                   device="cpu", progress=False)
    assert shards["steps"] == 2 * n_train
    with pytest.raises(InputError, match="one per dataset"):
        train([out, copy], tmp_path / "bad", dataclasses.replace(cfg, repeat=(2,)), device="cpu", progress=False)
    with pytest.raises(InputError, match="whole numbers >= 1"):
        TrainConfig(repeat=(1, 0)).check()
    with pytest.raises(SystemExit):
        main(["train", str(out), "--out", str(tmp_path / "cli"), "--repeat", "1,x"])


def test_flips_also_augment_training_on_shards(smoke_dataset, tmp_path):
    data, _ = smoke_dataset
    cfg = TrainConfig(epochs=1, batch_size=2, workers=0, augment_prob=0.0, flips=True)
    assert train(data, tmp_path / "run", cfg, device="cpu", progress=False)["steps"] == 2
    _, _, meta = load_model(tmp_path / "run" / "best.safetensors")
    assert meta["data_format"] == "shards" and meta["train_config"]["flips"] is True


def test_pack_refuses_bad_input_and_damage(smoke_dataset, smoke_pack, tmp_path, capsys):
    data, *_ = smoke_dataset
    *_, out, _ = smoke_pack
    assert main(["pack", str(tmp_path / "nothing"), "--out", str(tmp_path / "p")]) == 2
    assert "generate the dataset first" in capsys.readouterr().err
    assert main(["pack", str(data), "--out", str(tmp_path / "p"), "--splits", "train,bogus"]) == 2
    assert "no split bogus" in capsys.readouterr().err
    assert main(["pack", str(data), "--out", str(tmp_path / "p"), "--context-line", "map"]) == 2
    assert "--context-line is for context packs" in capsys.readouterr().err
    assert not (tmp_path / "p").exists()
    with pytest.raises(InputError, match="not a pack"):
        read_pack(tmp_path, "train")
    copy = tmp_path / "copy"
    copy.mkdir()
    for f in out.iterdir():
        copy.joinpath(f.name).write_bytes(f.read_bytes())
    raw = bytearray((copy / "train.h5").read_bytes())
    raw[-100] ^= 0xFF
    (copy / "train.h5").write_bytes(bytes(raw))
    with pytest.raises(InputError, match="sha256"):
        read_pack(copy, "train")
    info = json.loads((copy / "pack.json").read_text())
    assert main(["pack", str(data), "--out", str(copy), "--splits", "validation", "--quiet"]) == 0
    again = json.loads((copy / "pack.json").read_text())
    assert again["manifest_sha256"] == info["manifest_sha256"] and set(again["splits"]) == {"train", "validation"}


def test_cpu_training_makes_a_packs_batches_in_workers_and_steps_in_bf16(smoke_pack, tmp_path):
    # a worker process makes the batches the loop makes itself on a GPU (same samples, same erased patches):
    # the epoch's mean training loss is the same (the training step then runs on one thread instead of
    # two, which moves the weights after Adam's steps, and the validation loss, by a few 1e-3 of it);
    # bf16 steps train, and are a setting a resume must keep
    *_, out, _ = smoke_pack
    # the k-th batch: the epoch's k-th pair of samples, each erased as its slot draws
    split = packdata.PackSplit(out, "train", "cpu")
    made = packdata.PackBatches(split, [1, 0, 1], [2, 0, 1], 2, seed=0, epoch=3, erase=1.0)
    assert len(made) == 2
    for k, (samples, slots) in enumerate([([1, 0], [2, 0]), ([1], [1])]):
        x, y = split.batch(samples, [packdata.erasure(0, 3, i, 1.0) for i in slots])
        assert torch.equal(made[k][0], x) and torch.equal(made[k][1], y)
    assert not torch.equal(made[0][0][0], made[1][0][0])     # sample 1 in slots 2 and 1: other patches
    cfg = TrainConfig(epochs=1, batch_size=2, augment_prob=0.0, flips=True, erase=1.0)
    logs = {}
    for workers in (0, 1):
        torch.manual_seed(0)
        train(out, tmp_path / f"w{workers}", dataclasses.replace(cfg, workers=workers), device="cpu", progress=False)
        logs[workers] = (tmp_path / f"w{workers}" / "log.csv").read_text().splitlines()[1].split(",")
    assert float(logs[1][3]) == pytest.approx(float(logs[0][3]), rel=1e-4)      # train L2
    assert float(logs[1][4]) == pytest.approx(float(logs[0][4]), rel=2e-2)      # validation L2
    threads = torch.get_num_threads()
    bf16 = dataclasses.replace(cfg, precision="bf16")
    result = train(out, tmp_path / "bf16", bf16, device="cpu", progress=False)
    assert result["steps"] == 2 and np.isfinite(result["best_val_l2"])
    assert torch.get_num_threads() == threads                                   # the workers' cores given back
    assert load_model(tmp_path / "bf16" / "best.safetensors")[2]["train_config"]["precision"] == "bf16"
    with pytest.raises(InputError, match="other settings"):
        train(out, tmp_path / "bf16", dataclasses.replace(cfg, epochs=2), device="cpu", progress=False)
    with pytest.raises(InputError, match="precision 'fp16'"):
        TrainConfig(precision="fp16").check()


def test_training_on_a_pack_needs_no_geometry_stack(smoke_pack, tmp_path):
    # the README's promise for a GPU machine with PyTorch and no package registry: a pack trains with
    # trimesh, open3d, manifold3d, pyrender and scikit-fmm absent (None in sys.modules: importing them fails)
    import subprocess
    import sys

    _, _, out, _ = smoke_pack
    run = tmp_path / "run"
    code = ("import sys\n"
            "for n in ('trimesh', 'open3d', 'manifold3d', 'pyrender', 'skfmm', 'embreex', 'rtree', 'OpenGL'):\n"
            "    sys.modules[n] = None\n"
            "from colonbench.cli import main\n"
            f"sys.argv = ['colonbench', 'train', {str(out)!r}, '--out', {str(run)!r}, '--epochs', '1',\n"
            "            '--batch-size', '2', '--augment-prob', '0', '--flips', '--transposes', '0.3',\n"
            "            '--erase', '0.5', '--device', 'cpu', '--quiet']\n"
            "main()\n"
            "bad = sorted(n for n in ('trimesh', 'open3d', 'manifold3d', 'pyrender', 'skfmm') if sys.modules.get(n))\n"
            "assert not bad, bad\n")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr[-2000:]
    assert "1 epochs" in r.stdout and (run / "best.safetensors").exists()
    assert load_model(run / "best.safetensors")[2]["train_config"]["transposes"] == 0.3


def test_the_screening_set_up_pools_the_grids_and_runs_inside_the_full_grid(smoke_pack, tmp_path):
    """``--pool 2`` (decision record 0326): a coarse voxel is occupied where any of its 8 fine ones is, the heatmaps
    count distances in the pack's own voxels, the model trained on them records its pooling, and at inference it
    sees the cloud's pooled input and gives a prediction on the full grid."""
    from colonbench.completion.method import CompletionMethod
    from colonbench.completion.screening import pooled_input
    from colonbench.grid import fit_grid
    from colonbench.heatmaps import input_heatmap, voxelize_points
    from colonbench.shards.reader import Shard

    occ = torch.zeros(1, 8, 8, 8, dtype=torch.bool)
    occ[0, 3, 4, 5] = True                                 # one fine voxel: its coarse block (1, 2, 2)
    coarse = packdata.pooled(occ, 2)
    assert coarse.shape == (1, 4, 4, 4) and coarse.sum() == 1 and bool(coarse[0, 1, 2, 2])
    data, _, out, _ = smoke_pack
    full, screen = packdata.PackSplit(out, "validation", "cpu"), packdata.PackSplit(out, "validation", "cpu", pool=2)
    assert screen.size == 32 and screen._cache is not None  # screening heatmaps are made once
    g_full, g_screen = full.grids([0]), screen.grids([0])
    assert torch.equal(packdata.pooled(g_full[0], 2), g_screen[0])
    x, _ = screen.batch([0])
    d = torch.from_numpy(distance_np(g_screen[0, 0].numpy())).float()
    assert torch.allclose(x[0, 0], input_heatmap(2 * d), atol=1e-6)    # distances in the pack's voxels
    with pytest.raises(InputError, match="whole blocks"):
        packdata.PackSplit(out, "validation", "cpu", pool=3)

    run = tmp_path / "screen"
    train(out, run, TrainConfig(epochs=1, batch_size=2, workers=0, augment_prob=0.0, pool=2), device="cpu",
          progress=False)
    _, cfg, meta = load_model(run / "best.safetensors")
    assert meta["train_config"]["pool"] == 2 and meta["grid_options"]["size"] == 64
    with pytest.raises(InputError, match="pool must be"):
        train(out, tmp_path / "bad", TrainConfig(epochs=1, workers=0, augment_prob=0.0, pool=3), device="cpu",
              progress=False)
    with Shard(next((data / "test").glob("*.h5"))) as shard:
        points = shard.geometry(0)["partial_points"]
    method = CompletionMethod(run / "best.safetensors")
    assert ",pool=2" in method.version                  # a screening model's rows never pass for a full model's
    p = method.predictor(points)
    assert p.heatmap.shape == (64, 64, 64) and p.grid.size == 64       # on the full grid, the steps as ever
    grid = fit_grid(points, **meta["grid_options"])
    small = pooled_input(grid, points, 2)
    fine, _ = voxelize_points(grid, points)
    assert small.shape == (32, 32, 32) and np.array_equal(small == 0, packdata.pooled(
        torch.from_numpy(fine)[None], 2)[0].numpy())
    assert np.isfinite(method.estimate(points).coverage)


def test_a_pooled_prediction_is_interpolated_onto_the_full_grids_voxel_centres():
    """screening.upsampled: trilinear with the coarse voxel k's centre at fine index 2k + 0.5, so a linear ramp over
    the coarse voxels comes back as the same ramp at the fine voxels' centres (inside, away from the clamped faces)."""
    from colonbench.completion.screening import upsampled

    k = torch.arange(8, dtype=torch.float32)
    coarse = k.view(1, 1, 8, 1, 1).expand(1, 1, 8, 8, 8).contiguous()          # value k at coarse centre 2k + 0.5
    fine = upsampled(coarse, 2, 16)[0, 0, :, 4, 4]
    i = torch.arange(16, dtype=torch.float32)
    expected = (i - 0.5) / 2                                                     # fine index i lies at coarse (i - 0.5) / 2
    assert torch.allclose(fine[1:-1], expected[1:-1], atol=1e-6)
    assert upsampled(coarse, 1, 8) is coarse
