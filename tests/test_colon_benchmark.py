"""The whole-colon benchmark: whole-colon shards, exact per-segment truth, evaluate --task colon, its leaderboard."""

import json

import h5py
import numpy as np
import pandas as pd
import pytest
from scipy.spatial import cKDTree
from shapes import straight

from colonbench.cli import main
from colonbench.errors import InputError

RADIUS = 15.0


def _plane(z):
    return {"point": [0.0, 0.0, float(z)], "normal": [0.0, 0.0, 1.0]}


def test_segment_truth_and_unobserved_ends_on_a_tube_with_known_cuts():
    """A straight tube, a quarter of the wall cut over 30 mm in one segment and the whole wall over the first
    20 mm of the next: each segment's region gets its analytic coverage, and only the second has an unseen end."""
    from colonbench.benchmark.colon_metrics import segment_truth
    from colonbench.datagen.colon import tube_colon

    line = straight(300.0)
    tube = tube_colon(line, RADIUS, ring_spacing_mm=0.5, n_around=256)
    c = tube.mesh.vertices[tube.mesh.faces].mean(axis=1)
    ang = np.arctan2(c[:, 1], c[:, 0])
    cut = ((c[:, 2] > 70) & (c[:, 2] < 100) & (ang > 0) & (ang < np.pi / 2)) | ((c[:, 2] > 120) & (c[:, 2] < 140))
    segs = [{"plane_start": _plane(z), "plane_end": _plane(z + 60)} for z in range(0, 300, 60)]
    t = segment_truth(tube.mesh.vertices, tube.mesh.faces, ~cut, line, segs)
    assert t["truth"] == pytest.approx([1.0, 1 - 0.25 * 30 / 60, 1 - 20 / 60, 1.0, 1.0], abs=0.01)
    assert t["true_start_mm"] == pytest.approx([0, 60, 120, 180, 240], abs=0.6)
    assert t["end_seen"] == pytest.approx([1, 1, 0, 1, 1], abs=0.05)  # the planes land within 0.5 mm
    # each region holds 60 mm of a 15 mm tube (the 256-gon's perimeter 0.01 % short of the circle's)
    assert t["true_area_mm2"] == pytest.approx(np.full(5, 2 * np.pi * RADIUS * 60), rel=0.01)


@pytest.fixture(scope="module")
def colon_dataset(tmp_path_factory):
    """A task: colon manifest of one short procedural colon, two whole partials (sphere and camera holes)."""
    from colonbench.shards.dataset import generate

    manifest = {"name": "colon-smoke", "seed": 3, "task": "colon",
                "config": {"colon": {"length_mm": [450, 520], "ring_spacing_mm": 1.0, "edge_mm": 1.5}},
                "splits": {"test": {"colons": {"first": 0, "count": 1}, "permutations": 2,
                                    "hole_models": {"spheres": 0.5, "camera": 0.5}}}}
    out = tmp_path_factory.mktemp("colon") / "data"
    lock = generate(manifest, out, progress=False)
    return out, lock


def test_whole_colon_shards_hold_exact_truth(colon_dataset):
    from colonbench.meshes import triangle_areas
    from colonbench.shards.colonshard import ColonShard
    from colonbench.shards.verify import verify

    data, lock = colon_dataset
    assert list(lock["shards"]) == ["test/colon-00000.h5"] and lock["splits"]["test"]["samples"] == 2
    assert verify(data) == []
    shard = ColonShard(data / "test/colon-00000.h5")
    truth = shard.colon()
    area = triangle_areas(truth["vertices"], truth["faces"])
    centroids = truth["vertices"][truth["faces"]].mean(axis=1)
    assert np.all(np.diff(truth["centerline"].arclength) <= 1.0 + 1e-6)
    models = set()
    for i in range(len(shard)):
        s = shard.sample(i)
        models.add(s["hole_model"])
        assert s["coverage"] == pytest.approx(area[s["observed_faces"]].sum() / area.sum())
        assert 0.5 < s["coverage"] < 1.0
        _, face = cKDTree(centroids).query(s["points"])
        assert s["observed_faces"][face].mean() > 0.97  # the cloud lies on observed faces only
        # the trajectory withdraws: it ends at the rectum end of the true centerline, off it by its drift
        line = truth["centerline"]
        d, near = cKDTree(line.points).query(s["positions"])
        assert line.arclength[near[-1]] > line.arclength[-1] - 3.0 and line.arclength[near[0]] < 3.0
        assert 1.0 < np.median(d) and d.max() < 20.0  # at most half the way to the wall
    assert models == {"spheres", "camera"}  # 2 permutations of a half-and-half mix: one of each

