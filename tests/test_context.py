"""The in-context model: its slab and grid on known shapes, context packs cut from whole colons, training and
mapping with it."""

import json

import numpy as np
import pytest
from shapes import arc, straight

from colonbench.errors import InputError
from colonbench.slab import Slab, context_grid, context_rotation, slab_occupancy

torch = pytest.importorskip("torch")
pytest.importorskip("monai")

GRID = {"size": 48, "margin": 4, "min_extent_mm": 70.0}


def _cylinder(radius, z0, z1, n=4000, side=None, seed=0):
    """Points on the wall of a cylinder about z between z0 and z1 (``side``: only angles in that range)."""
    rng = np.random.default_rng(seed)
    lo, hi = side or (0.0, 2 * np.pi)
    a = rng.uniform(lo, hi, n)
    return np.stack([radius * np.cos(a), radius * np.sin(a), rng.uniform(z0, z1, n)], axis=1)


def _centres(grid):
    r = np.arange(grid.size, dtype=float)
    return grid.to_mm(np.stack(np.meshgrid(r, r, r, indexing="ij"), axis=-1).reshape(-1, 3)).reshape(
        (grid.size,) * 3 + (3,))


def test_the_slab_of_a_straight_tube_is_the_stretch_between_its_planes():
    line = straight(200.0)
    on = (line.arclength >= 45) & (line.arclength <= 135)
    slab = Slab(line.points[on], line.arclength[on], 60.0, 120.0)
    pts = _cylinder(15.0, 45.0, 135.0)
    grid = context_grid(pts, slab, **GRID)
    # the grid's first axis is the tube's, and the centerline and every point lie inside it
    assert abs(grid.rotation[0] @ [0, 0, 1]) == pytest.approx(1.0, abs=1e-9)
    for p in (pts, slab.line):
        v = grid.to_voxel(p)
        assert v.min() > 0 and v.max() < grid.size - 1
    z = _centres(grid)[..., 2]
    occ = slab_occupancy(grid, slab)
    clear = (np.abs(z - 60) > 0.5) & (np.abs(z - 120) > 0.5)  # the line's points are 0.5 mm apart
    np.testing.assert_array_equal(occ[clear], ((z >= 60) & (z <= 120))[clear])
    assert 0 < occ.mean() < 1
    # the segment alone (no context): voxels past either end are outside, not given to the end point
    alone = (line.arclength >= 60) & (line.arclength <= 120)
    occ0 = slab_occupancy(grid, Slab(line.points[alone], line.arclength[alone], 60.0, 120.0))
    np.testing.assert_array_equal(occ0[clear], ((z >= 60) & (z <= 120))[clear])


def test_the_slab_of_a_bend_follows_the_nearest_point_of_its_centerline():
    """A quarter circle of radius 60 mm: a voxel belongs to the segment where its angle does."""
    line = arc(60.0, np.pi / 2)
    slab = Slab(line.points, line.arclength, 60.0 * 0.4, 60.0 * 1.1)  # angles 0.4 to 1.1 rad
    ang = line.arclength / 60.0
    pts = np.concatenate([(60 + 15 * np.cos(b)) * np.stack([np.cos(ang), np.sin(ang), 0 * ang], 1)
                          + 15 * np.sin(b) * np.array([0, 0, 1.0]) for b in np.linspace(0, 2 * np.pi, 24)])
    grid = context_grid(pts, slab, **GRID)
    c = _centres(grid)
    theta = np.arctan2(c[..., 1], c[..., 0])
    near = np.hypot(c[..., 0], c[..., 1]) > 20  # away from the circle's centre, where every angle is near
    clear = near & (np.abs(theta - 0.4) > 0.02) & (np.abs(theta - 1.1) > 0.02) & (theta > 0.05) & (theta < 1.5)
    occ = slab_occupancy(grid, slab)
    np.testing.assert_array_equal(occ[clear], ((theta >= 0.4) & (theta <= 1.1))[clear])


def test_a_short_wide_segment_in_context_takes_its_axis_from_its_centerline():
    """50 mm of a 40 mm-radius cylinder with a third of its wall unseen: the grid's axis is the tube's within 2
    degrees, where the cloud's largest spread runs across it."""
    from colonbench.grid import principal_axes

    axis = np.array([1.0, 2.0, 2.0]) / 3.0
    rot = np.linalg.qr(np.stack([axis, [0, 1.0, 0], [0, 0, 1.0]]).T)[0]
    rot = rot * np.sign(rot[:, 0] @ axis)  # first column along the axis
    frame = np.stack([rot[:, 1], rot[:, 2], rot[:, 0]], axis=1)  # local z -> axis
    pts = _cylinder(40.0, 0.0, 50.0, side=(0.0, 4.2)) @ frame.T
    t = np.linspace(-10.0, 60.0, 141)
    slab = Slab(np.outer(t, axis), t, 0.0, 50.0)
    angle = np.degrees(np.arccos(min(1.0, abs(context_rotation(pts, slab)[0] @ axis))))
    assert angle < 2.0
    assert np.degrees(np.arccos(abs(principal_axes(pts)[0] @ axis))) > 20  # what the cloud alone would say


