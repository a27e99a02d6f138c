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


def test_a_whole_colon_suite_or_a_mesh_manifest_is_refused(tmp_path, capsys):
    rc = main(["suites", "build", "hidden", "--from", "colon-v1", "--data", str(tmp_path / "p"), "--publish",
               str(tmp_path / "q")])
    assert rc == 2 and "segment manifests" in capsys.readouterr().err
    rc = main(["suites", "build", "hidden", "--from", "real-v1", "--data", str(tmp_path / "p"), "--publish",
               str(tmp_path / "q")])
    assert rc == 2 and "procedural manifests only" in capsys.readouterr().err
    assert not (tmp_path / "p").exists() and not (tmp_path / "q").exists()
