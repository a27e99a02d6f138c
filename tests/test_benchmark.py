"""The benchmark: metrics with known answers, the method registry, evaluate runs and leaderboards."""

import json
import math

import numpy as np
import pandas as pd
import pytest

from colonbench.benchmark.evaluate import evaluate, load_results, noisy, read_rows, result_columns
from colonbench.benchmark.metrics import precision_recall, segment_metrics
from colonbench.benchmark.registry import DEFAULT_METHODS, available, load_method
from colonbench.benchmark.summary import metric_columns, summarize
from colonbench.cli import main
from colonbench.errors import InputError
from colonbench.estimate import as_estimate
from colonbench.reports.leaderboard import merge_runs, write_leaderboard


# ------------------------------------------------------------------------------------------------ metrics


def test_precision_recall_on_hand_made_point_sets():
    truth = np.array([[0.0, 0, 0], [10, 0, 0], [20, 0, 0], [30, 0, 0]])
    est = np.array([[0.5, 0, 0], [10, 1.5, 0], [50, 0, 0]])
    # at 1 mm: only (0.5,0,0) is near a GT point; only GT (0,0,0) has an estimate that near
    assert precision_recall(est, truth, 1.0) == (pytest.approx(1 / 3), pytest.approx(1 / 4))
    # at 2 mm: two of three estimates, two of four GT points
    assert precision_recall(est, truth, 2.0) == (pytest.approx(2 / 3), pytest.approx(2 / 4))
    assert precision_recall(truth, truth, 1e-6) == (1.0, 1.0)
    p, r = precision_recall(np.zeros((0, 3)), truth, 1.0)
    assert math.isnan(p) and math.isnan(r)  # undefined, never 0 or 1
    m = segment_metrics(0.7, est, truth, {"coverage": 0.75, "hole_points": truth, "centerline": np.zeros((0, 3))})
    assert m["coverage_error"] == pytest.approx(-0.05)
    assert m["holes_precision_2mm"] == pytest.approx(2 / 3) and math.isnan(m["centerline_recall_1mm"])
    assert set(m) == {"coverage_error", *metric_columns()}


def test_summary_statistics_by_hand():
    rows = []
    errors = [0.01, -0.03, 0.05, np.nan]  # the last: the method gave no coverage
    for k, e in enumerate(errors):
        row = {"method": "m", "noise_mm": 0.0, "true_coverage": 0.8, "coverage_error": e, "seconds": 0.5 * (k + 1),
               "error": ""}
        row.update({c: (1.0 if k % 2 == 0 else 0.5) for c in metric_columns()})
        rows.append(row)
    rows[3]["holes_precision_2mm"] = np.nan
    # a failure: scored as coverage 1, the farther end from its truth 0.3 (error +0.7), and 0 in precision / recall
    rows.append({**rows[0], "true_coverage": 0.3, "coverage_error": np.nan, "error": "RuntimeError: boom",
                 "seconds": np.nan, **{c: np.nan for c in metric_columns()}})
    s = summarize(pd.DataFrame(rows)).iloc[0]
    assert s["segments"] == 5 and s["failed"] == 1 and s["coverage_undefined"] == 1
    scored = [0.01, -0.03, 0.05, 0.7]
    assert s["coverage_mae"] == pytest.approx(100 * np.abs(scored).mean())
    assert s["coverage_median"] == pytest.approx(4.0)
    assert s["coverage_bias"] == pytest.approx(100 * np.mean(scored))
    assert s["coverage_q95"] == pytest.approx(100 * np.quantile(np.abs(scored), 0.95))
    assert s["holes_precision_2mm_mean"] == pytest.approx((1 + 0.5 + 1 + 0) / 4)
    assert s["holes_precision_2mm_undefined"] == 1 and s["holes_recall_2mm_undefined"] == 0
    assert s["centerline_recall_1mm_median"] == pytest.approx(0.5)
    assert s["seconds"] == pytest.approx(np.mean([0.5, 1.0, 1.5, 2.0]))
    # the same method answering that segment with the worst possible estimate scores no worse: failing never helps
    worst = pd.DataFrame(rows[:4] + [{**rows[4], "coverage_error": 0.7, "error": "",
                                      **{c: 0.0 for c in metric_columns()}}])
    assert summarize(worst).iloc[0]["coverage_mae"] == pytest.approx(s["coverage_mae"])
    # a failure where the truth has no hole points: its holes metrics stay undefined, as any answer's would; a
    # method that never gives a centerline (coverage only) keeps it undefined, and failures are not counted there
    empty = pd.DataFrame(rows).assign(holes_true_n=[5, 5, 5, 5, 0], centerline_true_n=5)
    for c in metric_columns():
        if c.startswith("centerline"):
            empty[c] = np.nan
    e = summarize(empty).iloc[0]
    assert e["holes_recall_2mm_mean"] == pytest.approx((1 + 0.5 + 1 + 0.5) / 4)
    assert np.isnan(e["centerline_recall_2mm_mean"]) and e["centerline_recall_2mm_undefined"] == 4


