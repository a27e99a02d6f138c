"""Hidden suites (colonbench suites build hidden): inputs published as export writes them, truth and seeds kept
in the private folder, scored by colonbench score from there."""

from __future__ import annotations

import csv
import hashlib
import json

import pytest
from server_fixtures import write_predictions

from colonbench.cli import main


def _published_ids(public):
    with open(public / "index.csv") as f:
        return {r["sample_id"] for r in csv.DictReader(f)}


def test_published_inputs_hold_no_truth_and_no_seed(hidden_suite):
    sid, private, public, seed = hidden_suite
    from colonbench.benchmark import local_suites
    from colonbench.server import hidden

    suite = local_suites.load(private / sid)
    names = sorted(p.name for p in public.iterdir())
    assert all(n.endswith(".ply") for n in names if n not in ("index.csv", "suite.json", hidden.INPUTS_FILE))
    assert not list(public.rglob("*.h5")) and not list(public.rglob("*.yaml")) and not list(public.rglob("*.gz"))
    # neither seed, nor the signature's digest (of per-sample truth), nor the content hash is published
    secrets = [str(seed), str(suite.noise_seed), suite.signature, suite.sha256.removeprefix("cb1-")]
    for p in public.iterdir():
        data = p.read_bytes()
        for s in secrets:
            assert s.encode() not in data, (p.name, s)
    record = json.loads((public / "suite.json").read_text())
    assert record["suite"] == {"id": sid, "name": "tiny-hidden", "version": 1, "hidden": True, "samples": 2,
                               "noise_mm": [0.0, 0.5]}
    # the inputs are those of every evaluated cloud, with their digest
    assert _published_ids(public) == hidden.sample_ids(suite) and len(hidden.sample_ids(suite)) == 4
    inputs = json.loads((public / hidden.INPUTS_FILE).read_text())
    for name, digest in inputs["files"].items():
        assert hashlib.sha256((public / name).read_bytes()).hexdigest() == digest
    assert set(inputs["files"]) == set(names) - {hidden.INPUTS_FILE}
    entry = local_suites.read_entry(private / sid)
    assert entry["hidden"] is True and entry["inputs_sha256"] == inputs["inputs_sha256"]
    # the truth side keeps the seed (the only way to regenerate it)
    assert f"seed: {seed}" in (private / sid / "manifest.yaml").read_text()
    assert hidden.served([private]) == {sid: suite}


def test_hidden_suite_is_scored_from_the_private_folder(hidden_suite, tmp_path, capsys):
    sid, private, public, _ = hidden_suite
    preds = write_predictions(tmp_path / "preds", _published_ids(public))
    assert main(["score", sid, str(preds), "--out", str(tmp_path / "run"), "--data", str(private), "--quiet"]) == 0
    rows = list(csv.DictReader(open(tmp_path / "run" / "results" / "preds.csv")))
    assert len(rows) == 4 and {r["sample_id"] for r in rows} == _published_ids(public)
    assert all(r["error"] == "" for r in rows)


def test_the_id_depends_on_the_seed_and_not_on_the_publication(tmp_path):
    from colonbench.server import hidden
    from server_fixtures import SEED, tiny_manifest

    import yaml

    m = yaml.safe_load(tiny_manifest(tmp_path / "m.yaml").read_text())
    a = hidden.suite_id("x", m, SEED)
    assert a == hidden.suite_id("x", {**m, "seed": 1}, SEED) and a != hidden.suite_id("x", m, SEED + 1)
    assert hidden.MIN_SEED <= hidden.new_seed() < hidden.MAX_SEED


@pytest.mark.parametrize("text, says", [("5", "at least 2**40"), ("abc", "one integer"), (str(2 ** 63), "below")])
def test_weak_or_bad_seeds_are_refused(tmp_path, capsys, text, says):
    from server_fixtures import tiny_manifest

    (tmp_path / "seed").write_text(text)
    rc = main(["suites", "build", "hidden", "--from", str(tiny_manifest(tmp_path / "m.yaml")), "--data",
               str(tmp_path / "priv"), "--publish", str(tmp_path / "pub"), "--seed-file", str(tmp_path / "seed")])
    assert rc == 2 and says in capsys.readouterr().err
    assert not (tmp_path / "priv").exists() and not (tmp_path / "pub").exists()


def test_publishing_inside_the_private_folder_is_refused(tmp_path, capsys):
    from server_fixtures import tiny_manifest

    rc = main(["suites", "build", "hidden", "--from", str(tiny_manifest(tmp_path / "m.yaml")), "--data",
               str(tmp_path / "priv"), "--publish", str(tmp_path / "priv" / "pub")])
    assert rc == 2 and "inside --data" in capsys.readouterr().err