def test_the_stretch_of_a_straight_line_spans_the_segment_and_its_context():
    from colonbench.slab import point_at, stretch

    line = straight(200.0)  # points 0.5 mm apart along z
    slab = stretch(line.points, line.arclength, 60.0, 120.0, 15.0)
    assert (slab.lo, slab.hi) == (60.0, 120.0)
    assert slab.arc[0] == pytest.approx(44.5) and slab.arc[-1] == pytest.approx(135.5)  # one point past each end
    assert stretch(line.points, line.arclength, 0.0, 40.0, 15.0).arc[0] == 0.0  # clamped at the line's start
    np.testing.assert_allclose(point_at(line.points, line.arclength, 72.25), [0.0, 0.0, 72.25], atol=1e-9)
    np.testing.assert_allclose(point_at(line.points, line.arclength, 250.0), line.points[-1])


def test_a_slab_refuses_a_line_that_is_no_line():
    with pytest.raises(InputError, match="non-decreasing"):
        Slab(np.zeros((3, 3)), np.array([0.0, 2.0, 1.0]), 0.0, 1.0)
    with pytest.raises(InputError, match="hi > lo"):
        Slab(np.zeros((2, 3)), np.array([0.0, 1.0]), 1.0, 1.0)


def test_a_widened_segment_model_computes_what_it_did_until_trained():
    from dataclasses import replace

    from colonbench.completion.method import shipped_model
    from colonbench.completion.network import build_network, load_model, widen_inputs

    net, cfg, _ = load_model(shipped_model())
    wide = build_network(replace(cfg, in_channels=2))
    wide.load_state_dict(widen_inputs(net.state_dict(), 2))
    wide.eval()
    x = torch.rand(1, 1, 32, 32, 32)
    with torch.no_grad():
        np.testing.assert_array_equal(net(x).numpy(), wide(torch.cat([x, torch.rand_like(x)], 1)).numpy())


@pytest.fixture(scope="module")
def context_pack(tmp_path_factory):
    """Two short procedural colons (train, validation), one whole partial each, and their context pack."""
    from colonbench.mapping.contextpack import write_context_pack
    from colonbench.shards.dataset import generate

    manifest = {"name": "context-smoke", "seed": 5, "task": "colon",
                "grid": {"size": 32, "margin": 2, "min_extent_mm": 70.0},
                "config": {"colon": {"length_mm": [420, 480], "ring_spacing_mm": 1.0, "edge_mm": 1.5}},
                "splits": {"train": {"colons": {"first": 0, "count": 1}, "permutations": 1,
                                     "hole_models": {"spheres": 1.0}},
                           "validation": {"colons": {"first": 1, "count": 1}, "permutations": 1,
                                          "hole_models": {"camera": 1.0}}}}
    root = tmp_path_factory.mktemp("context")
    generate(manifest, root / "data", progress=False)
    info = write_context_pack(root / "data", root / "pack", progress=False)
    return root, info


def test_a_context_pack_holds_each_segment_with_its_slab(context_pack):
    from colonbench.completion.packdata import PackSplit
    from colonbench.mapping.contextpack import write_context_pack
    from colonbench.shards.pack import read_pack

    root, info = context_pack
    assert info["inputs"] == ["heatmap", "slab"] and info["grid_options"]["context"] is True
    for split in ("train", "validation"):
        # two passes over a 420-480 mm colon in 40-80 mm windows: 4 to 11 segments each
        assert 8 <= info["splits"][split]["samples"] <= 22
    assert 0.5 < info["train_coverage_mean"] < 1.0
    _, bits = read_pack(root / "pack", "train")
    ds = PackSplit(root / "pack", "train", "cpu")
    assert ds.in_channels == 2
    x, y = ds.batch([0, 1])
    assert x.shape == (2, 2, 32, 32, 32) and y.shape == (2, 1, 32, 32, 32)
    slab = torch.from_numpy(np.unpackbits(bits["slab"][:2], axis=1).reshape(2, 32, 32, 32).astype(np.float32))
    assert torch.equal(x[:, 1], slab)
    assert 0.1 < float(slab.mean()) < 0.9  # the segment and its context, or the segment and the grid's margin
    assert float(x[:, 0].min()) == 0.0  # the input heatmap: 0 on the points
    # the same dataset cuts the same pack; a pack is written whole
    again = write_context_pack(root / "data", root / "again", splits=("train",), progress=False)
    assert again["splits"]["train"]["sha256"] == info["splits"]["train"]["sha256"]
    with pytest.raises(InputError, match="written whole"):
        write_context_pack(root / "data", root / "pack", progress=False)


