"""Point clouds for point-cloud networks: colonbench.shards.pointclouds on the smoke dataset."""

import pickle
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial import cKDTree

from colonbench.errors import InputError
from colonbench.shards.pointclouds import (PointCloudDataset, collate_points, fixed_size, resample_polyline,
                                           surface_sample)

ALL = ("partial", "complete", "holes", "centerline")

#: The example of docs/shards.md, "Point clouds for point-cloud networks" (``data``: a dataset folder).
EXAMPLE = '''\
import torch
from colonbench.shards.pointclouds import PointCloudDataset, collate_points

ds = PointCloudDataset(data, split="train", points=1024)            # items: "partial" (1024, 3) mm, "coverage", ...
loader = torch.utils.data.DataLoader(ds, batch_size=4, shuffle=True, collate_fn=collate_points)
point = torch.nn.Sequential(torch.nn.Linear(3, 32), torch.nn.ReLU())  # shared by every point
head = torch.nn.Sequential(torch.nn.Linear(32, 1), torch.nn.Sigmoid())
opt = torch.optim.Adam([*point.parameters(), *head.parameters()], lr=1e-3)
batch = next(iter(loader))
x = (batch["partial"] - batch["partial"].mean(dim=1, keepdim=True)) / 30.0  # (B, N, 3), centred, ~unit scale
pred = head(point(x).max(dim=1).values).squeeze(1)                 # max over points -> (B,) coverage
loss = torch.nn.functional.mse_loss(pred, batch["coverage"])
opt.zero_grad(); loss.backward(); opt.step()
'''


def stored(data, k):
    """Item ``k``'s stored geometry (through the reader, not the code under test)."""
    ds = PointCloudDataset(data, fields=())
    shard, i = ds.locate(k)
    return shard.geometry(i)


def rows(a):
    return {r.tobytes() for r in np.ascontiguousarray(a, np.float32)}


def test_items_have_fixed_shapes_dtypes_and_the_stored_values(smoke_dataset):
    data, _ = smoke_dataset
    ds = PointCloudDataset(data, points=512, fields=ALL, complete_points=300, hole_points=200, centerline_points=64)
    item, geo = ds[3], stored(data, 3)
    for key, n in (("partial", 512), ("complete", 300), ("holes", 200), ("centerline", 64)):
        assert item[key].shape == (n, 3) and item[key].dtype == np.float32, key
        assert np.isfinite(item[key]).all(), key
    assert item["partial_count"] == len(geo["partial_points"]) and type(item["partial_count"]) is int
    assert item["holes_count"] == len(geo["hole_points"]) > 0 and type(item["holes_count"]) is int
    assert item["coverage"] == geo["coverage"] and item["noise_mm"] == geo["noise_mm"]
    assert item["hole_model"] == geo["hole_model"] and item["index"] == 3
    assert rows(item["holes"]) <= rows(geo["hole_points"])
    # the centerline keeps its ends
    assert np.allclose(item["centerline"][[0, -1]], geo["centerline"][[0, -1]], atol=1e-4)
    # negative indices and split selection as in ShardDataset
    assert PointCloudDataset(data, fields=())[-1]["index"] == len(ds) - 1
    assert PointCloudDataset(data, split="train").shards[0].attrs["split"] == "train"


def test_partial_sample_is_distinct_stored_points(smoke_dataset):
    data, _ = smoke_dataset
    item, geo = PointCloudDataset(data, points=1024)[0], stored(data, 0)
    pts = geo["partial_points"]
    assert len(pts) > 1024 and len(rows(pts)) == len(pts)        # the stored cloud has no repeated rows
    dist, _ = cKDTree(pts).query(item["partial"])
    assert dist.max() == 0.0                                      # every sampled point IS a stored point
    assert len(rows(item["partial"])) == 1024                     # without replacement


def test_a_cloud_smaller_than_points_gives_all_its_points_plus_repeats(smoke_dataset):
    data, _ = smoke_dataset
    pts = stored(data, 2)["partial_points"]
    n = len(pts) + 500
    item = PointCloudDataset(data, points=n)[2]
    assert item["partial"].shape == (n, 3) and item["partial_count"] == len(pts)
    assert rows(item["partial"]) == rows(pts)                     # each stored point appears, nothing else
    assert len(np.unique(item["partial"], axis=0)) == len(pts)    # so 500 rows are repeats


def test_draws_are_reproducible_per_seed_epoch_and_item(smoke_dataset):
    data, _ = smoke_dataset
    a = PointCloudDataset(data, points=256, fields=ALL, seed=5)
    b = pickle.loads(pickle.dumps(PointCloudDataset(data, points=256, fields=ALL, seed=5)))  # as a worker gets it
    b[1]                                                          # another item read first changes nothing
    for key in ALL:
        assert np.array_equal(a[4][key], b[4][key]), key
    only = PointCloudDataset(data, points=256, seed=5)           # one field's draw does not depend on the others
    assert np.array_equal(only[4]["partial"], a[4]["partial"])
    first = a[4]
    a.set_epoch(1)
    again = a[4]
    for key in ("partial", "complete", "holes"):
        assert not np.array_equal(first[key], again[key]), key
    assert np.array_equal(first["centerline"], again["centerline"])  # no draw in it
    assert not np.array_equal(PointCloudDataset(data, points=256, seed=6)[4]["partial"], first["partial"])
    a.set_epoch(0)
    assert np.array_equal(a[4]["partial"], first["partial"])