# ------------------------------------------------------------------------------------------------ registry


def test_builtin_methods_are_registered_like_a_plugin_would_be():
    assert set(DEFAULT_METHODS) <= set(available())
    m = load_method("unwrap-pca")
    assert m.name == "unwrap-pca" and m.version
    half = load_method("plugin_methods:HalfCoverage")
    assert half.name == "HalfCoverage" and half.version == "unversioned"
    est = as_estimate(half.estimate(np.ones((10, 3))), half.name)
    assert est.coverage == 0.5 and est.holes.shape == (3, 3) and est.centerline.shape == (0, 3)
    with pytest.raises(InputError, match="unknown method 'nope'"):
        load_method("nope")
    with pytest.raises(InputError, match="cannot import"):
        load_method("no_such_module_here:X")
    with pytest.raises(InputError, match="has no 'Missing'"):
        load_method("plugin_methods:Missing")
    with pytest.raises(InputError, match=r"fraction in \[0, 1\]"):
        as_estimate({"coverage": 3.0}, "x")
    with pytest.raises(InputError, match=r"shape \(4,\)"):
        as_estimate({"coverage": 0.5, "holes": [1, 2, 3, 4]}, "x")


def test_noise_is_the_same_draw_for_every_method_and_rerun():
    pts = np.zeros((100, 3))
    a = noisy(pts, 0.5, 0, "test/a.h5", 3)
    assert np.array_equal(a, noisy(pts, 0.5, 0, "test/a.h5", 3))
    assert a.std() == pytest.approx(0.5, rel=0.15)
    assert not np.array_equal(a, noisy(pts, 0.5, 0, "test/a.h5", 4))
    assert not np.array_equal(a, noisy(pts, 0.5, 1, "test/a.h5", 3))
    assert np.array_equal(noisy(pts, 0.0, 0, "test/a.h5", 3), pts)


# ------------------------------------------------------------------------------------------------ runs


def test_ground_truth_fed_as_the_prediction_scores_perfectly(smoke_dataset, tmp_path):
    data, _ = smoke_dataset
    run = evaluate(data, ["plugin_methods:Oracle"], tmp_path / "run", noise=(0, 0.5), progress=False)
    meta, res = load_results(run)
    assert list(res.columns) == result_columns()
    assert len(res) == 2 * meta["data"]["samples"] and (res["error"] == "").all()
    assert (res["coverage_error"] == 0).all()
    for c in metric_columns():
        v = res[c].dropna()
        assert len(v) and (v == 1.0).all(), c
    assert meta["methods"]["oracle"]["reference"] and meta["methods"]["oracle"]["version"] == "1.0"
    summary = json.loads((run / "results" / "oracle.json").read_text())
    assert summary["data"]["manifest_name"] == "smoke" and summary["versions"]["colonbench"]
    assert all(r["coverage_mae"] == 0 for r in summary["summary"])


