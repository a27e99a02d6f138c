"""Weight averages of saved models (colonbench average): the mean of known weights, batch norm recomputed exactly."""

import json

import numpy as np
import pytest

torch = pytest.importorskip("torch")
pytest.importorskip("monai")

from colonbench.cli import main  # noqa: E402
from colonbench.completion.average import average_states, recompute_batchnorm  # noqa: E402
from colonbench.completion.network import NetworkConfig, build_network, load_model, network_config, save_model  # noqa: E402
from colonbench.errors import InputError  # noqa: E402
from colonbench.shards.schema import sha256_file  # noqa: E402

GRID = {"size": 16, "margin": 4, "min_extent_mm": 70.0, "axes": "tube"}
TINY = NetworkConfig(channels=(4, 8), strides=(2,), num_res_units=1)


def _saved(path, seed, config=TINY, grid=GRID):
    torch.manual_seed(seed)
    net = build_network(config)
    with torch.no_grad():
        for m in net.modules():  # batch-norm statistics that differ from model to model
            if isinstance(m, torch.nn.modules.batchnorm._BatchNorm):
                m.running_mean.uniform_(-1, 1)
                m.running_var.uniform_(0.5, 2)
    return save_model(path, net, config, {"grid_options": grid, "steps": seed})


def test_the_average_of_models_is_the_mean_of_their_weights(tmp_path):
    paths = [_saved(tmp_path / f"m{k}.safetensors", k) for k in range(3)]
    state, config, meta = average_states(paths)
    nets = [load_model(p)[0].state_dict() for p in paths]
    assert config == TINY and meta["steps"] == 2
    floats = [k for k, v in state.items() if v.is_floating_point()]
    assert len(floats) > 10
    for key in floats:
        want = (nets[0][key] + nets[1][key] + nets[2][key]) / 3
        assert torch.allclose(state[key], want, atol=1e-6), key
        if not torch.equal(nets[0][key], nets[1][key]):  # PReLU slopes start equal everywhere
            assert not torch.allclose(state[key], nets[0][key])
    ints = [k for k, v in state.items() if not v.is_floating_point()]
    assert ints and all(torch.equal(state[k], nets[2][k]) for k in ints)


def test_only_one_networks_models_on_one_grid_average(tmp_path):
    a = _saved(tmp_path / "a.safetensors", 0)
    with pytest.raises(InputError, match="at least two"):
        average_states([a])
    other = _saved(tmp_path / "b.safetensors", 1, config=NetworkConfig(channels=(4, 16), strides=(2,)))
    with pytest.raises(InputError, match="only one network"):
        average_states([a, other])
    grid = _saved(tmp_path / "c.safetensors", 2, grid={**GRID, "size": 32})
    with pytest.raises(InputError, match="other grids"):
        average_states([a, grid])
    (tmp_path / "bad.safetensors").write_bytes(b"not a model")
    with pytest.raises(InputError, match="not a readable"):
        average_states([a, tmp_path / "bad.safetensors"])


def test_recomputed_batch_norm_statistics_are_the_mean_over_the_batches():
    torch.manual_seed(0)
    conv = torch.nn.Conv3d(1, 3, 3)
    net = torch.nn.Sequential(conv, torch.nn.BatchNorm3d(3, momentum=0.1))
    batches = [torch.randn(4, 1, 6, 6, 6) * (k + 1) + k for k in range(5)]
    with torch.no_grad():
        outs = [conv(x) for x in batches]
    means = torch.stack([o.mean(dim=(0, 2, 3, 4)) for o in outs]).mean(0)
    n = outs[0].numel() / 3
    vars_ = torch.stack([o.var(dim=(0, 2, 3, 4), unbiased=False) * n / (n - 1) for o in outs]).mean(0)
    assert recompute_batchnorm(net, batches) == 5
    bn = net[1]
    assert torch.allclose(bn.running_mean, means, atol=1e-5) and torch.allclose(bn.running_var, vars_, rtol=1e-4)
    assert bn.momentum == 0.1 and not net.training and int(bn.num_batches_tracked) == 5


def test_colonbench_average_writes_a_model_that_says_how_it_was_made(smoke_pack, tmp_path, capsys):
    *_, pack, info = smoke_pack
    grid = info["grid_options"]
    paths = [_saved(tmp_path / f"m{k}.safetensors", k, config=network_config("small"), grid=grid) for k in range(2)]
    out = tmp_path / "avg.safetensors"
    args = ["average", *map(str, paths), "--out", str(out), "--bn-data", str(pack), "--repeat", "2", "--bn-samples", "6",
            "--seed", "3"]
    assert main(args) == 0
    assert "the uniform mean of 2 models" in capsys.readouterr().out
    net, config, meta = load_model(out)
    avg = meta["average"]
    assert [m["sha256"] for m in avg["models"]] == [sha256_file(p) for p in paths]
    assert avg["batchnorm"]["samples"] == 6 and avg["batchnorm"]["batches"] == 2 and avg["command"].startswith(
        "colonbench average")
    assert meta["train_coverage_mean"] == pytest.approx(json.loads((pack / "pack.json").read_text())[
        "train_coverage_mean"])
    assert meta["grid_options"] == grid and meta["steps"] == "avg2"
    state = net.state_dict()
    first = [k for k in state if k.endswith("running_mean")][0]
    loaded = [load_model(p)[0].state_dict()[first] for p in paths]
    assert not torch.allclose(state[first], (loaded[0] + loaded[1]) / 2)  # recomputed, not averaged
    x = torch.rand(1, 1, *(grid["size"],) * 3)
    with torch.no_grad():
        assert np.isfinite(net(x).numpy()).all()
    # The same command again: the same weights and statistics, to the rounding of batch norm's sums over threads (a
    # full run once saw the last bits differ). Another draw of the samples would move the running statistics by far
    # more than this bound.
    again = tmp_path / "again.safetensors"
    assert main([*args[:3], "--out", str(again), *args[5:]]) == 0
    state2 = load_model(again)[0].state_dict()
    stats = [k for k in state if k.endswith(("running_mean", "running_var"))]
    assert stats and all(torch.equal(state[k], state2[k]) for k in state if k not in stats), "the weights differ"
    off = {k: float((state[k] - state2[k]).abs().max()) for k in stats}
    assert all(torch.allclose(state[k], state2[k], rtol=1e-5, atol=1e-6) for k in stats), off


def test_colonbench_average_refuses_bad_input_with_a_message(smoke_pack, tmp_path, capsys):
    *_, pack, info = smoke_pack
    paths = [_saved(tmp_path / f"m{k}.safetensors", k, config=network_config("small"), grid=info["grid_options"])
             for k in range(2)]
    out = tmp_path / "avg.safetensors"
    assert main(["average", str(paths[0]), str(paths[1]), "--out", str(out), "--bn-data", str(tmp_path)]) == 2
    assert "neither" in capsys.readouterr().err
    assert main(["average", str(paths[0]), str(paths[1]), "--out", str(out), "--bn-data", str(pack),
                 "--bn-samples", "100000"]) == 2
    assert "training slots" in capsys.readouterr().err
    assert main(["average", str(paths[0]), str(paths[1]), "--out", str(out), "--bn-data", str(pack),
                 "--repeat", "1,2"]) == 2
    assert "one per dataset" in capsys.readouterr().err
    assert main(["average", str(paths[0]), str(tmp_path / "none.safetensors"), "--out", str(out), "--bn-data",
                 str(pack)]) == 2
    assert "no such model file" in capsys.readouterr().err
    assert not out.exists()
