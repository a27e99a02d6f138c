"""The suites' dataset cards and Croissant metadata: what they say, that the committed ones are current, that
Croissant tools read them."""

import json
import logging
from pathlib import Path

import pytest

from colonbench.benchmark import cards, suites
from colonbench.cli import main

ROOT = Path(__file__).resolve().parents[1]
CARDS = ROOT / "docs" / "suites"


def test_the_committed_cards_are_what_the_code_writes_today():
    expected = {f"{s.id}{ext}" for s in suites.SUITES for ext in (".md", ".croissant.json")}
    assert {p.name for p in CARDS.iterdir()} == expected, "regenerate them with: make cards"
    for s in suites.SUITES:
        assert (CARDS / f"{s.id}.md").read_text() == cards.card(s), f"{s.id}: regenerate with make cards"
        assert json.loads((CARDS / f"{s.id}.croissant.json").read_text()) == cards.croissant(s), s.id
    benchmark = (ROOT / "docs" / "benchmark.md").read_text()
    assert all(f"(suites/{s.id}.md)" in benchmark for s in suites.SUITES)


def test_each_card_says_what_its_suite_is_made_of_and_how_to_cite_it():
    for s in suites.SUITES:
        text = cards.card(s)
        assert s.signature in text and f"`{s.citation}`" in text and s.sha256 in text, s.id
        assert f"colonbench generate data_manifests/{s.manifest} " in text and f"--suites {s.id} " in text, s.id
        assert "MIT" in text and "../formats.md" in text, s.id
    real, demo = cards.card("real-v1"), cards.card("demo-v1")
    for words in ("gca00060", "EdinGCA_3D_00060", "CC BY 4.0", "Burger et al.",
                  "BMC Medical Informatics and Decision Making 23:36 (2023)", "Keep this attribution"):
        assert words in real, words
    assert "gca" not in demo and "CC BY" not in demo and "Burger" not in demo and "no third-party data" in demo
    assert "HuBMAP" not in real   # the HuBMAP sentence only with a HuBMAP mesh (gca00080 is in no suite)
    colon = cards.card("colon-v1")
    assert "**not a segment**" in colon and "per-face" in colon and "`observed_faces`" in colon
    assert "gca00060" in colon and "CC BY 4.0" in colon and "`partial_points`" not in colon
    assert "`partial_points`" in real and "`hole_points`" in real and "`centerline`" in real
    assert "86 segments of the `test` split" in real and "43 `camera`, 43 `spheres` samples" in real
    assert "400 spread evenly" in cards.card("paper-v1") and "x 0.25-4 points/mm^2" in cards.card("wide-v1")


def test_croissant_metadata_has_the_required_keys_and_the_files_hashes():
    for s in suites.SUITES:
        meta = json.loads(json.dumps(cards.croissant(s)))   # plain JSON
        assert meta["@context"]["cr"] == "http://mlcommons.org/croissant/"
        assert meta["@context"]["@vocab"] == "https://schema.org/" and meta["@context"]["citeAs"] == "cr:citeAs"
        assert meta["@type"] == "sc:Dataset" and meta["conformsTo"] == "http://mlcommons.org/croissant/1.0"
        assert meta["name"] == s.id and s.citation in meta["citeAs"] and s.citation in meta["description"]
        files = {d["@id"]: d for d in meta["distribution"]}
        assert files["shards"]["@type"] == "cr:FileSet" and files["shards"]["encodingFormat"] == "application/x-hdf5"
        for d in files.values():
            if d["@type"] == "cr:FileObject":
                assert cards._sha256(ROOT / d["contentUrl"]) == d["sha256"], (s.id, d["contentUrl"])
        sets = {r["@id"]: r for r in meta["recordSet"]}
        assert set(sets) == {"samples", "arrays"}, s.id
        names = {f["name"]: f for f in sets["arrays"]["field"]}
        want = ({"points", "coverage", "observed_faces", "positions"} if s.task == "colon"
                else {"partial_points", "coverage", "hole_points", "centerline"})
        assert want <= set(names), s.id
        assert names["coverage"]["dataType"] == "sc:Float" and "fraction" in names["coverage"]["description"]
        assert all(f["source"]["fileSet"]["@id"] == "shards" for f in sets["arrays"]["field"])
        rows = sets["samples"]["data"]          # the samples, listed in the JSON-LD itself
        assert len(rows) == s.samples and {"samples/shard", "samples/index", "samples/coverage"} <= set(rows[0])
    real, demo = cards.croissant("real-v1"), cards.croissant("demo-v1")
    assert real["license"] == [cards.LICENSES["MIT"], cards.LICENSES["CC-BY-4.0"]] and "Burger et al." in real["citeAs"]
    assert demo["license"] == cards.LICENSES["MIT"] and "Burger" not in demo["citeAs"]
    assert {"mesh-gca00060", "midline-gca00060"} <= {d["@id"] for d in real["distribution"]}
    mesh = next(d for d in real["distribution"] if d["@id"] == "mesh-gca00060")
    assert mesh["sha256"] == "cc7f2ed1c5a07e80e16bf03a9cb1b098321fc1d9e44977d6f99a9ea63bc87892"