def test_keeping_the_truth_inside_the_published_folder_is_refused(tmp_path, capsys):
    from server_fixtures import tiny_manifest

    rc = main(["suites", "build", "hidden", "--from", str(tiny_manifest(tmp_path / "m.yaml")), "--data",
               str(tmp_path / "pub" / "priv"), "--publish", str(tmp_path / "pub")])
    assert rc == 2 and "inside --publish" in capsys.readouterr().err
    assert not (tmp_path / "pub").exists()      # refused before anything was built


def test_a_whole_colon_suite_is_refused(tmp_path, capsys):
    rc = main(["suites", "build", "hidden", "--from", "colon-v1", "--data", str(tmp_path / "p"), "--publish",
               str(tmp_path / "q")])
    assert rc == 2 and "segment manifests" in capsys.readouterr().err
    assert not (tmp_path / "p").exists() and not (tmp_path / "q").exists()


def _tube_manifest(folder):
    """A manifest naming one private mesh (a 200 mm tube written to PLY beside it, by relative path): two 50 mm
    segments of its test split."""
    import numpy as np
    import yaml
    from shapes import straight

    from colonbench.datagen.colon import tube_colon
    from colonbench.shards.schema import sha256_file

    folder.mkdir(parents=True)
    (folder / "meshes").mkdir()
    tube = tube_colon(straight(200.0), lambda s, theta: 15.0 + 0 * s + 0 * theta, ring_spacing_mm=1.0, n_around=64)
    tube.mesh.export(folder / "meshes" / "tube.ply")
    np.save(folder / "meshes" / "tube_mid.npy", straight(200.0).points)
    entry = {"id": 9000, "mesh": "meshes/tube.ply", "mesh_sha256": sha256_file(folder / "meshes" / "tube.ply"),
             "centerline": "meshes/tube_mid.npy", "centerline_sha256": sha256_file(folder / "meshes" / "tube_mid.npy")}
    manifest = {"name": "mine", "seed": 3, "generator_version": "0.2.0", "grid": {"axes": "tube"},
                "config": {"segments": {"lengths_mm": [50.0]}}, "meshes": {"tube": entry},
                "splits": {"test": {"colons": {"first": 0, "count": 0}, "meshes": ["tube"], "segments_per_length": 2,
                                    "permutations": 1, "hole_models": {"spheres": 1.0}}}}
    (folder / "mine.yaml").write_text(yaml.safe_dump(manifest))
    return folder / "mine.yaml", entry


def test_a_manifest_of_private_meshes_is_hidden(tmp_path, capsys):
    from colonbench.benchmark import local_suites
    from colonbench.server import hidden
    from server_fixtures import SEED

    path, entry = _tube_manifest(tmp_path / "mine")
    (tmp_path / "seed").write_text(str(SEED))
    private, public = tmp_path / "private", tmp_path / "public"
    run = tmp_path / "elsewhere"     # mesh paths are the manifest's folder's, not the current folder's
    run.mkdir()
    import os
    cwd = os.getcwd()
    os.chdir(run)
    try:
        assert main(["suites", "build", "hidden", "--from", str(path), "--data", str(private), "--publish",
                     str(public), "--seed-file", str(tmp_path / "seed"), "--quiet"]) == 0
    finally:
        os.chdir(cwd)
    (sid,) = [p.name for p in private.iterdir() if not p.name.startswith(".")]
    suite = local_suites.load(private / sid)
    assert sid.startswith("mine-hidden-") and suite.samples == 2 and hidden.is_hidden(suite)
    built = local_suites.read_entry(private / sid)
    assert built["source"] == {"meshes": {"tube": {"mesh_sha256": entry["mesh_sha256"],
                                                    "centerline_sha256": entry["centerline_sha256"]}}}
    # the private manifest has the secret seed and names the mesh by absolute path with its sha256, not a copy
    saved = (private / sid / "manifest.yaml").read_text()
    assert f"seed: {SEED}" in saved and str((tmp_path / "mine" / "meshes" / "tube.ply").resolve()) in saved
    assert entry["mesh_sha256"] in saved
    for folder in (private, public):
        assert not list(folder.rglob("*.npy")) and not list(folder.rglob("tube.ply"))
    # published: inputs only, no seed, no signature, no content hash, no mesh path
    assert _published_ids(public) == hidden.sample_ids(suite)
    for p in public.iterdir():
        data = p.read_bytes()
        for secret in (str(SEED), str(suite.noise_seed), suite.signature, suite.sha256.removeprefix("cb1-"),
                       "meshes/tube", entry["mesh_sha256"]):
            assert secret.encode() not in data, (p.name, secret)
    # the id does not depend on where the mesh lies; the seed makes it
    import yaml
    raw = yaml.safe_load(path.read_text())
    moved = {**raw, "meshes": {"tube": {**raw["meshes"]["tube"], "mesh": "/else/tube.ply"}}}
    assert hidden.suite_id("mine-hidden", moved, SEED) == sid != hidden.suite_id("mine-hidden", raw, SEED + 1)
    preds = write_predictions(tmp_path / "preds", _published_ids(public))
    assert main(["score", sid, str(preds), "--out", str(tmp_path / "run"), "--data", str(private), "--quiet"]) == 0