def test_a_run_resumes_adds_methods_and_refuses_other_settings(smoke_dataset, tmp_path):
    data, _ = smoke_dataset
    out = tmp_path / "run"
    evaluate(data, ["constant", "plugin_methods:Oracle"], out, noise=(0,), progress=False)
    first = read_rows(out / "results" / "constant.csv").drop(columns="seconds")
    part = next((out / "parts" / "constant").glob("*.csv"))
    part.unlink()  # as if killed before this unit was written
    evaluate(data, ["constant", "plugin_methods:Oracle"], out, noise=(0,), progress=False)
    pd.testing.assert_frame_equal(read_rows(out / "results" / "constant.csv").drop(columns="seconds"), first)
    evaluate(data, ["unwrap-pca"], out, noise=(0,), progress=False)  # a method added to the run
    meta, res = load_results(out)
    assert set(meta["methods"]) == {"constant", "oracle", "unwrap-pca"}
    assert set(res["method"]) == set(meta["methods"])
    with pytest.raises(InputError, match="other noise_mm"):
        evaluate(data, ["constant"], out, noise=(0, 0.5), progress=False)
    with pytest.raises(InputError, match="other data"):
        evaluate(data, ["constant"], out, noise=(0,), limit=1, progress=False)
    other = tmp_path / "stuff"
    other.mkdir()
    (other / "notes.txt").write_text("mine")
    with pytest.raises(InputError, match="not empty"):
        evaluate(data, ["constant"], other, progress=False)
    with pytest.raises(InputError, match="no shards of split 'nope'"):
        evaluate(data, ["constant"], tmp_path / "r2", split="nope", progress=False)


def test_leaderboard_merges_runs_counts_failures_and_refuses_other_data(smoke_dataset, tmp_path):
    data, _ = smoke_dataset
    a = evaluate(data, ["plugin_methods:Oracle"], tmp_path / "a", progress=False)
    b = evaluate(data, ["constant", "plugin_methods:Broken"], tmp_path / "b", progress=False)
    result = write_leaderboard([a, b], tmp_path / "lb")
    names = {p.name for p in result["paths"]}
    assert {"leaderboard.md", "leaderboard.csv", "leaderboard.json", "boxplots.png", "scatter.png"} <= names
    tab = pd.read_csv(tmp_path / "lb" / "leaderboard.csv")
    assert set(tab["method"]) == {"oracle", "constant", "broken"}
    assert len(tab) == 3 * 2  # per noise level
    broken = tab[tab["method"] == "broken"]
    meta, rows = load_results(a)
    n = meta["data"]["samples"]
    assert (broken["failed"] == n).all() and (broken["coverage_undefined"] == 0).all()
    # every failure scored as the farther of coverage 0 and 1: never dropped, never better than an answer
    true = rows[rows["noise_mm"] == 0]["true_coverage"]
    assert broken["coverage_mae"].to_numpy() == pytest.approx([100 * np.maximum(true, 1 - true).mean()] * 2)
    assert (broken["coverage_mae"] > tab[tab["method"] == "constant"]["coverage_mae"].max()).all()
    const = tab[tab["method"] == "constant"]
    assert (const["holes_recall_2mm_undefined"] == n).all() and const["reference"].all()
    text = (tmp_path / "lb" / "leaderboard.md").read_text()
    assert "| oracle * | 1.0 |" in text and "| broken |" in text
    js = json.loads((tmp_path / "lb" / "leaderboard.json").read_text())
    assert js["data"]["manifest_name"] == "smoke" and len(js["rows"]) == 6
    # a run on other samples, a method given twice, an unfinished run: refused
    c = evaluate(data, ["constant"], tmp_path / "c", limit=1, progress=False)
    with pytest.raises(InputError, match="other data"):
        merge_runs([a, c])
    with pytest.raises(InputError, match="in both"):
        merge_runs([b, b])
    (b / "results" / "constant.csv").unlink()
    with pytest.raises(InputError, match="not finished"):
        merge_runs([a, b])


