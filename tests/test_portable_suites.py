"""Suites that verify on every machine: per-sample signatures with tolerances, a second machine played, archives."""

import functools
import http.server
import json
import shutil
import threading
from dataclasses import replace
from pathlib import Path

import h5py
import numpy as np
import pandas as pd
import pytest

from colonbench.benchmark import signature, suites, verification
from colonbench.cli import main
from colonbench.errors import InputError

DEMO = "demo-v1"


def _copy(demo_data, tmp_path, name="copy") -> Path:
    """A copy of the generated demo-v1 folder, to change."""
    data = tmp_path / name / DEMO
    shutil.copytree(suites.data_dir(suites.get(DEMO), demo_data), data)
    return data


def _relock(data: Path) -> None:
    """Record changed shard files in a suite copy's lock, as a generation that made them would have."""
    from colonbench.shards.dataset import LOCK_NAME
    from colonbench.shards.schema import sha256_file

    lock = json.loads((data / LOCK_NAME).read_text())
    for name, entry in lock["shards"].items():
        entry.update(bytes=(data / name).stat().st_size, sha256=sha256_file(data / name))
    (data / LOCK_NAME).write_text(json.dumps(lock))


def _cylinder(rng, n, radius=20.0):
    """(n, 3) points uniform on a cylinder of ``radius`` mm, 60 mm long, mm."""
    phi, z = rng.uniform(0, 2 * np.pi, n), rng.uniform(0, 60, n)
    return np.stack([radius * np.cos(phi), radius * np.sin(phi), z], axis=1) + [100.0, -50.0, 30.0]


# ------------------------------------------------------------------------------------------------ the sketch


def test_a_sketch_sees_a_point_moved_by_a_millimetre_and_not_float_noise():
    rng = np.random.default_rng(0)
    pts = _cylinder(rng, 20000).astype(np.float32).astype(float)
    base = signature.sketch(pts)
    ulps = pts + 3 * np.spacing(pts.astype(np.float32)).astype(float) * rng.choice([-1, 1], pts.shape)
    assert signature.displacement_mm(signature.sketch(ulps), base) < signature.TOLERANCES.points_mm / 2
    for d in rng.normal(size=(50, 3)):                                          # one point, 1 mm, any direction
        moved = pts.copy()
        moved[rng.integers(len(pts))] += d / np.linalg.norm(d)
        assert signature.displacement_mm(signature.sketch(moved), base) > 0.1
    swapped = pts.copy()
    swapped[[10, 15000]] = swapped[[15000, 10]]                                 # the order is part of the data
    assert signature.displacement_mm(signature.sketch(swapped), base) > signature.TOLERANCES.points_mm
    # a redraw of the same surface is the same distribution; the same count on a wider tube is not
    entry = signature.points_entry(pts)
    assert signature.z_score(signature.points_entry(_cylinder(rng, 20000)), entry) < signature.TOLERANCES.z
    assert signature.z_score(signature.points_entry(_cylinder(rng, 20000, radius=21.0)), entry) > signature.TOLERANCES.z


# ------------------------------------------------------------------------------------------------ a second machine


def _regenerate_first_shard(data: Path) -> str:
    """Remove the first shard of a suite copy and generate it again in this process; its name."""
    from colonbench.shards.dataset import LOCK_NAME, generate

    lock = json.loads((data / LOCK_NAME).read_text())
    name = sorted(lock["shards"])[0]
    (data / name).unlink()
    generate(suites.manifest_path(suites.get(DEMO)), data, workers=1, splits=["test"], progress=False)
    return name