def test_a_mesh_that_is_not_the_manifests_is_refused(tmp_path, capsys):
    path, _ = _tube_manifest(tmp_path / "mine")
    (tmp_path / "mine" / "meshes" / "tube.ply").write_bytes(b"ply\n")
    rc = main(["suites", "build", "hidden", "--from", str(path), "--data", str(tmp_path / "p"), "--publish",
               str(tmp_path / "q")])
    err = capsys.readouterr().err
    assert rc == 2 and "meshes.tube.mesh" in err and "not the file the manifest names" in err, err
    (tmp_path / "mine" / "meshes" / "tube.ply").unlink()
    rc = main(["suites", "build", "hidden", "--from", str(path), "--data", str(tmp_path / "p"), "--publish",
               str(tmp_path / "q")])
    assert rc == 2 and "is not a file" in capsys.readouterr().err
    assert not (tmp_path / "p").exists() and not (tmp_path / "q").exists()


def test_a_malformed_mesh_entry_is_refused_as_every_manifest_refuses_it(tmp_path, capsys):
    import yaml

    path, entry = _tube_manifest(tmp_path / "mine")
    raw = yaml.safe_load(path.read_text())
    for bad, says in (({k: v for k, v in entry.items() if k != "centerline_sha256"}, "expected the keys"),
                      ({**entry, "mesh_sha256": "abc"}, "expected the file's sha256")):
        path.write_text(yaml.safe_dump({**raw, "meshes": {"tube": bad}}))
        rc = main(["suites", "build", "hidden", "--from", str(path), "--data", str(tmp_path / "p"), "--publish",
                   str(tmp_path / "q")])
        err = capsys.readouterr().err
        assert rc == 2 and "meshes.tube" in err and says in err and "Traceback" not in err, err
    assert not (tmp_path / "p").exists() and not (tmp_path / "q").exists()


def test_a_c3vd_download_is_hidden(tmp_path, capsys):
    import importlib.util

    from colonbench.benchmark import local_suites
    from colonbench.server import hidden
    from server_fixtures import ROOT

    spec = importlib.util.spec_from_file_location("c3vd_example", ROOT / "scripts" / "c3vd_example.py")
    example = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(example)
    download, private, public = tmp_path / "download", tmp_path / "private", tmp_path / "public"
    assert example.main([str(download), "--frames", "24"]) == 0
    capsys.readouterr()
    rc = main(["suites", "build", "hidden", "--from", str(download), "--data", str(private), "--publish",
               str(public), "--frames-every", "6", "--quiet"])
    out = capsys.readouterr().out
    assert rc == 0, out
    (sid,) = [p.name for p in private.iterdir() if not p.name.startswith(".")]
    suite = local_suites.load(private / sid)
    entry = local_suites.read_entry(private / sid)
    assert sid.startswith("c3vd-") and hidden.is_hidden(suite) and f"built hidden suite {sid}" in out
    assert entry["importer"]["name"] == "c3vd" and entry["source"]["digest"]
    assert hidden.served([private]) == {sid: suite}
    # published: the inputs as export writes them, their digest on both sides, no truth
    inputs = json.loads((public / hidden.INPUTS_FILE).read_text())
    assert entry["inputs_sha256"] == inputs["inputs_sha256"]
    assert _published_ids(public) == hidden.sample_ids(suite)
    assert not list(public.rglob("*.h5")) and not list(public.rglob("*.gz")) and not list(public.rglob("*.yaml"))
    with open(public / "index.csv") as f:
        header = next(csv.reader(f))
    assert not {"coverage", "holes", "hole_points", "centerline"} & set(header), header
    record = json.loads((public / "suite.json").read_text())
    assert set(record["suite"]) == {"id", "name", "version", "hidden", "samples", "noise_mm"}
    assert "coverage" not in json.dumps(record) and "holes" not in json.dumps(record)
    for p in public.iterdir():
        data = p.read_bytes()
        for secret in (suite.signature, suite.sha256.removeprefix("cb1-"), entry["source"]["digest"]):
            assert secret.encode() not in data, (p.name, secret)
    preds = write_predictions(tmp_path / "preds", _published_ids(public))
    assert main(["score", sid, str(preds), "--out", str(tmp_path / "run"), "--data", str(private), "--quiet"]) == 0
    rows = list(csv.DictReader(open(tmp_path / "run" / "results" / "preds.csv")))
    assert {r["sample_id"] for r in rows} == _published_ids(public) and all(r["error"] == "" for r in rows)
    # a seed or name is for manifests; importer options for a download
    rc = main(["suites", "build", "hidden", "--from", str(download), "--data", str(tmp_path / "p2"), "--publish",
               str(tmp_path / "q2"), "--name", "x"])
    assert rc == 2 and "read as a C3VD download" in capsys.readouterr().err
