"""Format-2 shards: occupancy grids stored in place of the heatmaps, training splits' points in micrometres.

The smoke manifest is generated in both formats by the real generator; the heatmaps a reader makes from the
stored grids must be format 1's stored ones, and everything else the same data.
"""

import json

import h5py
import numpy as np
import pytest

from colonbench.errors import InputError
from colonbench.shards import schema
from colonbench.shards.build import build_shard
from colonbench.shards.manifest import load, units
from colonbench.shards.reader import Shard, ShardDataset
from colonbench.shards.verify import check_shard
from colonbench.shards.writer import quantize_points

from conftest import MANIFESTS


@pytest.fixture(scope="module")
def both_formats(smoke_dataset, tmp_path_factory):
    """(format-2 folder, format-1 folder, shard names): smoke.yaml made by generate and by format 1's writer."""
    data, _ = smoke_dataset
    old = tmp_path_factory.mktemp("format1")
    resolved = load(MANIFESTS / "smoke.yaml")
    names = []
    for u in units(resolved):
        build_shard(resolved, u, old, version=1)
        names.append(u.name)
    return data, old, names


def test_a_readers_heatmaps_are_format_1s_stored_ones_on_every_sample(both_formats):
    new, old, names = both_formats
    n = 0
    for name in names:
        with Shard(new / name) as a, Shard(old / name) as b:
            assert (a.version, b.version) == (2, 1)
            with h5py.File(old / name) as h5:
                stored = h5["samples/input"][()], h5["samples/target"][()]
            for i in range(len(a)):
                x, y = a.heatmaps(i)
                assert x.dtype == np.float32 and np.array_equal(x, stored[0][i].astype(np.float32))
                assert np.array_equal(y, stored[1][i].astype(np.float32))
                bits_a, bits_b = a.occupancy_bits(i), b.occupancy_bits(i)
                assert all(np.array_equal(bits_a[g], bits_b[g]) for g in schema.OCCUPANCIES)
                n += 1
    assert n == 8
    ds = ShardDataset(new, split="train")
    first = ds[1]["target"].copy()
    assert len(ds._cache) >= 1 and np.array_equal(ds[1]["target"], first)  # the second read comes from the cache
    shard, i = ds.locate(1)
    assert np.array_equal(first[0], Shard(old / shard.path.relative_to(new)).heatmaps(i)[1])
    # the cache holds what its size allows (1 MiB a sample: two 64^3 float16 heatmaps), and nothing at 0
    for mib, kept in ((1.5, 1), (0, 0)):
        small = ShardDataset(new, split="train", cache_mib=mib)
        for k in range(len(small)):
            small[k]
        assert len(small._cache) == kept
    with pytest.raises(InputError, match="cache_mib"):
        ShardDataset(new, split="train", cache_mib="lots")


def test_the_geometry_is_the_same_and_training_points_are_micrometres(both_formats):
    new, old, names = both_formats
    for name in names:
        with Shard(new / name) as a, Shard(old / name) as b:
            quantized = a.attrs["split"] in schema.QUANTIZED_SPLITS
            assert a.h5["samples/partial_points"].dtype == (np.int32 if quantized else np.float32)
            for i in range(len(a)):
                ga, gb = a.geometry(i), b.geometry(i)
                for key in ("partial_points", "hole_points"):
                    assert ga[key].dtype == np.float32 and ga[key].shape == gb[key].shape
                    if quantized:  # half a micrometre, plus float32's rounding of the decoded value
                        assert np.abs(ga[key].astype(float) - gb[key].astype(float)).max(initial=0) <= 0.5e-3 + 2e-5
                    else:  # the benchmark's inputs, bit for bit
                        assert np.array_equal(ga[key], gb[key])
                if quantized and len(gb["hole_points"]):
                    # a metric at a threshold sees the micrometres only where a distance is within one of it:
                    # a guess shifted by about the threshold puts many there, and moves a point or two
                    from colonbench.benchmark.metrics import precision_recall

                    guess = gb["hole_points"][::3] + np.random.default_rng(i).normal(0, 1.0, (1, 3))
                    for th in (1.0, 2.0):
                        p_a, r_a = precision_recall(guess, ga["hole_points"], th)
                        p_b, r_b = precision_recall(guess, gb["hole_points"], th)
                        assert abs(p_a - p_b) * len(guess) <= 3 and abs(r_a - r_b) * len(gb["hole_points"]) <= 3
                for key in ("vertices", "faces", "centerline", "observed_faces", "hole_areas_mm2", "grid_affine"):
                    assert np.array_equal(ga[key], gb[key]), key
                assert ga["coverage"] == gb["coverage"] and ga["outside_grid"] == gb["outside_grid"]