def test_a_broken_whole_colon_shard_is_reported(colon_dataset, tmp_path):
    import shutil

    from colonbench.shards.verify import check_shard, verify

    data, _ = colon_dataset
    copy = tmp_path / "data"
    shutil.copytree(data, copy)
    path = copy / "test/colon-00000.h5"
    assert check_shard(path) == []
    with h5py.File(path, "r+") as h5:
        h5["samples/coverage"][0] = 1.5
        del h5["samples/positions_offsets"]
    faults = check_shard(path)
    assert any("positions_offsets" in f for f in faults)
    assert any("sha256 differs" in f or "bytes" in f for f in verify(copy))


def test_evaluate_colon_task_and_its_leaderboard(colon_dataset, tmp_path):
    data, _ = colon_dataset
    run = tmp_path / "run"
    assert main(["evaluate", str(data), "--task", "colon", "--methods", "constant,thresholding", "--noise", "0",
                 "--contexts", "0,15", "--out", str(run), "--quiet"]) == 0
    colons = pd.read_csv(run / "results" / "colons.csv")
    segments = pd.read_csv(run / "results" / "segments.csv")
    assert len(colons) == 2 * 2 * 2  # samples x methods x tracks
    assert set(colons["track"]) == {"segment-only", "context-15mm"}
    assert (colons["error"].isna() | (colons["error"] == "")).all()
    # the whole-colon truth is the shard's, and the tracks cut the same segments (one centerline per sample)
    from colonbench.shards.colonshard import ColonShard

    shard = ColonShard(data / "test/colon-00000.h5")
    for _, r in colons.iterrows():
        assert r["true_coverage"] == pytest.approx(shard.sample(int(r["index"]))["coverage"])
    key = ["method", "index", "segment"]
    a = segments[segments["track"] == "segment-only"].set_index(key).sort_index()
    b = segments[segments["track"] == "context-15mm"].set_index(key).sort_index()
    assert a.index.equals(b.index)
    assert np.allclose(a["start_mm"], b["start_mm"]) and np.allclose(a["true_coverage"], b["true_coverage"])
    # the constant guess errs by exactly its constant minus the truth
    const = segments[segments["method"] == "constant"]
    guess = const["coverage"].iloc[0]
    assert np.allclose(const["coverage_error"], guess - const["true_coverage"], equal_nan=True)
    assert segments["true_coverage"].between(0, 1).all()
    # the segments' true regions do not overlap: per map they hold at most the colon's area, and most of it
    from colonbench.meshes import triangle_areas

    truth = shard.colon()
    colon_area = triangle_areas(truth["vertices"], truth["faces"]).sum()
    mapped = segments.groupby(["method", "track", "index"])["true_area_mm2"].sum()
    assert (mapped <= colon_area * (1 + 1e-9)).all() and (mapped > 0.5 * colon_area).all()
    # a rerun finds everything done
    assert main(["evaluate", str(data), "--task", "colon", "--methods", "constant,thresholding", "--noise", "0",
                 "--contexts", "0,15", "--out", str(run), "--quiet"]) == 0
    out = tmp_path / "board"
    assert main(["leaderboard", str(run), "--out", str(out)]) == 0
    text = (out / "leaderboard.md").read_text()
    assert "whole-colon leaderboard" in text and "In context vs segment-only" in text
    rows = json.loads((out / "leaderboard.json").read_text())["rows"]
    mine = [r for r in rows if r["method"] == "constant" and r["track"] == "segment-only"][0]
    assert mine["segment_mae"] == pytest.approx(100 * np.nanmean(np.abs(
        const[const["track"] == "segment-only"]["coverage_error"])))
    assert (out / "colon-maps.png").stat().st_size > 10_000


def test_colon_task_refuses_bad_input(colon_dataset, smoke_dataset, tmp_path, capsys):
    from colonbench.shards.manifest import resolve

    base = {"name": "x", "seed": 1, "task": "colon"}
    with pytest.raises(InputError, match="not whole-colon hole models"):
        resolve({**base, "splits": {"test": {"colons": {"first": 0, "count": 1}, "hole_models": {"video": 1}}}})
    with pytest.raises(InputError, match="segments_per_length"):
        resolve({**base, "splits": {"test": {"colons": {"first": 0, "count": 1}, "segments_per_length": 3}}})
    with pytest.raises(InputError, match="task"):
        resolve({**base, "task": "colons", "splits": {"test": {"colons": {"first": 0, "count": 1}}}})
    smoke, _ = smoke_dataset
    assert main(["evaluate", str(smoke), "--task", "colon", "--out", str(tmp_path / "r"), "--quiet"]) == 2
    assert "segments dataset" in capsys.readouterr().err
    data, _ = colon_dataset
    assert main(["evaluate", str(data), "--task", "colon", "--methods", "gt-heatmap", "--out", str(tmp_path / "g"),
                 "--quiet"]) == 2
    assert "ground truth" in capsys.readouterr().err