@pytest.mark.filterwarnings("ignore::DeprecationWarning")   # rdflib's, inside mlcroissant
def test_mlcroissant_validates_every_committed_croissant_file(caplog):
    mlc = pytest.importorskip("mlcroissant", reason="mlcroissant is not installed (pip install 'colonbench[test]')")
    for s in suites.SUITES:
        with caplog.at_level(logging.WARNING):
            dataset = mlc.Dataset(jsonld=str(CARDS / f"{s.id}.croissant.json"))   # raises on any error
        issues = dataset.metadata.ctx.issues
        assert not issues.errors, (s.id, issues.errors)
        # the only remark: no datePublished (the registry records none)
        assert all("datePublished" in w for w in issues.warnings), (s.id, issues.warnings)
        assert "not standard" not in caplog.text, caplog.text   # the @context is the specification's


def test_cli_writes_a_card_and_refuses_an_unknown_suite(tmp_path, capsys):
    assert main(["suites", "card", "real", "--out", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert str(tmp_path / "real-v1.md") in out and str(tmp_path / "real-v1.croissant.json") in out
    assert (tmp_path / "real-v1.md").read_text() == (CARDS / "real-v1.md").read_text()
    assert (tmp_path / "real-v1.croissant.json").read_text() == (CARDS / "real-v1.croissant.json").read_text()
    assert main(["suites", "card", "paper-v9", "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert "unknown suite 'paper-v9'" in err and "Traceback" not in err
    assert not (tmp_path / "paper-v9.md").exists()


def test_an_attribution_the_readme_no_longer_gives_fails_loudly(tmp_path, monkeypatch):
    (tmp_path / "meshes").mkdir()
    readme = (suites.manifest_dir() / "meshes" / "README.md").read_text()
    monkeypatch.setattr(suites, "manifest_dir", lambda: tmp_path)
    (tmp_path / "meshes" / "README.md").write_text(readme.replace("Burger et al.", "Someone"))
    with pytest.raises(ValueError, match="no data paper"):
        cards.mesh_attribution(["gca00060"])
    (tmp_path / "meshes" / "README.md").write_text(readme.replace("`gca00060_large", "`gca00061_large"))
    with pytest.raises(ValueError, match="no row of gca00060"):
        cards.mesh_attribution(["gca00060"])


def test_each_card_says_one_thing_of_the_stored_points_and_their_noise(demo_data):
    """The stored points are noiseless (every suite's manifest stores noise 0) and the benchmark adds each noise
    level when it scores: the metrics sentence and the field table say so alike."""
    from colonbench.shards.reader import Shard

    for s in suites.SUITES:
        text = cards.card(s)
        assert "added by the benchmark to the stored noiseless points" in text, s.id
        points = "points" if s.task == "colon" else "partial_points"
        rows = {r.split("|")[1].strip(" `"): r for r in text.splitlines() if r.startswith("| `")}
        assert "noise included" not in rows[points] and "stored noiseless" in rows[points], (s.id, rows[points])
        assert "0 in this suite's data" in rows["noise_mm"], (s.id, rows["noise_mm"])
        fields = {f["name"]: f["description"] for r in cards.croissant(s)["recordSet"] for f in r["field"]}
        assert "noise included" not in fields[points] and "stored noiseless" in fields[points], s.id
    # what the demo suite's data hold: noise 0 stored with every sample, as the cards say
    shard = sorted((demo_data / "demo-v1" / "test").glob("*.h5"))[0]
    with Shard(shard) as sh:
        assert all(float(sh.geometry(i)["noise_mm"]) == 0.0 for i in range(len(sh)))


@pytest.mark.filterwarnings("ignore::DeprecationWarning")   # rdflib's, inside mlcroissant
def test_mlcroissant_reads_one_record_per_sample_of_each_suite(demo_data):
    """records("samples") of a committed card yields the suite's samples, each naming where its arrays are; on
    demo-v1 built here, each record is the sample its shard holds at its row."""
    mlc = pytest.importorskip("mlcroissant", reason="mlcroissant is not installed (pip install 'colonbench[test]')")
    from colonbench.shards.reader import Shard

    for s in suites.SUITES:
        records = list(mlc.Dataset(jsonld=str(CARDS / f"{s.id}.croissant.json")).records("samples"))
        assert len(records) == s.samples, s.id
        truth = [x["coverage"] for x in suites.published_signature(s)["samples"]]
        assert [r["samples/coverage"] for r in records] == pytest.approx(truth), s.id
    records = list(mlc.Dataset(jsonld=str(CARDS / "demo-v1.croissant.json")).records("samples"))
    folder = demo_data / "demo-v1"
    assert len(records) == sum(len(Shard(p)) for p in (folder / "test").glob("*.h5")) == 24
    for r in records:
        with Shard(folder / _text(r["samples/shard"])) as sh:
            geo = sh.geometry(int(r["samples/index"]))
        assert geo["coverage"] == pytest.approx(r["samples/coverage"], abs=1e-12)
        assert str(geo["hole_model"]) == _text(r["samples/hole_model"])
        assert len(geo["partial_points"]) == r["samples/input_points"]


def _text(value) -> str:
    """A text field of an mlcroissant record (bytes from files, str from data in the JSON-LD)."""
    return value.decode() if isinstance(value, bytes) else str(value)