def test_a_second_machine_played_verifies_and_a_changed_generator_does_not(demo_data, tmp_path, monkeypatch):
    suite = suites.get(DEMO)
    # float arrays moved by a few ulps, as another CPU's arithmetic moves them
    data = _copy(demo_data, tmp_path, "ulps")
    rng = np.random.default_rng(1)
    for shard in sorted((data / "test").glob("*.h5")):
        with h5py.File(shard, "r+") as h5:
            for path in ("samples/partial_points", "samples/hole_points", "segments/centerline"):
                a = h5[path][()]
                h5[path][...] = a + 3 * np.spacing(a) * rng.choice([-1, 1], a.shape).astype(a.dtype)
            cov = h5["samples/coverage"][()]
            h5["samples/coverage"][...] = cov - 4 * np.spacing(cov)
    _relock(data)
    result = suites.check(suite, data)
    assert result.verified and {s.level for s in result.samples} == {"same"}, result.summary()
    assert not result.bit_identical       # a 1 µm rounding edge was crossed somewhere: the exact hash moved

    # the observed flags of the faces nearest a visibility tie flipped, and the shard generated again from there
    from colonbench.datagen import camera

    real = camera.visible_faces

    def flip_nearest_ties(*args, **kwargs):
        seen, margin = real(*args, **{**kwargs, "margins": True})
        nearest = np.argsort(margin)[:3]
        seen[nearest] = ~seen[nearest]
        return seen

    data = _copy(demo_data, tmp_path, "ties")
    monkeypatch.setattr(camera, "visible_faces", flip_nearest_ties)
    name = _regenerate_first_shard(data)
    result = suites.check(suite, data)
    assert result.verified, result.summary()
    flipped = [s for s in result.samples if s.sample.startswith(f"test_{Path(name).stem}_")]
    assert any(s.level == "tie" for s in flipped) and all(s.level != "differs" for s in flipped)
    assert result.status == "within tolerance" and "near-tie" in result.summary()

    # a changed generator (a view cone 10 % narrower) is refused, naming the first sample it changed
    data = _copy(demo_data, tmp_path, "narrower")
    monkeypatch.setattr(camera, "visible_faces",
                        lambda scene, poses, fov_deg, *a, **k: real(scene, poses, 0.9 * fov_deg, *a, **k))
    name = _regenerate_first_shard(data)
    result = suites.check(suite, data)
    assert not result.verified and f"sample test_{Path(name).stem}_" in result.first_difference()
    with pytest.raises(InputError, match=rf"does not hold suite {DEMO}: .*sample test_{Path(name).stem}_\d+_noise0"):
        suites.verify(suite, data)


def test_what_must_still_fail(demo_data):
    suite = suites.get(DEMO)
    data = suites.data_dir(suite, demo_data)
    sha256, records, lock, _ = suites.identity(suite, data)
    published = suites.published_signature(suite)

    def check(recs=records, lk=lock):
        return verification.check_suite(published, lk, sha256, recs)

    assert check().verified
    dropped = check(records[:5] + records[6:])
    assert not dropped.verified and f"published {records[5]['sample']}" in dropped.first_difference()
    swapped = check([records[1], records[0]] + records[2:])
    assert not swapped.verified and "reordered" in swapped.first_difference()
    other_manifest = check(lk={**lock, "manifest_sha256": "0" * 64})
    assert not other_manifest.verified and "another manifest" in other_manifest.first_difference()
    other_config = check(lk={**lock, "config_sha256": "1" * 64})
    assert not other_config.verified and "another generator configuration" in other_config.first_difference()
    assert "another noise protocol" in verification.check_suite(published, lock, sha256, records, noise_mm=(0.0, 1.0),
                                                                 noise_seed=0).first_difference()
    # another noise draw: the noisy inputs are not the published ones, wherever the noiseless ones are
    _, noisier, _, _ = suites.identity(replace(suite, noise_seed=1), data)
    redrawn = check(noisier)
    assert not redrawn.verified and "input@0.5: points moved by" in redrawn.first_difference()
    # ... also in a sample decided otherwise at a near-tie, where the noiseless input came out the same
    tie = {**records[3], "coverage": records[3]["coverage"] + 2e-5, "observed_faces": records[3]["observed_faces"] + 1}
    assert signature.check_sample(tie, published["samples"][3]).level == "tie"
    noisy_tie = {**tie, "points": {**tie["points"], "input@0.5": noisier[3]["points"]["input@0.5"]}}
    result = signature.check_sample(noisy_tie, published["samples"][3])
    assert result.level == "differs" and "input@0.5" in result.what
    nan = signature.check_sample({**records[3], "coverage": float("nan")}, published["samples"][3])
    assert nan.level == "differs" and "coverage nan" in nan.what
    # an evaluation that goes on anyway says so in its record
    assert suites.verify(suite, data)["check"] in ("bit-identical", "within tolerance")