def test_a_program_maps_whole_colons_through_exec(colon_dataset, tmp_path):
    """exec: on whole colons: one call per map with the clouds of the segments the map estimates, each answered
    by id in both tracks; the rows match the built-in constant guess segment for segment."""
    import sys

    from colonbench.benchmark.colon_evaluate import evaluate_colons

    program = tmp_path / "point_eight.py"
    program.write_text("import json, sys\nfrom pathlib import Path\na = sys.argv[1:]\n"
                       "out = Path(a[a.index('--out-dir') + 1]); out.mkdir(parents=True, exist_ok=True)\n"
                       "for f in a[:a.index('--out-dir')]:\n"
                       "    (out / (Path(f).stem + '.json')).write_text(json.dumps({'coverage': 0.8}))\n")
    data, _ = colon_dataset
    run = evaluate_colons(data, [f"exec:{sys.executable} {program}", "constant"], tmp_path / "run", noise=[0],
                          contexts=[0, 15], progress=False)
    from colonbench.benchmark.runfolder import read_rows

    seg = read_rows(run / "results" / "segments.csv")   # error "" where there is none
    mine, const = seg[seg["method"] == "point_eight"], seg[seg["method"] == "constant"]
    key = ["track", "index", "segment"]
    a, b = mine.set_index(key).sort_index(), const.set_index(key).sort_index()
    assert a.index.equals(b.index) and len(a) > 10
    guess = const["coverage"].mode().iloc[0]
    plain = b["coverage"] == guess   # segments estimated whole (no unreconstructed stretch added)
    assert plain.sum() > 5 and np.allclose(a.loc[plain, "coverage"], 0.8)
    assert a["error"].eq(b["error"]).all()
    # both tracks give the program each segment's own points: the same answers
    assert np.allclose(a.xs("segment-only")["coverage"], a.xs("context-15mm")["coverage"], equal_nan=True)
    from colonbench.mapping.colonmap import MIN_POINTS

    answers = sorted((run / "predictions" / "point_eight").glob("*.json"))
    assert len(answers) == int((a.xs("segment-only")["points"] >= MIN_POINTS).sum())   # one per estimated segment
    assert all("_seg" in p.stem and p.stem.startswith("test_colon-00000_") for p in answers)
    # what benchmark's warnings count: the headline track's segments, and the first error among them
    import dataclasses

    from colonbench.benchmark import suites
    from colonbench.pipeline import failures

    suite = dataclasses.replace(suites.get("colon-v1"), contexts_mm=(0.0, 15.0))
    rows = {r["method"]: r for r in failures(suite, run)}
    from colonbench.benchmark.colon_evaluate import skipped_rows

    head = a.xs("context-15mm")
    head = head[~skipped_rows(head)]              # the segments the map gave the methods
    errors = head.loc[head["error"] != "", "error"]
    for name in ("point_eight", "constant"):
        assert rows[name]["samples"] == len(head) and rows[name]["failed"] == len(errors)
        assert rows[name]["first_error"] == (errors.iloc[0] if len(errors) else "")
        ids = {f"{r['shard'].removesuffix('.h5').replace('/', '_')}_{i:03d}_noise{r['noise_mm']:g}_seg{k:03d}"
               for (i, k), r in head[head["error"] != ""].iterrows()}           # its segment's id, as exec: gets it
        assert rows[name]["first_sample"] in (ids or {""})


def test_the_colon_task_scores_the_segments_intervals(colon_dataset, tmp_path):
    from colonbench.benchmark.colon_evaluate import evaluate_colons
    from colonbench.reports.colon_leaderboard import write_colon_leaderboard

    class Sure:
        name, version = "sure", "1"

        def estimate(self, points):
            return {"coverage": 0.8, "coverage_interval": [0.7, 0.9]}

    data, _ = colon_dataset
    run = evaluate_colons(data, [Sure(), "constant"], tmp_path / "run", noise=[0], contexts=[0], progress=False)
    seg = pd.read_csv(run / "results" / "segments.csv")
    sure = seg[seg["method"] == "sure"]
    assert (sure["interval_low"] == 0.7).all() and (sure["interval_high"] == 0.9).all()
    assert seg[seg["method"] == "constant"]["interval_low"].isna().all()
    inside = 100 * sure["true_coverage"].between(0.7, 0.9).mean()
    assert 0 < inside < 100                             # the maps' segments lie on both sides of [0.7, 0.9]
    write_colon_leaderboard([run], tmp_path / "board", figures=False)
    rows = {r["method"]: r for r in json.loads((tmp_path / "board" / "leaderboard.json").read_text())["rows"]}
    assert rows["sure"]["interval_covered"] == pytest.approx(inside)
    assert rows["sure"]["interval_width"] == pytest.approx(20.0)
    assert rows["constant"]["interval_covered"] is None or np.isnan(rows["constant"]["interval_covered"])
    md = (tmp_path / "board" / "leaderboard.md").read_text()
    assert f"| {inside:.1f} % of {sure['true_coverage'].notna().sum()}, 20.0 |" in md and "| n/a |" in md