def test_quantized_points_hold_at_the_last_bit():
    rng = np.random.default_rng(3)
    x = (rng.random((5000, 3)) * 300 - 50).astype(np.float32)
    x[:10] = np.float32(12.0005)  # on a half-micrometre tie
    for moved in (x, np.nextafter(x, np.float32(np.inf)), np.nextafter(x, np.float32(-np.inf))):
        q, offset = quantize_points(moved)
        back = (q * schema.POINT_SCALE_MM + offset).astype(np.float32)
        assert q.dtype == np.int32 and np.all(offset == np.floor(offset))
        assert np.abs(back.astype(float) - moved.astype(float)).max() <= 0.5e-3 + 2e-5
    with pytest.raises(ValueError, match="too far"):
        quantize_points(np.array([[0, 0, 0], [3e6, 0, 0]], np.float32))


def test_verify_reads_both_formats_and_names_what_is_damaged(both_formats, tmp_path):
    new, old, names = both_formats
    for name in names:
        assert check_shard(new / name) == [] and check_shard(old / name) == []
    train = next(n for n in names if n.startswith("train/"))
    bad = tmp_path / "bad.h5"
    bad.write_bytes((new / train).read_bytes())
    with h5py.File(bad, "r+") as h5:
        h5["samples/s1"][1] = 0
        del h5["samples/hole_points"].attrs["offset_mm"]
    faults = check_shard(bad)
    assert any("hole_points lacks its scale_mm" in f for f in faults)
    with h5py.File(bad, "r+") as h5:
        h5["samples/hole_points"].attrs["offset_mm"] = np.zeros(3)
    assert check_shard(bad) == ["samples/s1[1] is empty (no occupied voxel: no heatmap can be made)"]
    with h5py.File(bad, "r+") as h5:
        h5.attrs["format_version"] = 3
    assert "a newer colonbench wrote it" in check_shard(bad)[0]
    with pytest.raises(InputError, match="reads versions 1, 2"):
        Shard(bad)


def test_generation_will_not_mix_formats_in_one_folder(both_formats, tmp_path):
    from colonbench.shards.dataset import generate

    new, _, _ = both_formats
    folder = tmp_path / "data"
    folder.mkdir()
    (folder / "manifest.yaml").write_bytes((new / "manifest.yaml").read_bytes())
    lock = json.loads((new / schema.LOCK_NAME).read_text())
    (folder / schema.LOCK_NAME).write_text(json.dumps({**lock, "shard_format_version": 1}))
    with pytest.raises(InputError, match="holds shards of format 1; this colonbench writes format 2"):
        generate(MANIFESTS / "smoke.yaml", folder, progress=False)


def test_a_pack_of_format_2_shards_is_their_grids(smoke_pack):
    from colonbench.shards.pack import read_pack, read_shard_bits

    data, _, out, info = smoke_pack
    for split in ("train", "validation"):
        _, bits = read_pack(out, split)
        shard_info, shard_bits = read_shard_bits(data, split)
        assert all(np.array_equal(bits[g], shard_bits[g]) for g in schema.OCCUPANCIES)
        assert shard_info["grid_options"] == info["grid_options"]
        assert info["splits"][split]["max_heatmap_difference"] == 0.0


def test_a_format_1_dataset_packs_to_the_same_grids_and_is_not_read_as_grids(both_formats, smoke_pack, tmp_path):
    from colonbench.shards.pack import CHECK_TOLERANCE, read_pack, read_shard_bits, write_pack

    new, old, _ = both_formats
    lock = json.loads((new / schema.LOCK_NAME).read_text())
    (old / schema.LOCK_NAME).write_text(json.dumps({**lock, "shard_format_version": 1}))
    info = write_pack(old, tmp_path / "pack1", progress=False)
    *_, pack2, _ = smoke_pack
    for split in ("train", "validation"):
        assert info["splits"][split]["shard_format"] == 1
        assert 0 < info["splits"][split]["max_heatmap_difference"] <= CHECK_TOLERANCE  # float16 against float32
        one, two = read_pack(tmp_path / "pack1", split)[1], read_pack(pack2, split)[1]
        assert all(np.array_equal(one[g], two[g]) for g in schema.OCCUPANCIES)
    with pytest.raises(InputError, match="a format-1 shard"):
        read_shard_bits(old, "train")