def test_a_method_that_answers_no_coverage_fails_and_is_scored_as_a_failure(smoke_dataset, tmp_path):
    """A Python method returning NaN on a segment gains nothing by it: the row is a failure, scored as the farther of
    coverage 0 and 1 (exec programs cannot return NaN at all)."""
    data, _ = smoke_dataset

    class Shy:                                          # no coverage for the first of the two segments
        name, version, calls = "shy", "1", 0

        def estimate(self, points):
            self.calls += 1
            return {"coverage": float("nan") if self.calls == 1 else 0.5}

    run = evaluate(data, [Shy()], tmp_path / "run", noise=[0], progress=False)
    rows = pd.read_csv(run / "results" / "shy.csv")
    nan = rows["error"].fillna("").str.contains("gave no coverage")
    assert 0 < nan.sum() < len(rows) and rows.loc[nan, "coverage"].isna().all()
    write_leaderboard([run], tmp_path / "lb", figures=False)
    tab = pd.read_csv(tmp_path / "lb" / "leaderboard.csv")
    true = rows["true_coverage"]
    expected = np.where(nan, np.maximum(true, 1 - true), (true - 0.5).abs()).mean()
    assert tab.loc[0, "failed"] == nan.sum() and tab.loc[0, "coverage_mae"] == pytest.approx(100 * expected)


def test_cli_evaluates_the_real_methods_in_parallel_like_in_one_process(smoke_dataset, tmp_path, capsys):
    data, _ = smoke_dataset
    methods = "completion,thresholding,unwrap,gt-heatmap,unwrap-gt"
    assert main(["evaluate", str(data), "--methods", methods, "--out", str(tmp_path / "one"), "--quiet"]) == 0
    assert main(["evaluate", str(data), "--methods", methods, "--out", str(tmp_path / "two"), "--workers", "2",
                 "--quiet"]) == 0
    _, one = load_results(tmp_path / "one")
    _, two = load_results(tmp_path / "two")
    keys = ["method", "shard", "index", "noise_mm"]
    one, two = one.sort_values(keys).reset_index(drop=True), two.sort_values(keys).reset_index(drop=True)
    assert (one["error"] == "").all(), one["error"].unique()
    pd.testing.assert_frame_equal(one.drop(columns="seconds"), two.drop(columns="seconds"))
    gt = one[one["method"] == "gt-heatmap"]
    assert gt["coverage_error"].abs().max() < 0.05 and (gt["centerline_recall_2mm"] > 0.95).all()
    assert len(list((tmp_path / "one" / "examples" / "completion").glob("*.npz"))) >= 2
    capsys.readouterr()
    assert main(["leaderboard", str(tmp_path / "one"), "--out", str(tmp_path / "lb")]) == 0
    out = capsys.readouterr().out
    assert "## Noise sigma = 0.5 mm" in out and "| gt-heatmap * |" in out
    assert any(p.name.startswith("triplets-completion") for p in (tmp_path / "lb").iterdir())
    assert main(["methods"]) == 0
    assert "unwrap-pca" in capsys.readouterr().out
    assert main(["evaluate", str(data), "--methods", "nope", "--out", str(tmp_path / "x")]) == 2
    assert main(["leaderboard", str(tmp_path / "x2"), "--out", str(tmp_path / "lb2")]) == 2
    assert "not a colonbench run" in capsys.readouterr().err


def test_estimate_runs_any_registered_method_but_not_references(smoke_dataset, tmp_path, capsys):
    from colonbench.shards.reader import ShardDataset

    data, _ = smoke_dataset
    np.save(tmp_path / "seg.npy", ShardDataset(data, split="test", geometry=True)[0]["partial_points"])
    assert main(["estimate", str(tmp_path / "seg.npy"), "--method", "unwrap-pca", "--out-dir", str(tmp_path / "o")]) == 0
    assert json.loads((tmp_path / "o" / "seg.json").read_text())["method"] == "unwrap-pca"
    assert main(["estimate", str(tmp_path / "seg.npy"), "--method", "gt-heatmap", "--out-dir", str(tmp_path / "o")]) == 2
    assert "needs ground truth" in capsys.readouterr().err


