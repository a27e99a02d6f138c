"""The plain-PyTorch UNet that inference runs is MONAI's network: the same weights give the same outputs."""

import subprocess
import sys

import pytest

torch = pytest.importorskip("torch")
pytest.importorskip("monai")

from colonbench.completion.network import NETWORKS, NetworkConfig, build_network, load_model  # noqa: E402


def _randomised(net):
    """Every parameter and batch-norm statistic drawn at random, so no layer can hide behind its initial value."""
    g = torch.Generator().manual_seed(1)
    with torch.no_grad():
        for p in net.parameters():
            p.copy_(torch.rand(p.shape, generator=g) - 0.5)
        for m in net.modules():
            if isinstance(m, torch.nn.BatchNorm3d):
                m.running_mean.copy_(torch.rand(m.running_mean.shape, generator=g) - 0.5)
                m.running_var.copy_(torch.rand(m.running_var.shape, generator=g) + 0.5)
    return net.eval()


@pytest.mark.parametrize("config", [NETWORKS["small"], NETWORKS["large"], NetworkConfig(in_channels=2),
                                    NetworkConfig(channels=(8, 16, 32), strides=(2, 2), num_res_units=2)],
                         ids=["small", "large", "in-context", "two-units"])
def test_plain_unet_computes_monais_outputs(config):
    monai_net = _randomised(build_network(config))
    plain = build_network(config, plain=True).eval()
    assert type(plain).__module__ == "colonbench.completion.unet"
    plain.load_state_dict(monai_net.state_dict(), strict=True)   # the same parameter names, one for one
    x = torch.randn((2, config.in_channels, 32, 32, 32), generator=torch.Generator().manual_seed(2))
    with torch.no_grad():
        a, b = monai_net(x), plain(x)
    assert a.shape == b.shape == (2, 1, 32, 32, 32)
    assert torch.allclose(a, b, rtol=0, atol=1e-6) and a.abs().mean() > 0.1


def test_the_shipped_model_loads_into_either_network():
    from colonbench.completion.method import shipped_model

    plain, config, _ = load_model(shipped_model())
    monai_net, _, _ = load_model(shipped_model(), plain=False)
    assert type(plain).__module__ == "colonbench.completion.unet" and "monai" in type(monai_net).__module__
    x = torch.rand((1, config.in_channels, 64, 64, 64), generator=torch.Generator().manual_seed(3))
    with torch.no_grad():
        assert torch.allclose(plain(x), monai_net(x), rtol=0, atol=1e-6)


def test_estimate_does_not_import_monai(tmp_path):
    import numpy as np

    rng = np.random.default_rng(0)
    a, z = rng.uniform(0, 2 * np.pi, 6000), rng.uniform(0, 60, 6000)
    np.save(tmp_path / "tube.npy", np.c_[15 * np.cos(a), 15 * np.sin(a), z])
    code = ("import sys\nfrom colonbench.cli import main\n"
            f"assert main(['estimate', {str(tmp_path / 'tube.npy')!r}, '--out-dir', {str(tmp_path)!r}]) == 0\n"
            "print('monai' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip().splitlines()[-1] == "False"
    assert (tmp_path / "tube.json").is_file()