def test_a_failed_map_segment_is_scored_as_the_worst_answer(colon_dataset, tmp_path):
    """A segment the method fails on counts as the farther of coverage 0 and 1 in the segment MAE and is counted,
    whatever its error says (one mimics the map's words); one the map gives no method (too few points) is left out
    for every method alike, as the map records it. A map whose every segment failed has its whole-colon coverage
    scored so too."""
    from colonbench.benchmark.colon_evaluate import evaluate_colons, skipped_rows
    from colonbench.errors import ColonbenchError
    from colonbench.mapping.colonmap import MIN_POINTS
    from colonbench.mapping.reach import unreached_error
    from colonbench.mapping.segments import few_points_error, skipped_by_map
    from colonbench.reports.colon_leaderboard import colon_table, write_colon_leaderboard

    assert skipped_by_map(few_points_error(12, 200)) and skipped_by_map(unreached_error(np.ones(9, bool), 0.4, True))
    assert not skipped_by_map("the method returned no coverage (its completed surface is empty): not estimated")

    class Flaky:
        name, version = "flaky", "1"

        def estimate(self, points):
            if len(points) % 3 == 0:
                raise ColonbenchError("3 points, fewer than 10: not estimated")      # the map's words, its own failure
            if len(points) % 2:
                raise ColonbenchError("odd")
            return {"coverage": 0.8}

    class Broken:
        name, version = "broken", "1"

        def estimate(self, points):
            raise ColonbenchError("never")

    data, _ = colon_dataset
    run = evaluate_colons(data, [Flaky(), Broken()], tmp_path / "run", noise=[0], contexts=[0], progress=False)
    from colonbench.benchmark.runfolder import read_rows

    seg = read_rows(run / "results" / "segments.csv")
    colons = read_rows(run / "results" / "colons.csv")
    seg = seg[seg["method"] == "flaky"]
    assert (skipped_rows(seg) == (seg["points"] < MIN_POINTS).to_numpy()).all()
    # one answered segment made a map-skip, as the map writes one (the fixture's maps skip none)
    k = int(np.flatnonzero(seg["error"].eq("").to_numpy())[0])
    seg.loc[seg.index[k], ["coverage", "coverage_error", "error", "skipped"]] = [np.nan, np.nan,
                                                                               few_points_error(150, MIN_POINTS), True]
    skipped = skipped_rows(seg)
    mimic = seg["error"].str.contains("fewer than 10").to_numpy()
    assert skipped.sum() == 1 and mimic.sum() >= 1 and not (mimic & skipped).any()   # its own words: a failure
    legacy = skipped_rows(seg.drop(columns="skipped"))     # rows written before the flag: only the words tell
    assert (legacy[~mimic] == skipped[~mimic]).all()
    bad = seg["error"].ne("").to_numpy() & ~skipped
    assert bad.sum() >= 3 and (~bad & ~skipped).sum() >= 2             # both kinds of segment are there
    t = seg["true_coverage"].to_numpy()
    expected = np.where(bad, np.maximum(t, 1 - t), np.abs(0.8 - t))[~skipped].mean() * 100
    flaky = colon_table(seg, colons[colons["method"] == "flaky"]).iloc[0]
    assert flaky["segment_mae"] == pytest.approx(expected)
    assert flaky["failed_segments"] == bad.sum() and flaky["estimated"] == (~bad & ~skipped).sum()
    write_colon_leaderboard([run], tmp_path / "board", figures=False)
    rows = {r["method"]: r for r in json.loads((tmp_path / "board" / "leaderboard.json").read_text())["rows"]}
    # a map whose every segment failed has no whole-colon coverage: scored as the farther of 0 and 1 too
    whole = colons[colons["method"] == "broken"]
    assert whole["coverage"].isna().all() and whole["error"].eq("").all()
    t = whole["true_coverage"].to_numpy()
    assert rows["broken"]["whole_mae"] == pytest.approx(100 * np.maximum(t, 1 - t).mean())
    assert rows["broken"]["estimated"] == 0 and rows["broken"]["failed_segments"] == len(seg)