def test_a_context_pack_cut_along_the_maps_centerline_keeps_each_window_on_its_true_stretch(context_pack):
    """The map's own centerline (what inference cuts along): each window's truth is the true stretch between its
    ends, about as long as the window, and the window's points lie on it."""
    from scipy.spatial import cKDTree

    from colonbench.shards.colonshard import ColonShard
    from colonbench.mapping.contextpack import _map_line_samples, write_context_pack

    root, truth = context_pack
    shard = ColonShard(root / "data" / "train" / "colon-00000.h5")
    colon, smp = shard.colon(), shard.sample(0)
    cl = colon["centerline"]
    tree = cKDTree(cl.points)
    cuts = list(_map_line_samples(smp["points"], colon, smp["positions"], np.random.default_rng(0), {}))
    assert len(cuts) >= 4
    for pts, slab, (lo, hi), (a, b) in cuts:
        assert a <= lo < hi <= b
        assert abs((hi - lo) - (slab.hi - slab.lo)) < 0.25 * (slab.hi - slab.lo)
        s = cl.arclength[tree.query(pts)[1]]
        assert np.mean((s >= a - 5.0) & (s <= b + 5.0)) > 0.95
    info = write_context_pack(root / "data", root / "pack-map", splits=("train",), progress=False, line="map")
    assert info["context"]["line"] == "map" and truth["context"]["line"] == "truth"
    assert info["splits"]["train"]["skipped"] == {}
    n = truth["splits"]["train"]["samples"]
    assert abs(info["splits"]["train"]["samples"] - n) <= max(2, 0.25 * n)
    assert info["train_coverage_mean"] == pytest.approx(truth["train_coverage_mean"], abs=0.03)
    assert info["splits"]["train"]["sha256"] != truth["splits"]["train"]["sha256"]  # other slabs and grids
    with pytest.raises(InputError, match="context-line"):
        write_context_pack(root / "data", root / "pack-axis", progress=False, line="axis")


def test_context_packs_need_a_whole_colon_dataset_and_train_alone(context_pack, smoke_dataset, tmp_path):
    from colonbench.completion.packdata import PackSplit
    from colonbench.mapping.contextpack import write_context_pack
    from colonbench.shards.pack import write_pack

    root, _ = context_pack
    data, _ = smoke_dataset
    with pytest.raises(InputError, match="not a whole-colon dataset"):
        write_context_pack(data, tmp_path / "p", progress=False)
    write_pack(data, tmp_path / "segments", progress=False)
    with pytest.raises(InputError, match="another grid|context pack"):
        PackSplit([root / "pack", tmp_path / "segments"], "train", "cpu")


def test_an_in_context_model_trains_from_a_segment_model_and_maps_a_colon(context_pack):
    from colonbench.completion.method import CompletionMethod
    from colonbench.completion.network import load_model
    from colonbench.completion.train import TrainConfig, train
    from colonbench.mapping.colonmap import map_colon
    from colonbench.shards.colonshard import ColonShard

    root, _ = context_pack
    cfg = TrainConfig(network="small", epochs=1, batch_size=2, lr=1e-4, augment_prob=0.0, flips=True,
                      init="small", workers=0)
    train(root / "pack", root / "run", cfg, device="cpu", progress=False)
    path = root / "run" / "best.safetensors"
    _, net_cfg, meta = load_model(path)
    assert net_cfg.in_channels == 2 and meta["grid_options"]["context"] is True
    method = CompletionMethod(path)
    assert method.takes_slab
    shard = ColonShard(root / "data" / "validation" / "colon-00001.h5")
    pts = shard.sample(0)["points"]
    with pytest.raises(InputError, match="in-context model"):
        method.estimate(pts[:3000])
    result = map_colon(pts, method, segment_mm=60.0, progress=False, context_mm=5.0)
    done = [s for s in result["segments"] if s.coverage is not None]
    assert len(done) >= 0.75 * len(result["segments"]) >= 4
    line, s = result["centerline"], result["arclength"]
    from scipy.spatial import cKDTree
    for seg in done:
        v, f, _ = seg.mesh
        _, near = cKDTree(line).query(v[f].mean(axis=1))
        assert np.all((s[near] >= seg.start_mm - 1e-6) & (s[near] <= seg.end_mm + 1e-6))  # clipped to its stretch
        assert 0.0 <= seg.coverage <= 1.0
    assert json.dumps(meta["train_config"]["init"]) == '"small"'
    # as the context model of the segment model: the tracks with context are its, the segment-only one is not
    both = CompletionMethod("small", context_model=path)
    assert both.takes_slab and not both.needs_slab and "context=best@" in both.version
    again = map_colon(pts, both, segment_mm=60.0, progress=False, context_mm=5.0)
    # (the same network: its first call is eager, the next ones optimized for inference, equal to 1e-5)
    assert [s.coverage for s in again["segments"]] == pytest.approx([s.coverage for s in result["segments"]],
                                                                    abs=1e-4)
    alone = map_colon(pts, both, segment_mm=60.0, progress=False, context_mm=0.0)
    plain = map_colon(pts, CompletionMethod("small"), segment_mm=60.0, progress=False, context_mm=0.0)
    assert [s.coverage for s in alone["segments"]] == pytest.approx([s.coverage for s in plain["segments"]],
                                                                    abs=1e-4)
    with pytest.raises(InputError, match="not an in-context model"):
        CompletionMethod("small", context_model="small")