def test_suites_check_reports_each_cached_suite_and_fails_only_on_a_real_difference(demo_data, tmp_path, capsys):
    assert main(["suites", "--check", "--data", str(demo_data)]) == 0
    out = capsys.readouterr().out
    assert f"cite as {suites.get(DEMO).citation}" in out and f"{DEMO}: verified, " in out
    # only the named suites: listed and checked; an unknown one, or one with no data, is refused in a line
    assert main(["suites", "--check", "demo", "--data", str(demo_data)]) == 0
    out = capsys.readouterr().out
    assert f"{DEMO}: verified, " in out and "paper-v1" not in out
    for name, words in (("demo-v9", "unknown suite 'demo-v9'"), ("paper", "nothing to check: paper-v1 has no data")):
        assert main(["suites", "--check", DEMO, name, "--data", str(demo_data)]) == 2
        captured = capsys.readouterr()
        assert words in captured.err and "Traceback" not in captured.err and "verified" not in captured.out
    data = _copy(demo_data, tmp_path)
    shard = sorted((data / "test").glob("*.h5"))[1]
    with h5py.File(shard, "r+") as h5:
        h5["samples/coverage"][2] = h5["samples/coverage"][2] + 0.02          # two points of truth changed
    _relock(data)
    assert main(["suites", "--check", "--data", str(data.parent)]) == 1
    out = capsys.readouterr().out
    assert f"{DEMO}: differs: sample test_{shard.stem}_002_noise0: coverage" in out


# ------------------------------------------------------------------------------------------------ archives


@pytest.fixture
def http_folder(tmp_path, monkeypatch):
    """A local HTTP server over a folder: (folder, base URL)."""
    folder = tmp_path / "www"
    folder.mkdir()
    monkeypatch.setenv("NO_PROXY", "127.0.0.1,localhost")
    handler = functools.partial(http.server.SimpleHTTPRequestHandler, directory=str(folder))
    handler.log_message = lambda *a, **k: None
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), handler)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    yield folder, f"http://127.0.0.1:{server.server_address[1]}"
    server.shutdown()


def _rows(run: Path, method: str) -> pd.DataFrame:
    return pd.read_csv(run / "results" / f"{method}.csv").drop(columns="seconds")