def test_complete_samples_lie_on_the_stored_surface(smoke_dataset):
    data, _ = smoke_dataset
    geo = stored(data, 5)
    v, f = geo["vertices"].astype(float), geo["faces"]
    pts = PointCloudDataset(data, points=2000, fields=("complete",))[5]["complete"]
    edge = np.linalg.norm(v[f] - v[np.roll(f, 1, axis=1)], axis=2)
    dist, _ = cKDTree(v).query(pts)
    assert dist.max() <= edge.max() and np.median(dist) < np.median(edge)


def test_surface_sampling_is_uniform_by_area():
    # two triangles in the plane z = 0, of areas 1 and 3
    v = np.array([[0, 0, 0], [2, 0, 0], [0, 1, 0], [10, 0, 0], [16, 0, 0], [10, 1, 0]], float)
    f = np.array([[0, 1, 2], [3, 4, 5]])
    pts = surface_sample(np.random.default_rng(0), v, f, 20_000)
    assert pts.shape == (20_000, 3) and pts.dtype == np.float32 and (pts[:, 2] == 0).all()
    small = pts[:, 0] < 5
    assert abs(small.mean() - 0.25) < 0.015                      # sigma 0.003
    x, y = pts[:, 0] - np.where(small, 0, 10), pts[:, 1]
    assert (x >= -1e-6).all() and (y >= -1e-6).all()
    assert (x / np.where(small, 2, 6) + y <= 1 + 1e-6).all()       # inside its triangle
    assert np.isnan(surface_sample(np.random.default_rng(0), v, f[:0], 4)).all()


def test_centerline_resampling_is_even_by_arc_length():
    d = np.array([2.0, -1.0, 2.0]) / 3.0                          # a unit direction
    line = np.array([0.0, 1.0, 1.0, 5.0, 50.0, 100.0])[:, None] * d + [3.0, 4.0, 5.0]  # uneven, a repeated vertex
    out = resample_polyline(line, 11)
    assert out.shape == (11, 3) and out.dtype == np.float32
    assert np.allclose(np.linalg.norm(np.diff(out, axis=0), axis=1), 100.0 / 10, atol=1e-4)
    assert np.allclose(out[[0, -1]], line[[0, -1]], atol=1e-5)
    assert np.array_equal(resample_polyline(line[:1], 3), np.repeat(line[:1], 3, axis=0).astype(np.float32))


def test_empty_sets_are_nan_and_fixed_size_never_draws_outside():
    rng = np.random.default_rng(1)
    assert fixed_size(rng, np.zeros((0, 3)), 5).shape == (5, 3) and np.isnan(fixed_size(rng, np.zeros((0, 3)), 5)).all()
    pts = np.arange(12.0).reshape(4, 3)
    assert rows(fixed_size(rng, pts, 9)) == rows(pts) and rows(fixed_size(rng, pts, 2)) < rows(pts)


@pytest.mark.parametrize("kwargs, words", [({"points": 0}, "points must be an integer of at least 1"),
                                           ({"points": 2.5}, "points must be an integer"),
                                           ({"complete_points": -3}, "complete_points"),
                                           ({"fields": ("partial", "normals")}, "unknown field 'normals'")])
def test_bad_arguments_raise_one_line_input_errors(smoke_dataset, kwargs, words):
    data, _ = smoke_dataset
    with pytest.raises(InputError, match=words) as err:
        PointCloudDataset(data, **kwargs)
    assert "\n" not in str(err.value)


def test_a_dataloader_batch_and_collate(smoke_dataset):
    import torch

    data, _ = smoke_dataset
    ds = PointCloudDataset(data, split="train", points=128, fields=("partial", "holes", "centerline"))
    batch = next(iter(torch.utils.data.DataLoader(ds, batch_size=4, collate_fn=collate_points, num_workers=0)))
    assert batch["partial"].shape == (4, 128, 3) and batch["partial"].dtype == torch.float32
    assert batch["holes"].shape == (4, 128, 3) and batch["centerline"].shape == (4, 256, 3)
    for key, dtype in (("coverage", torch.float32), ("noise_mm", torch.float32), ("index", torch.int64),
                       ("partial_count", torch.int64), ("holes_count", torch.int64)):
        assert batch[key].shape == (4,) and batch[key].dtype == dtype, key
    assert batch["index"].tolist() == [0, 1, 2, 3]
    assert isinstance(batch["hole_model"], list) and len(batch["hole_model"]) == 4
    assert np.array_equal(batch["partial"][2].numpy(), ds[2]["partial"])


def test_the_module_does_not_import_torch():
    code = "import sys, colonbench.shards.pointclouds; assert 'torch' not in sys.modules"
    subprocess.run([sys.executable, "-c", code], check=True)


def test_the_docs_example_trains_one_step(smoke_dataset):
    data, _ = smoke_dataset
    space = {"data": str(data)}
    exec(EXAMPLE, space)
    assert space["batch"]["partial"].shape == (4, 1024, 3)
    assert np.isfinite(space["loss"].item()) and space["point"][0].weight.grad is not None


def test_the_docs_show_this_example():
    text = (Path(__file__).resolve().parents[1] / "docs" / "shards.md").read_text()
    assert "## Point clouds for point-cloud networks" in text and "```python\n" + EXAMPLE + "```" in text
