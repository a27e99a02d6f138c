"""The completion method as users call it: input checks, the estimate command, order-free estimates, shared predictions."""

import json

import numpy as np
import pytest

pytest.importorskip("torch")
pytest.importorskip("monai")

from colonbench.cli import main  # noqa: E402
from colonbench.completion.method import CompletionMethod, check_cloud  # noqa: E402
from colonbench.datagen.colon import tube_colon  # noqa: E402
from colonbench.datagen.generate import write_points_ply  # noqa: E402
from colonbench.errors import InputError  # noqa: E402
from colonbench.shards.reader import ShardDataset  # noqa: E402
from shapes import straight  # noqa: E402

R = 20.0


@pytest.mark.parametrize("cloud, message", [
    (np.zeros((0, 3)), "at least"),
    (np.random.default_rng(0).normal(size=(12, 3)) * 20, "only 12 point"),
    (np.full((500, 3), np.nan), "NaN"),
    (np.random.default_rng(0).normal(size=(5000, 3)) * 0.02, "metres"),
    # a 60 mm segment of a 15 mm-radius tube written in centimetres: 6.7 units across
    (np.c_[1.5 * np.cos(np.linspace(0, 60, 3000)), 1.5 * np.sin(np.linspace(0, 60, 3000)),
           np.linspace(0, 6, 3000)], "looks like centimetres"),
    (np.random.default_rng(0).normal(size=(5000, 3)) * 300, "far more than one colon segment"),
    (np.ones((500, 3)), "all 500 points coincide"),
    (np.repeat(np.random.default_rng(0).uniform(0, 50, (20, 3)), 30, axis=0),
     "only 20 point.s. once repeated points are dropped .600 given."),
    (np.linspace(0, 60, 500)[:, None] * [[1.0, 0.5, 0.0]], "lie on a line"),
    (np.c_[np.random.default_rng(0).uniform(0, 50, (500, 2)), np.full(500, 7.0)], "lie in one plane"),
])
def test_bad_clouds_get_clear_messages(cloud, message):
    with pytest.raises(InputError, match=message):
        check_cloud(cloud)


def test_the_smallest_segment_is_not_taken_for_centimetres():
    # the widened generator's smallest segment: 10 mm radius, 20 mm long (its diameter), a third of its wall seen
    theta, z = np.meshgrid(np.linspace(0, 2 * np.pi / 3, 40), np.linspace(0, 20, 30))
    wall = np.c_[10 * np.cos(theta).ravel(), 10 * np.sin(theta).ravel(), z.ravel()]
    assert len(check_cloud(wall)) == 1200


def test_a_nearly_flat_wall_is_a_cloud():
    # a 40 mm-wide strip of a 40 mm-radius wall bulges 5.4 mm: curved, not refused as flat
    theta, z = np.meshgrid(np.linspace(-0.5, 0.5, 40), np.linspace(0, 50, 50))
    wall = np.c_[40 * np.sin(theta).ravel(), 40 * np.cos(theta).ravel(), z.ravel()]
    assert len(check_cloud(wall)) == 2000


def test_estimate_command_writes_one_json_per_input(tiny_run, tmp_path, capsys):
    out, run, _, _ = tiny_run
    ds = ShardDataset(out, split="test", geometry=True)
    inputs = []
    for k in range(2):
        folder = tmp_path / f"seg{k}"
        folder.mkdir()
        inputs.append(write_points_ply(folder / "partial.ply", ds[k]["partial_points"]))
    np.save(tmp_path / "other.npy", ds[0]["partial_points"])
    res = tmp_path / "res"
    assert main(["estimate", *map(str, inputs), str(tmp_path / "other.npy"), "--model", str(run / "best.safetensors"),
                 "--out-dir", str(res), "--mesh"]) == 0
    for name in ("seg0", "seg1", "other"):
        data = json.loads((res / f"{name}.json").read_text())
        assert {"coverage", "holes", "centerline", "method"} <= set(data)
        assert data["method"] == "completion"
        assert all(len(p) == 3 for p in data["centerline"])
    assert (res / "seg0_mesh.ply").exists() and (res / "seg0_centerline.ply").exists()
    # one bad input among good ones: named, the others still written
    (tmp_path / "bad.xyz").write_text("1 2 3\n")
    assert main(["estimate", str(tmp_path / "bad.xyz"), str(tmp_path / "other.npy"), "--model",
                 str(run / "best.safetensors"), "--out-dir", str(tmp_path / "res2")]) == 2
    err = capsys.readouterr().err
    assert "bad.xyz" in err and "only 1 point" in err and "1 of 2 input(s) failed" in err
    assert "the others were written" in err
    # a reader's message names the file once, not twice
    np.save(tmp_path / "six.npy", np.zeros((300, 6)))
    assert main(["estimate", str(tmp_path / "six.npy"), "--model", str(run / "best.safetensors"),
                 "--out-dir", str(tmp_path / "res3")]) == 2
    err = capsys.readouterr().err
    assert err.count("six.npy") == 1 and "got an array of shape (300, 6)" in err
    assert "1 of 1 input(s) failed (see above); nothing was written" in err
    assert (tmp_path / "res2" / "other.json").exists()