def test_an_archive_served_over_http_is_fetched_and_scored_as_the_generated_suite(demo_data, tmp_path, http_folder,
                                                                                   capsys):
    www, url = http_folder
    assert main(["suites", "archive", DEMO, "--data", str(demo_data), "--out", str(www / "demo.tar")]) == 0
    sha = capsys.readouterr().out.split("sha256 ")[-1].split()[0]
    assert len(sha) == 64
    # written twice, the same bytes
    assert main(["suites", "archive", DEMO, "--data", str(demo_data), "--out", str(tmp_path / "again.tar"),
                 "--quiet"]) == 0
    assert (tmp_path / "again.tar").read_bytes() == (www / "demo.tar").read_bytes()

    cache = tmp_path / "cache"
    assert main(["suites", "fetch", DEMO, "--url", f"{url}/demo.tar", "--sha256", sha, "--data", str(cache),
                 "--quiet"]) == 0
    assert "verified against" in capsys.readouterr().out
    assert sorted(p.name for p in cache.iterdir()) == [DEMO]
    from colonbench.benchmark.evaluate import evaluate

    generated = evaluate(suites.data_dir(suites.get(DEMO), demo_data), ["constant", "unwrap-pca"], tmp_path / "a",
                         progress=False, examples=0)
    fetched = evaluate(cache / DEMO, ["constant", "unwrap-pca"], tmp_path / "b", progress=False, examples=0)
    for m in ("constant", "unwrap-pca"):
        pd.testing.assert_frame_equal(_rows(generated, m), _rows(fetched, m))
    run = json.loads((fetched / "run.json").read_text())
    assert run["suite"]["verified"] and run["suite"]["signature"] == suites.get(DEMO).signature
    assert "numpy_cpu_features" in run["environment"] and "trimesh" in run["versions"]

    # refused, leaving nothing: a wrong sha256, a truncated file, a file that is no archive
    data = (www / "demo.tar").read_bytes()
    (www / "short.tar").write_bytes(data[: len(data) // 2])
    (www / "junk.tar").write_bytes(b"not a tar file at all" * 100)
    import hashlib

    junk_sha = hashlib.sha256((www / "junk.tar").read_bytes()).hexdigest()
    empty = tmp_path / "empty"
    for name, digest, words in (("demo.tar", "0" * 64, "its sha256 is"), ("short.tar", sha, "its sha256 is"),
                                ("junk.tar", junk_sha, "not a readable suite archive")):
        assert main(["suites", "fetch", DEMO, "--url", f"{url}/{name}", "--sha256", digest, "--data", str(empty),
                     "--quiet"]) == 2
        assert words in capsys.readouterr().err
        assert not empty.exists() or not any(empty.iterdir()), list(empty.iterdir())

    # the right sha256 but data that do not verify: refused, nothing left; and no fetch over cached data
    import tarfile

    bad = tmp_path / "bad"
    with tarfile.open(www / "demo.tar") as tar:
        tar.extractall(bad)
    shard = sorted((bad / "test").glob("*.h5"))[0]
    with h5py.File(shard, "r+") as h5:
        h5["samples/coverage"][0] = h5["samples/coverage"][0] - 0.05
    _relock(bad)
    with tarfile.open(www / "bad.tar", "w") as tar:
        for f in sorted(bad.rglob("*")):
            if f.is_file():
                tar.add(f, arcname=f.relative_to(bad).as_posix())
    bad_sha = hashlib.sha256((www / "bad.tar").read_bytes()).hexdigest()
    assert main(["suites", "fetch", DEMO, "--url", f"{url}/bad.tar", "--sha256", bad_sha, "--data", str(empty),
                 "--quiet"]) == 2
    assert f"do not verify against {suites.get(DEMO).signature}: sample test_{shard.stem}_000_noise0" in \
        capsys.readouterr().err
    assert not empty.exists() or not any(empty.iterdir())
    assert main(["suites", "--data", str(cache), "fetch", DEMO, "--url", f"{url}/demo.tar", "--sha256", sha,
                 "--quiet"]) == 2
    assert "exists" in capsys.readouterr().err and (cache / DEMO / "suite.json").is_file()

    # a suite whose registry entry names the archive is fetched, not generated
    published = replace(suites.get(DEMO), archive_url=f"{url}/demo.tar", archive_sha256=sha)
    where = suites.ensure_data(published, tmp_path / "registry", progress=False)
    assert (where / "suite.json").is_file() and suites.check(published, where).verified


def test_a_subset_shard_keeps_its_samples_under_their_ids_and_readers_take_only_those(demo_data, tmp_path):
    from colonbench.benchmark.evaluate import select
    from colonbench.shards.reader import Shard
    from colonbench.shards.subset import write_subset
    from colonbench.shards.verify import verify

    data = _copy(demo_data, tmp_path)
    name = sorted(p.relative_to(data).as_posix() for p in (data / "test").glob("*.h5"))[0]
    original = (data / name).read_bytes()
    (tmp_path / "whole.h5").write_bytes(original)
    write_subset(tmp_path / "whole.h5", data / name, [0, 2])
    assert (data / name).stat().st_size < len(original)
    with Shard(tmp_path / "whole.h5") as a, Shard(data / name) as b:
        for i in (0, 2):
            ga, gb = a.geometry(i), b.geometry(i)
            for key in ("partial_points", "hole_points", "centerline", "vertices", "faces", "observed_faces"):
                assert np.array_equal(ga[key], gb[key]), key
            assert np.array_equal(a.heatmaps(i)[1], b.heatmaps(i)[1]) and gb["coverage"] == ga["coverage"]
        assert len(b.geometry(1)["partial_points"]) == 0          # an emptied row
    lock = json.loads((data / "dataset.lock.json").read_text())
    lock["kept_samples"] = {name: [0, 2]}
    (data / "dataset.lock.json").write_text(json.dumps(lock))
    _relock(data)
    assert not verify(data)                                           # the schema holds
    _, picks = select(data, "test")
    assert dict(picks)[name] == [0, 2] and sum(len(i) for _, i in picks) == 24 - 2
    with pytest.raises(InputError, match="segment shard"):
        colon = tmp_path / "colon.h5"
        with h5py.File(colon, "w") as h5:
            h5.attrs["format"] = "colonbench-colon-shard"
        write_subset(colon, tmp_path / "sub.h5", [0])
