"""Shards on real HDF5 files: every field round-trips, bytes do not depend on workers, runs resume, faults are named."""

import json
import os
import pickle
import shutil
import signal
import subprocess
import sys
import time

import h5py
import numpy as np
import pytest

from colonbench.augment import AugmentConfig
from colonbench.cli import main
from colonbench.datagen.generate import GeneratorConfig, colon_samples, procedural_colon
from colonbench.errors import InputError
from colonbench.shards import schema
from colonbench.shards.dataset import LOCK_NAME, generate
from colonbench.shards.manifest import draw_mix, load, resolve, units
from colonbench.shards.reader import Shard, ShardDataset
from colonbench.shards.verify import verify
from colonbench.shards.writer import ShardWriter
from conftest import MANIFESTS


def shas(lock):
    return {k: v["sha256"] for k, v in lock["shards"].items()}


def synthetic_rows(rng, size=8):
    """Two segments and three samples of random values shaped as the schema says."""
    segs, samples = [], []
    for m in range(2):
        nv, nf = 30 + m, 50 + m
        segs.append(dict(segment_id=5 + m, window_mm=rng.uniform(0, 900, 2), complete_area_mm2=rng.uniform(1e3, 1e4),
                         vertices=rng.normal(size=(nv, 3)).astype(np.float32),
                         faces=rng.integers(0, nv, (nf, 3)).astype(np.int32),
                         centerline=rng.normal(size=(40 + m, 3)).astype(np.float32)))
    for i, m in enumerate([0, 1, 1]):
        samples.append(dict(s0=rng.integers(1, 256, size ** 3 // 8).astype(np.uint8),
                            s1=rng.integers(1, 256, size ** 3 // 8).astype(np.uint8),
                            c=rng.integers(1, 256, size ** 3 // 8).astype(np.uint8),
                            grid_affine=rng.normal(size=(4, 4)), segment=m, permutation=i, hole_model=i % 3,
                            noise_mm=np.float32(0.5 * i), coverage=rng.uniform(), outside_grid=np.float32(0.01 * i),
                            observed_faces=rng.integers(0, 2, 50 + m).astype(bool),
                            partial_points=rng.normal(size=(100 + i, 3)).astype(np.float32),
                            hole_points=rng.normal(size=(i * 7, 3)).astype(np.float32),  # sample 0 has no hole
                            hole_areas_mm2=rng.uniform(1, 50, i).astype(np.float32)))
    return segs, samples


def shard_attrs(n_samples, n_segments, size, split="test"):
    return {"format": schema.FORMAT, "format_version": schema.FORMAT_VERSION, "generator_version": "test",
            "manifest_name": "t", "manifest_sha256": "0" * 64, "config_sha256": "1" * 64, "seed": 0,
            "split": split, "colon_id": 3, "length_mm": 60.0, "grid_size": size, "grid_margin": 1,
            "grid_min_extent_mm": 70.0,
            "heatmap_scale": 0.2, "n_samples": n_samples, "n_segments": n_segments}


@pytest.mark.parametrize("split", ["test", "train"])
def test_every_field_round_trips(tmp_path, split):
    rng = np.random.default_rng(0)
    segs, samples = synthetic_rows(rng)
    path = tmp_path / "s.h5"
    quantized = split in schema.QUANTIZED_SPLITS
    with ShardWriter(path, len(samples), 8, quantize=quantized) as w:
        for s in segs:
            w.add_segment(**s)
        for s in samples:
            w.add_sample({g: s[g] for g in schema.OCCUPANCIES},
                         **{k: v for k, v in s.items() if k not in schema.OCCUPANCIES})
        w.close(shard_attrs(len(samples), len(segs), 8, split))
    with h5py.File(path) as h5:
        assert schema.check(h5) == []
    covered = set()
    with Shard(path) as shard:
        assert len(shard) == 3
        for i, s in enumerate(samples):
            got = shard.sample(i)
            seg = segs[s["segment"]]
            expected = {**{f"segments/{k}": v for k, v in seg.items()},
                        **{f"samples/{k}": v for k, v in s.items()}}
            expected["samples/hole_model"] = ["camera", "spheres", "camera+spheres"][s["hole_model"]]
            for path_, value in expected.items():
                name = path_.split("/")[1]
                key = name if name in got else None
                if name == "segment":  # the row reference is resolved into the segment's own fields
                    assert got["segment_id"] == seg["segment_id"]
                    covered.add(path_)
                    continue
                assert key is not None, f"{path_} not returned by the reader"
                if isinstance(value, str):
                    assert got[key] == value
                elif quantized and name in ("partial_points", "hole_points"):  # micrometres, float32 back
                    assert got[key].dtype == np.float32 and got[key].shape == value.shape
                    np.testing.assert_allclose(got[key], value, rtol=0, atol=0.5e-3 + 1e-6, err_msg=path_)
                else:
                    np.testing.assert_array_equal(np.asarray(got[key]), np.asarray(value).astype(
                        np.asarray(got[key]).dtype), err_msg=path_)
                covered.add(path_)
        assert shard.grid(2).affine.tolist() == samples[2]["grid_affine"].tolist()
        assert shard.sample(0)["input"].shape == (8, 8, 8)  # made from the stored grids
    assert covered == {f.path for f in schema.FIELDS}


def test_writer_publishes_nothing_when_interrupted(tmp_path):
    path = tmp_path / "x.h5"
    with pytest.raises(ZeroDivisionError):
        with ShardWriter(path, 2, 8) as w:
            w.add_segment(segment_id=0, window_mm=[0, 1], complete_area_mm2=1.0, vertices=np.zeros((3, 3)),
                          faces=[[0, 1, 2]], centerline=np.zeros((2, 3)))
            1 / 0
    assert list(tmp_path.iterdir()) == []


def test_stored_samples_are_the_generator_samples(smoke_dataset):
    # the stream of (colon, length, segment, permutation) is the same as `colonbench segments` draws
    out, lock = smoke_dataset
    resolved = load(out / "manifest.yaml")
    config = GeneratorConfig.from_dict(resolved["config"])
    name = next(k for k, v in lock["shards"].items() if v["split"] == "test")
    with Shard(out / name) as shard:
        colon = procedural_colon(config, resolved["seed"], shard.attrs["colon_id"])
        for i in range(len(shard)):
            geo = shard.geometry(i)
            (_, _, sample), = colon_samples(colon, config, resolved["seed"], shard.attrs["colon_id"], 60.0, 1,
                                            geo["hole_model"], [geo["segment_id"]])
            assert geo["coverage"] == sample.coverage
            np.testing.assert_array_equal(geo["partial_points"], sample.partial_points.astype(np.float32))
            np.testing.assert_array_equal(geo["observed_faces"], sample.observed_faces)
            assert geo["window_mm"].tolist() == list(sample.window)
            # the grid comes from the partial points alone and holds the whole segment here
            ijk = shard.grid(i).to_voxel(geo["partial_points"])
            assert ijk.min() >= 4 - 1e-6 and ijk.max() <= 59 + 1e-6
            h_in, h_t = shard.heatmaps(i)
            assert h_in.min() == 0 and h_t.max() == pytest.approx(1.0, abs=1e-3)


def test_same_bytes_for_one_two_workers_and_a_dask_cluster(smoke_dataset, tmp_path):
    out, lock = smoke_dataset
    two = generate(MANIFESTS / "smoke.yaml", tmp_path / "two", workers=2, progress=False)
    assert shas(two) == shas(lock)
    from distributed import LocalCluster

    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster:
        dask = generate(MANIFESTS / "smoke.yaml", tmp_path / "dask", scheduler=cluster.scheduler_address,
                        progress=False)
    assert shas(dask) == shas(lock)
    assert (tmp_path / "dask" / LOCK_NAME).read_bytes() == (out / LOCK_NAME).read_bytes()


def test_killed_generation_resumes_to_the_same_checksums(smoke_dataset, tmp_path):
    _, lock = smoke_dataset
    dest = tmp_path / "killed"
    proc = subprocess.Popen([sys.executable, "-m", "colonbench.cli", "generate", str(MANIFESTS / "smoke.yaml"),
                             "--out", str(dest), "--quiet"], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.time() + 120
    while time.time() < deadline and not list(dest.glob("*/*.h5")):
        time.sleep(0.05)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    finished = list(dest.glob("*/*.h5"))
    assert 1 <= len(finished) < len(lock["shards"]), "the kill should land between the first and the last shard"
    assert not (dest / LOCK_NAME).exists()
    assert verify(dest) != []  # not a finished dataset yet, and verify says so
    resumed = generate(MANIFESTS / "smoke.yaml", dest, progress=False)
    assert shas(resumed) == shas(lock)
    assert verify(dest) == []
    assert not list(dest.rglob("*.tmp-*"))


def test_verify_names_corrupt_missing_and_foreign_files(smoke_dataset, tmp_path, capsys):
    out, lock = smoke_dataset
    bad = tmp_path / "bad"
    shutil.copytree(out, bad)
    assert verify(bad) == []
    names = list(lock["shards"])
    # flip bytes inside the first shard
    f0 = bad / names[0]
    data = bytearray(f0.read_bytes())
    mid = len(data) // 2
    data[mid: mid + 16] = bytes(b ^ 0xFF for b in data[mid: mid + 16])
    f0.write_bytes(bytes(data))
    (bad / names[1]).unlink()
    (bad / "train" / "stray.h5").write_bytes(b"not hdf5")
    faults = verify(bad)
    assert any(names[0] in f and "sha256" in f for f in faults)
    assert any(names[1] in f and "missing" in f for f in faults)
    assert any("stray.h5" in f and "not listed" in f for f in faults)
    assert main(["verify", str(bad)]) == 1
    assert "FAULT" in capsys.readouterr().out
    assert main(["verify", str(out)]) == 0


def test_verify_checks_the_schema_of_a_shard(smoke_dataset, tmp_path):
    out, lock = smoke_dataset
    f = tmp_path / "s.h5"
    shutil.copy(out / next(iter(lock["shards"])), f)
    assert verify(f) == []
    with h5py.File(f, "a") as h5:
        del h5["samples/coverage"]
        h5["segments/faces_offsets"][-1] = 3
    faults = verify(f)
    assert any("samples/coverage is missing" in x for x in faults)
    assert any("segments/faces_offsets" in x for x in faults)
    (tmp_path / "junk.h5").write_bytes(b"junk")
    assert "not a readable HDF5 file" in verify(tmp_path / "junk.h5")[0]


def test_dataset_reader_is_lazy_picklable_and_augments_deterministically(smoke_dataset):
    out, lock = smoke_dataset
    ds = ShardDataset(out, split="train")
    assert len(ds) == lock["splits"]["train"]["samples"]
    item = ds[1]
    assert item["input"].shape == (1, 64, 64, 64) and item["input"].dtype == np.float32
    clone = pickle.loads(pickle.dumps(ds))
    assert all(s._h5 is None for s in clone.shards)
    np.testing.assert_array_equal(clone[1]["target"], item["target"])
    # augmentation that changes nothing remakes the stored heatmaps (made as float16) from the stored geometry:
    # exactly from the test split's float32 points; from a training split's micrometres, the grid fitted to
    # points moved by up to half a micrometre flips a voxel here and there
    identity = AugmentConfig(scale=1.0, rotation_deg=0.0, deform_mm=0.0, noise_mm=0.0)
    for split, most in (("test", 0.0), ("train", 2e-3)):
        stored = ShardDataset(out, split=split)[1]
        same = ShardDataset(out, split=split, augment=identity)[1]
        for key in ("input", "target"):
            remade = same[key].astype(np.float16).astype(np.float32)
            assert np.mean(remade != stored[key]) <= most, (split, key)
            assert np.abs(remade - stored[key]).mean() <= most
    aug = ShardDataset(out, split="train", augment=AugmentConfig(), seed=3)
    a, b = aug[1], aug[1]
    np.testing.assert_array_equal(a["input"], b["input"])
    assert not np.array_equal(a["input"], item["input"])
    aug.set_epoch(1)
    assert not np.array_equal(aug[1]["input"], a["input"])
    assert 0 <= a["target"].min() and a["target"].max() <= 1
    geo = ShardDataset(out, split="test", geometry=True)[0]
    assert geo["partial_points"].shape[1] == 3 and geo["split"] == "test"


def test_shipped_manifests_spell_out_everything():
    import yaml

    for name in ("smoke", "demo", "paper"):
        raw = yaml.safe_load((MANIFESTS / f"{name}.yaml").read_text())
        resolved = resolve(raw)
        assert raw["config"] == resolved["config"], f"{name}.yaml does not spell out the full config"
    paper = load(MANIFESTS / "paper.yaml")
    n_lengths = len(paper["config"]["segments"]["lengths_mm"])
    counts = {k: v["colons"]["count"] * v["segments_per_length"] * n_lengths for k, v in paper["splits"].items()}
    assert counts == {"train": 10200, "validation": 3000, "test": 1200}
    assert paper["splits"]["train"]["permutations"] == paper["splits"]["validation"]["permutations"] == 15
    assert len(units(paper)) == 480 * 3


@pytest.mark.parametrize("change, message", [
    ({"splits": {"train": {"colons": {"first": 0, "count": 5}}, "test": {"colons": {"first": 4, "count": 2}}}},
     "overlap"),
    ({"splits": {"train": {"colons": {"first": 0, "count": 1}, "hole_models": {"laser": 1}}}}, "unknown hole model"),
    ({"splits": {"train": {"colons": [0, 1]}}}, "first: ID, count: N"),
    ({"splits": {"training": {"colons": {"first": 0, "count": 1}}}}, "unknown split"),
    ({"seed": -1}, "seed"),
    ({"colour": "red"}, "unknown key"),
    ({"config": {"colon": {"length_mm": [100, 200]}}}, "length_mm"),
])
def test_bad_manifests_get_clear_messages(change, message):
    base = {"name": "x", "seed": 1, "splits": {"test": {"colons": {"first": 0, "count": 1}}}}
    with pytest.raises(InputError, match=message):
        resolve({**base, **change})


def test_a_folder_of_another_dataset_and_another_version_are_refused(smoke_dataset, tmp_path):
    out, _ = smoke_dataset
    other = {"name": "other", "seed": 99, "splits": {"test": {"colons": {"first": 0, "count": 1}}}}
    with pytest.raises(InputError, match="another dataset"):
        generate(other, out, progress=False)
    with pytest.raises(InputError, match="written for colonbench 0.0.1"):
        generate({**other, "generator_version": "0.0.1"}, tmp_path / "v", progress=False)


def test_mix_draws_follow_their_weights():
    mix = {"camera": 0.25, "spheres": 0.75}
    draws = [draw_mix(mix, 5, "hole_model", 0, 60000, k, 0) for k in range(4000)]
    assert draws.count("spheres") / len(draws) == pytest.approx(0.75, abs=0.03)
    assert draws == [draw_mix(mix, 5, "hole_model", 0, 60000, k, 0) for k in range(4000)]


def test_cli_generate_splits_and_extend(tmp_path, capsys):
    dest = tmp_path / "d"
    assert main(["generate", str(MANIFESTS / "smoke.yaml"), "--out", str(dest), "--splits", "test", "--quiet"]) == 0
    lock = json.loads((dest / LOCK_NAME).read_text())
    assert set(lock["splits"]) == {"test"} and len(lock["missing"]) == 2
    assert main(["verify", str(dest)]) == 0
    assert main(["generate", str(MANIFESTS / "smoke.yaml"), "--out", str(dest), "--splits", "nope"]) == 2
    assert "not in manifest" in capsys.readouterr().err
    assert main(["generate", str(tmp_path / "nope.yaml"), "--out", str(dest)]) == 2
    assert "no such manifest file" in capsys.readouterr().err
    (tmp_path / "bad.yaml").write_text("name: [unclosed")
    assert main(["generate", str(tmp_path / "bad.yaml"), "--out", str(dest)]) == 2
    assert "not valid YAML" in capsys.readouterr().err
    assert (dest / "stats.png").stat().st_size > 10_000
    assert os.access(dest / "manifest.yaml", os.R_OK)