def test_two_evaluations_never_share_a_run_folder(smoke_dataset, tmp_path):
    from colonbench.folderlock import folder_lock

    data, _ = smoke_dataset
    out = tmp_path / "run"
    out.mkdir()
    with folder_lock(out, "evaluate", "evaluation"):  # as a running evaluation holds it
        with pytest.raises(InputError, match="another evaluation is running"):
            evaluate(data, ["constant"], out, progress=False)
    evaluate(data, ["constant"], out, progress=False)  # released with its holder
    assert (out / "results" / "constant.csv").exists()
    assert not (out / ".evaluate.lock").exists()  # a finished run leaves no lock file behind


def test_a_rerun_says_how_many_stored_failures_it_kept_and_how_to_retry_them(smoke_dataset, tmp_path, capsys):
    data, _ = smoke_dataset
    args = ["evaluate", str(data), "--methods", "constant,plugin_methods:Broken", "--out", str(tmp_path / "run"),
            "--noise", "0", "--quiet"]
    assert main(args) == 0
    failed = int((read_rows(tmp_path / "run" / "results" / "broken.csv")["error"] != "").sum())
    assert failed > 0 and "stored failure" not in capsys.readouterr().err    # nothing stored the first time
    assert main(args) == 0
    lines = [x for x in capsys.readouterr().err.splitlines() if "stored failure" in x]
    assert lines == [f"colonbench: warning: broken: {failed} stored failure(s) of an earlier run in "
                     f"{tmp_path / 'run'} kept, not evaluated again (--retry-failed evaluates them again)"]


def test_a_changed_exec_method_is_refused_saying_its_version_is_the_hash_of_its_command(smoke_dataset, tmp_path,
                                                                                          capsys):
    import sys
    from pathlib import Path

    data, _ = smoke_dataset
    script = tmp_path / "mine.py"
    example = Path(__file__).resolve().parents[1] / "examples" / "constant_method.py"
    script.write_text(example.read_text())
    args = ["evaluate", str(data), "--methods", f"exec:{sys.executable} {script}", "--out", str(tmp_path / "run"),
            "--noise", "0", "--limit", "1", "--quiet"]
    assert main(args) == 0
    script.write_text(example.read_text().replace('"coverage": 0.8', '"coverage": 0.7'))
    capsys.readouterr()
    assert main(args) == 2
    err = capsys.readouterr().err
    assert "method 'mine' was evaluated as version 'command:" in err and "Traceback" not in err
    assert "an exec: method's version is a hash of its command line and of the files it names (its script)" in err
    assert "evaluate into a new run folder (colonbench benchmark: another --out), or undo the change" in err


def test_a_failure_warning_names_the_sample_of_its_first_failure(demo_data, tmp_path, capsys):
    from colonbench.commands.benchmark import warn_failures
    from colonbench.pipeline import run_benchmark

    class Third:                                        # fails on its third segment, at noise 0
        name, version, calls = "third", "1", 0

        def estimate(self, points):
            self.calls += 1
            if self.calls == 3:
                raise ValueError("the third segment")
            return {"coverage": 0.5}

    result = run_benchmark([Third()], "demo-v1", tmp_path / "bench", data=demo_data, figures=False, progress=False,
                           shipped=False, submitted=False)
    rows = read_rows(tmp_path / "bench" / "runs" / "demo-v1" / "results" / "third.csv")
    (sid,) = rows.loc[rows["error"] != "", "sample_id"]
    warn_failures(result["failures"], lambda suite: tmp_path / "bench" / "runs" / suite / "results")
    (line,) = [x for x in capsys.readouterr().err.splitlines() if x.startswith("colonbench: warning: third")]
    assert "failed on 1 of 24 samples of demo-v1 at noise 0 mm" in line, line
    assert f"first: {sid}: ValueError: the third segment" in line, line