@pytest.mark.parametrize("density", [2.0, 10.0])
def test_the_estimate_is_the_same_whatever_the_order_of_the_points(density):
    # a tube with a window, sampled like a reconstruction (more points than the grid's normals and the density
    # estimate use): shuffled, and with a fifth of its points repeated, the shipped model must give the same
    # answer (to the rounding of sums over points); at 10 points/mm^2 the cloud is thinned at random first,
    # and that draw depended on the order of the points (steps 10)
    from colonbench.meshes import sample_surface
    from colonbench.grid import even_subsample

    colon = tube_colon(straight(63.0), R, ring_spacing_mm=0.5, n_around=256)
    pts = sample_surface(np.random.default_rng(2), colon.mesh.vertices, colon.mesh.faces, density)
    theta = np.arctan2(pts[:, 1], pts[:, 0])
    pts = pts[~((np.abs(theta) < 0.5) & (pts[:, 2] > 20) & (pts[:, 2] < 40))]
    rng = np.random.default_rng(3)
    repeated = np.concatenate([pts, pts[rng.choice(len(pts), len(pts) // 5)]])
    shuffled = repeated[rng.permutation(len(repeated))]
    assert len(pts) > 3000
    a = np.sort(even_subsample(pts, 1000).view("f8,f8,f8"), axis=0)
    b = np.sort(even_subsample(pts[rng.permutation(len(pts))], 1000).view("f8,f8,f8"), axis=0)
    assert len(a) <= 1000 and np.array_equal(a, b)
    method = CompletionMethod()
    one, other = method.estimate(pts), method.estimate(shuffled)
    assert one.coverage == pytest.approx(other.coverage, abs=1e-6)
    assert 1 - one.coverage == pytest.approx(R * 1.0 * 20.0 / (2 * np.pi * R * 63.0), abs=0.03)  # the window
    assert one.centerline.shape == other.centerline.shape and one.holes.shape == other.holes.shape
    np.testing.assert_allclose(one.centerline, other.centerline, atol=1e-3)   # mm: float32 rounding
    np.testing.assert_allclose(one.holes, other.holes, atol=1e-3)


def test_the_methods_built_on_the_network_share_its_prediction_of_a_dense_cloud():
    # a tube scanned at 10 points/mm^2: completion thins it before the network; thresholding and unwrapping
    # take the same prediction (one network run) and report its line, while counting on every point
    from colonbench.baselines.threshold import ThresholdMethod
    from colonbench.baselines.unwrap import UnwrapMethod
    from colonbench.completion.method import method_cloud, shared_predictor
    from colonbench.completion.surface import cloud_density
    from colonbench.meshes import sample_surface

    colon = tube_colon(straight(63.0), R, ring_spacing_mm=0.5, n_around=256)
    pts = sample_surface(np.random.default_rng(4), colon.mesh.vertices, colon.mesh.faces, 10.0)
    theta = np.arctan2(pts[:, 1], pts[:, 0])
    pts = pts[~((np.abs(theta) < 0.5) & (pts[:, 2] > 20) & (pts[:, 2] < 40))]
    assert cloud_density(pts) > 8 and len(method_cloud(pts)) < len(pts) / 4
    predictor = shared_predictor()
    predictor._cache.clear()
    full = CompletionMethod().estimate(pts)
    unwrap, thresholding = UnwrapMethod().estimate(pts), ThresholdMethod().estimate(pts)
    assert len(predictor._cache) == 1                                  # the network ran once
    np.testing.assert_allclose(unwrap.centerline, full.centerline, atol=0.05)   # the line completion reports
    window = R * 1.0 * 20.0 / (2 * np.pi * R * 63.0)
    for est in (full, unwrap):                                         # (thresholding errs on its own)
        assert 1 - est.coverage == pytest.approx(window, abs=0.04)
    assert np.isfinite(thresholding.coverage)
    assert "thin_above=3" in UnwrapMethod().version and "thin_above=3" in ThresholdMethod().version


def test_the_orientation_probe_cycles_the_grid_axes_and_reproduces_the_method_on_the_fitted_grid():
    # scripts/probe_orientation.py: a straight tube along z with a window of known area; on the grid as fitted
    # the probe's estimate is the method's, and the cycled grids put the tube's axis third, then second
    import importlib.util
    from pathlib import Path

    from colonbench.completion.method import method_cloud
    from colonbench.meshes import sample_surface

    spec = importlib.util.spec_from_file_location(
        "probe_orientation", Path(__file__).resolve().parents[1] / "scripts" / "probe_orientation.py")
    probe = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(probe)
    colon = tube_colon(straight(63.0), R, ring_spacing_mm=0.5, n_around=256)
    pts = sample_surface(np.random.default_rng(2), colon.mesh.vertices, colon.mesh.faces, 2.0)
    theta = np.arctan2(pts[:, 1], pts[:, 0])
    pts = method_cloud(pts[~((np.abs(theta) < 0.5) & (pts[:, 2] > 20) & (pts[:, 2] < 40))])
    method = CompletionMethod()
    options = method.predictor.grid_options
    for shift, row in ((0, 0), (1, 2), (2, 1)):
        rot = probe.cycled_grid(pts, options, shift).rotation
        assert abs(rot[row] @ [0.0, 0.0, 1.0]) > 0.999 and np.allclose(rot @ rot.T, np.eye(3))
    fitted = probe.estimate_on_cycled_grid(method, pts, 0)
    assert fitted.coverage == pytest.approx(method.estimate(pts).coverage, abs=1e-3)
    assert 1 - fitted.coverage == pytest.approx(R * 1.0 * 20.0 / (2 * np.pi * R * 63.0), abs=0.03)  # the window
    assert all(0.0 <= probe.estimate_on_cycled_grid(method, pts, k).coverage <= 1.0 for k in (1, 2))


def test_symmetries_keep_the_tube_axis_and_come_back_exactly():
    import torch

    from colonbench.completion.symmetry import SYMMETRIES, averaged, transform

    x = torch.arange(4 * 5 * 5, dtype=torch.float32).reshape(1, 1, 4, 5, 5)   # a different length along the axis
    moved = [transform(x, s) for s in SYMMETRIES]
    assert all(m.shape == x.shape for m in moved)                  # the first (tube) axis stays the first
    assert len({m.numpy().tobytes() for m in moved}) == 16         # 16 distinct symmetries
    assert all(torch.equal(transform(m, s, inverse=True), x) for m, s in zip(moved, SYMMETRIES))
    assert torch.equal(averaged(lambda t: t + 1, x, 8), x + 1)     # an equivariant map is its own average
    w = torch.rand(1, 1, 4, 5, 5)                                  # one that is not: a fixed weight grid
    # K = 2 adds the half turn about the axis, flip(x, (3, 4)): the mean of x w and x flip(w, (3, 4))
    assert torch.allclose(averaged(lambda t: t * w, x, 2), x * (w + torch.flip(w, dims=(3, 4))) / 2)
    # K = 4 the quarter turns: w averaged over the four rotations of its cross-section
    rotations = sum(torch.rot90(w, r, dims=(3, 4)) for r in range(4)) / 4
    assert torch.allclose(averaged(lambda t: t * w, x, 4), x * rotations)


def test_the_prediction_averaged_over_symmetries_is_the_mean_of_the_moved_predictions():
    import torch

    from colonbench.completion.method import Predictor
    from colonbench.completion.symmetry import SYMMETRIES, transform
    from colonbench.heatmaps import input_from_points

    colon = tube_colon(straight(50.0), R, ring_spacing_mm=1.0, n_around=96)
    pts = check_cloud(colon.mesh.vertices[colon.mesh.vertices[:, 0] > -10])    # a wall seen mostly from one side
    four = Predictor(tta=4)
    assert four.version.endswith(",tta=4") and Predictor().version == four.version[: -len(",tta=4")]
    p = four(pts)
    x = torch.from_numpy(input_from_points(p.grid, pts)[0][None, None])
    with torch.inference_mode():
        mean = sum(transform(four.net(transform(x, s)), s, inverse=True) for s in SYMMETRIES[:4]) / 4
    np.testing.assert_allclose(p.heatmap, np.clip(mean[0, 0].numpy(), 0, 1), atol=1e-5)
    assert not np.allclose(p.heatmap, Predictor()(pts).heatmap, atol=1e-3)    # the network is not equivariant
    assert "tta=4" in CompletionMethod(tta=4).version
    for bad in (3, 0, 4.5, True, "4"):
        with pytest.raises(InputError, match="tta must be one of 1, 2, 4, 8, 16"):
            CompletionMethod(tta=bad)


def test_the_methods_on_the_network_share_the_averaged_prediction():
    from colonbench.benchmark.registry import load_method

    averaged = load_method("thresholding", tta=4)
    assert averaged.predictor is CompletionMethod(tta=4.0).predictor is load_method("unwrap", tta=4).predictor
    assert averaged.predictor is not CompletionMethod().predictor
    assert "tta=4" in averaged.version and "tta" not in load_method("thresholding").version
    assert load_method("poisson", tta=4).version == load_method("poisson").version   # no network: not offered


def test_a_clouds_prediction_does_not_depend_on_what_came_before_it_in_the_process():
    """The first cloud a predictor sees runs the same network as every later one (the eager network's sums differ
    from the fast one's in the last bits, which the steps after it can turn into a whole vertex or voxel)."""
    from colonbench.completion.method import Predictor

    colon = tube_colon(straight(50.0), R, ring_spacing_mm=1.0, n_around=96)
    a = check_cloud(colon.mesh.vertices[colon.mesh.vertices[:, 0] > -10])
    b = check_cloud(colon.mesh.vertices[colon.mesh.vertices[:, 2] < 35])
    first = Predictor()(a).heatmap
    later = Predictor()
    later(b)
    assert np.array_equal(later(a).heatmap, first)