def _old_voxels(size, ijk):
    """Format 1's voxel rounding and occupancy, as they were written before the column-wise rewrite."""
    with np.errstate(invalid="ignore"):  # NaN and inf cast to int, as it did
        idx = np.rint(ijk).astype(np.int64)
    keep = np.all((idx >= 0) & (idx < size), axis=1)
    idx = idx[keep]
    occ = np.zeros((size,) * 3, dtype=bool)
    occ[idx[:, 0], idx[:, 1], idx[:, 2]] = True
    return occ, float(1.0 - keep.mean()) if len(keep) else 0.0


def _old_lattice(a, b, c, spacing):
    """Format 1's triangle lattice, as it was written before the rewrite (one triangle's points together)."""
    edges = np.stack([np.linalg.norm(b - a, axis=1), np.linalg.norm(c - b, axis=1),
                      np.linalg.norm(a - c, axis=1)], axis=1)
    n_sub = np.maximum(np.ceil(edges.max(axis=1) / spacing), 1).astype(np.int64)
    out = []
    for n in np.unique(n_sub):
        sel = n_sub == n
        i, j = np.meshgrid(np.arange(n + 1), np.arange(n + 1), indexing="ij")
        ok = (i + j) <= n
        u, v = (i[ok] / n)[:, None], (j[ok] / n)[:, None]
        w = 1.0 - u - v
        pts = w[None] * a[sel][:, None] + u[None] * b[sel][:, None] + v[None] * c[sel][:, None]
        out.append(pts.reshape(-1, 3))
    return np.concatenate(out)


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_the_triangle_lattice_is_format_1s_point_for_point(dtype):
    from colonbench.heatmaps import triangle_lattice

    rng = np.random.default_rng(9)
    a, b, c = (rng.normal(0, 2, (3000, 3)).astype(dtype) for _ in range(3))
    new, old = triangle_lattice(a, b, c, 0.5), _old_lattice(a, b, c, 0.5)
    assert new.dtype == old.dtype and new.shape == old.shape
    # the same points to the bit, in another order (a set, as voxelization takes it)
    assert np.array_equal(np.unique(new, axis=0), np.unique(old, axis=0))
    assert np.array_equal(np.sort(new.view(np.int64), axis=0), np.sort(old.view(np.int64), axis=0))


def test_voxel_rounding_is_the_one_format_1_was_made_with():
    from colonbench.grid import Grid
    from colonbench.heatmaps import occupancy, voxel_indices

    rng = np.random.default_rng(5)
    grid = Grid(np.eye(4), 16)
    ijk = rng.uniform(-3, 19, (4000, 3))
    ijk[:200] = np.round(ijk[:200] * 2) / 2                        # on the half-voxel ties rint rounds to even
    ijk[200:210] = [np.nan, 1, 1]
    ijk[210:220] = [np.inf, -np.inf, 2]
    ijk[220:230] = np.nextafter(15.5, 16)                          # a last-bit step over the far edge
    ijk[230:240] = np.nextafter(-0.5, -1)                          # and under the near one
    idx, outside = voxel_indices(grid, ijk)
    expected, expected_outside = _old_voxels(16, ijk)
    assert np.array_equal(occupancy(grid, idx), expected) and outside == expected_outside


def test_points_that_are_not_finite_are_refused_not_wrapped():
    with pytest.raises(ValueError, match="NaN or infinite"):
        quantize_points(np.array([[1, 2, 3], [np.nan, 0, 0]], np.float32))


def test_a_subset_of_a_training_shard_keeps_its_micrometres(both_formats, tmp_path):
    from colonbench.shards.subset import write_subset

    new, _, names = both_formats
    train = next(n for n in names if n.startswith("train/"))
    out = write_subset(new / train, tmp_path / "sub.h5", [1])
    assert check_shard(out) == []
    with Shard(new / train) as whole, Shard(out) as part:
        assert np.array_equal(part.geometry(1)["partial_points"], whole.geometry(1)["partial_points"])
        assert np.array_equal(part.heatmaps(1)[1], whole.heatmaps(1)[1])
        with pytest.raises(InputError, match="sample 0 has an empty s0 and s1 and c grid"):
            part.heatmaps(0)


def test_an_interrupted_format_1_run_is_finished_in_format_2(both_formats, tmp_path):
    from colonbench.shards.dataset import generate

    new, old, names = both_formats
    folder = tmp_path / "data"
    (folder / "train").mkdir(parents=True)
    (folder / "manifest.yaml").write_bytes((new / "manifest.yaml").read_bytes())
    train = next(n for n in names if n.startswith("train/"))
    (folder / train).write_bytes((old / train).read_bytes())     # left by a run of an older colonbench, no lock
    lock = generate(MANIFESTS / "smoke.yaml", folder, progress=False)
    assert lock["shard_format_version"] == 2 and Shard(folder / train).version == 2
    assert (folder / train).read_bytes() == (new / train).read_bytes()
