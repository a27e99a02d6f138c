"""The benchmark release: named suites and their hashes, exec: and offline methods, shipped results, one command."""

import json
import re
import shutil
import sys
from pathlib import Path

import h5py
import numpy as np
import pandas as pd
import pytest

from colonbench.benchmark import shipped, suites, tracks
from colonbench.benchmark.evaluate import evaluate as cb_evaluate
from colonbench.cli import main
from colonbench.errors import InputError

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "constant_method.py"
#: A program outside colonbench that gets one thing wrong per input, by the input's position in its call.
FAULTY = '''
import json, sys, time
from pathlib import Path
args = sys.argv[1:]
out = Path(args[args.index("--out-dir") + 1]); out.mkdir(parents=True, exist_ok=True)
files = [Path(a) for a in args if a.endswith(".ply")]
answers = [{"coverage": 0.7, "holes": [[0, 0, 0]], "centerline": [[0, 0, 0], [0, 0, 1]]},
           None, {"coverage": float("nan")}, {"coverage": 1.5}, {"coverage": 0.5, "holes": [[1, 2]]}, "{not json"]
for k, f in enumerate(files):
    a = answers[k % len(answers)]
    if a is not None:
        (out / (f.stem + ".json")).write_text(a if isinstance(a, str) else json.dumps(a))
sys.exit(3 if "--crash" in args else 0)
'''


# ------------------------------------------------------------------------------------------------ the registry


def test_registry_names_every_v1_suite_with_its_manifest(tmp_path):
    ids = [s.id for s in suites.SUITES]
    assert ids == ["demo-v1", "paper-v1", "wide-v1", "real-v1", "video-v1", "colon-v1"]
    assert len(set(s.sha256 for s in suites.SUITES)) == len(ids)
    for s in suites.SUITES:
        assert suites.manifest_path(s).is_file(), s.manifest
        assert s.sha256.startswith("cb1-") and len(s.sha256) == 4 + 64
        assert re.fullmatch(r"cbs1-[0-9a-f]{12}", s.signature) and suites.published_signature(s)["suite"] == s.id
        assert s.tests and s.samples > 0 and s.noise_mm == (0.0, 0.5)
    assert suites.get("paper").id == "paper-v1" and suites.get("real-v1").manifest == "real-test.yaml"
    assert [s.id for s in suites.parse("all")] == ids
    assert [s.id for s in suites.parse("real,demo-v1,real-v1")] == ["real-v1", "demo-v1"]
    with pytest.raises(InputError, match="unknown suite 'paper-v9'"):
        suites.get("paper-v9")
    # a suite built from a download, asked for before any is built, is told how to build it
    with pytest.raises(InputError, match="colonbench suites build c3vd --from DIR"):
        suites.get("c3vd", root=tmp_path)


def test_hashing_rounds_to_a_micrometre():
    from colonbench.benchmark.fingerprint import _Hasher

    def digest(points):
        h = _Hasher()
        h.lengths("input", points)
        return h.hexdigest()

    p = np.array([[10.0001, 20.0, 30.0], [1.0, 2.0, 3.0]])
    assert digest(p) == digest(p + 1e-9)             # float noise far below the rounding step
    assert digest(p) != digest(p + [[0, 0, 0], [0.002, 0, 0]])   # one coordinate 2 µm off
    assert digest(p) != digest(p[::-1])              # the order is part of the data


def test_demo_v1_regenerates_to_the_published_suite(demo_data):
    """CI's check that the generator still makes the published suite (a change that moves it needs demo-v2):
    every sample verifies against its published signature, bit-identical or within tolerance."""
    suite = suites.get("demo-v1")
    result = suites.check(suite, suites.data_dir(suite, demo_data))
    assert result.verified, result.summary()
    assert len(result.samples) == 24 and not result.faults


@pytest.mark.slow
def test_real_v1_regenerates_to_the_published_suite(tmp_path):
    suite = suites.get("real-v1")
    data = suites.ensure_data(suite, tmp_path, workers=2, progress=False)
    result = suites.check(suite, data)
    assert result.verified, result.summary()


def test_a_tampered_sample_is_refused(demo_data, tmp_path, capsys):
    suite = suites.get("demo-v1")
    data = tmp_path / "demo-v1"
    shutil.copytree(suites.data_dir(suite, demo_data), data)
    shard = sorted((data / "test").glob("*.h5"))[0]
    with h5py.File(shard, "r+") as h5:
        pts = h5["samples/partial_points"]
        pts[5] = pts[5] + np.float32(1.0)          # one point moved by 1 mm along each axis
    assert main(["evaluate", str(data), "--methods", "constant", "--out", str(tmp_path / "run"), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "does not hold suite demo-v1" in err and "--allow-unverified" in err
    assert f"sample test_{shard.stem}_000_noise0: input@0" in err and "off the surface" in err
    assert main(["evaluate", str(data), "--methods", "constant", "--out", str(tmp_path / "run"), "--quiet",
                 "--allow-unverified"]) == 0
    rec = json.loads((tmp_path / "run" / "run.json").read_text())["suite"]
    assert rec["id"] == "demo-v1" and rec["verified"] is False and rec["sha256"] != suite.sha256
    assert main(["leaderboard", str(tmp_path / "run"), "--out", str(tmp_path / "lb"), "--no-figures"]) == 0
    assert "**unverified**" in (tmp_path / "lb" / "leaderboard.md").read_text()
    assert main(["leaderboard", str(tmp_path / "run"), "--out", str(tmp_path / "lb2"), "--shipped"]) == 2
    assert "not the published demo-v1" in capsys.readouterr().err


# ------------------------------------------------------------------------------------------------ other programs


def test_a_program_outside_colonbench_joins_the_shipped_leaderboard(demo_data, tmp_path, capsys):
    """The README's promise: a 10-line script writing a constant, on demo-v1, beside the shipped results."""
    out = tmp_path / "bench"
    assert main(["benchmark", "--methods", f"exec:{sys.executable} {EXAMPLE}", "--suites", "demo-v1",
                 "--data", str(demo_data), "--out", str(out), "--quiet", "--no-figures"]) == 0
    summary = pd.read_csv(out / "leaderboard.csv")
    published = shipped.load(suites.get("demo-v1"))
    assert published is not None, "benchmark/shipped_results/demo-v1 is missing: python scripts/reference_results.py"
    assert set(summary["method"]) == {"constant_method"} | set(published[0]["methods"])
    assert (summary.loc[summary["method"] != "constant_method", "source"] == "shipped").all()
    mine = pd.read_csv(out / "runs" / "demo-v1" / "results" / "constant_method.csv")
    assert (mine["error"].isna()).all() and np.allclose(mine["coverage"], 0.8)
    assert np.allclose(mine["coverage_error"], 0.8 - mine["true_coverage"])
    row = summary[(summary["method"] == "constant_method") & (summary["noise_mm"] == 0)].iloc[0]
    assert row["mae"] == pytest.approx(100 * np.abs(0.8 - mine["true_coverage"]).mean() / 1)
    assert row["mae_lo"] < row["mae"] < row["mae_hi"]
    page = (out / "suites" / "demo-v1" / "leaderboard.md").read_text()
    assert f"verified against its signature `{suites.get('demo-v1').signature}`" in page
    assert "constant_method" in (out / "leaderboard.md").read_text()
    # the same through export + score
    inputs, preds = tmp_path / "inputs", tmp_path / "preds"
    assert main(["export", "demo-v1", "--data", str(demo_data), "--out", str(inputs), "--quiet"]) == 0
    index = pd.read_csv(inputs / "index.csv")
    assert len(index) == 24 * 2 and (inputs / index["file"].iloc[0]).is_file()
    assert not any("coverage" in c for c in index.columns)        # no truth in an export
    files = [str(inputs / f) for f in index["file"]]
    import subprocess

    subprocess.run([sys.executable, str(EXAMPLE), *files, "--out-dir", str(preds)], check=True)
    run = tmp_path / "scored"
    assert main(["score", "demo-v1", str(preds), "--name", "constant_method", "--data", str(demo_data),
                 "--out", str(run), "--quiet"]) == 0
    scored = pd.read_csv(run / "results" / "constant_method.csv")
    key = ["shard", "index", "noise_mm"]
    a, b = mine.set_index(key).sort_index(), scored.set_index(key).sort_index()
    assert np.array_equal(a["coverage_error"], b["coverage_error"])
    assert main(["leaderboard", str(run), "--out", str(tmp_path / "lb"), "--shipped", "--no-figures"]) == 0
    text = (tmp_path / "lb" / "leaderboard.md").read_text()
    assert "constant_method" in text and "| completion † |" in text    # the shipped rows marked
    # one malformed prediction: score says which file and why, as benchmark does
    bad = preds / f"{index['sample_id'].iloc[-1]}.json"
    bad.write_text('{"coverage": 1.5}')
    capsys.readouterr()
    assert main(["score", "demo-v1", str(preds), "--data", str(demo_data), "--out", str(tmp_path / "scored2"),
                 "--quiet"]) == 0
    out, err = capsys.readouterr()
    assert "24 of 24 segments, 1 without a valid prediction (scored as the farther of coverage 0 and 1)" in out
    (warning,) = [x for x in err.splitlines() if x.startswith("colonbench: warning:")]
    assert f"failed on 1 of 24 samples of demo-v1 at noise {index['noise_mm'].iloc[-1]:g} mm" in warning
    assert f"first: {bad.name}: coverage 1.5 is not a fraction in [0, 1]" in warning
    assert str(tmp_path / "scored2" / "results") in warning


def test_exec_colonbench_estimate_gives_the_in_process_results(demo_data, tmp_path, monkeypatch):
    suite = suites.get("demo-v1")
    data = suites.data_dir(suite, demo_data)
    colonbench = Path(sys.executable).with_name("colonbench")
    from colonbench.benchmark.evaluate import evaluate

    import torch

    from colonbench.completion import method as completion_method

    # a fresh predictor, as in the program's new process: a process runs its first cloud on the network as loaded
    # and the later ones on the network prepared for inference (equal to 1e-5), so both must start alike
    monkeypatch.setattr(completion_method, "_PREDICTORS", {})
    threads = torch.get_num_threads()
    torch.set_num_threads(1)   # the network's sums run in the same order in both processes (one thread each)
    try:
        run = evaluate(data, ["completion", f"viaexec=exec:env OMP_NUM_THREADS=1 {colonbench} estimate --method "
                                            "completion"], tmp_path / "run", limit=4, progress=False, examples=0)
    finally:
        torch.set_num_threads(threads)
    rows = pd.read_csv(run / "results" / "completion.csv")
    other = pd.read_csv(run / "results" / "viaexec.csv")
    assert (other["error"].isna()).all()
    assert np.array_equal(rows["coverage"], other["coverage"])        # exactly: JSON floats round-trip
    metrics = [c for c in rows.columns if "precision" in c or "recall" in c]
    assert np.allclose(rows[metrics], other[metrics], equal_nan=True)


def test_bad_outputs_are_that_segments_failure(demo_data, tmp_path):
    program = tmp_path / "faulty.py"
    program.write_text(FAULTY)
    data = suites.data_dir(suites.get("demo-v1"), demo_data)
    from colonbench.benchmark.evaluate import evaluate

    run = evaluate(data, [f"exec:{sys.executable} {program}"], tmp_path / "run", noise=[0], limit=12,
                   progress=False, batch=6)
    rows = pd.read_csv(run / "results" / "faulty.csv").fillna({"error": ""})
    assert len(rows) == 12
    errors = list(rows["error"])
    # inputs go in sample order, six per call: each call's k-th input gets the k-th answer
    assert errors[0] == "" and rows["coverage"].iloc[0] == 0.7
    assert "exited with status 0 without writing" in errors[1] and "_noise0.json or" in errors[1]
    assert "not a fraction in [0, 1]" in errors[2] and "nan" in errors[2]
    assert "1.5 is not a fraction" in errors[3]
    assert "'holes' has shape (1, 2)" in errors[4]
    assert "not valid JSON" in errors[5]
    kinds = [re.sub(r"call-\d+", "CALL", re.sub(r"test_colon\S+?_noise0", "ID", e)) for e in errors]  # another sample
    assert kinds[6:] == kinds[:6]
    assert rows["coverage_error"].isna().sum() == 10   # failures are counted, not dropped
    # a crash and a timeout: the program's own words end up in the rows
    crash = evaluate(data, [f"exec:{sys.executable} {program} --crash"], tmp_path / "crash", noise=[0], limit=2,
                     progress=False)
    err = pd.read_csv(crash / "results" / "faulty.csv")["error"].fillna("")
    assert err.iloc[0] == "" and "exited with status 3" in err.iloc[1]
    sleeper = tmp_path / "sleeper.py"
    sleeper.write_text("import time; time.sleep(30)\n")
    slow = evaluate(data, [f"exec:{sys.executable} {sleeper}"], tmp_path / "slow", noise=[0], limit=2,
                    progress=False, timeout=0.5)
    assert pd.read_csv(slow / "results" / "sleeper.csv")["error"].str.contains("stopped after 1 s").all()


def test_each_noise_levels_warning_names_a_failure_at_that_noise_level(demo_data, tmp_path, capsys):
    program = tmp_path / "faulty.py"
    program.write_text(FAULTY)
    out = tmp_path / "bench"
    assert main(["benchmark", "--methods", f"exec:{sys.executable} {program}", "--suites", "demo-v1", "--data",
                 str(demo_data), "--out", str(out), "--quiet", "--no-figures"]) == 0
    warnings = [x for x in capsys.readouterr().err.splitlines() if x.startswith("colonbench: warning: faulty")]
    rows = pd.read_csv(out / "runs" / "demo-v1" / "results" / "faulty.csv").fillna({"error": ""})
    assert len(warnings) == 2
    for noise, line in zip((0.0, 0.5), warnings):
        first = rows[(rows["noise_mm"] == noise) & (rows["error"] != "")]["error"].iloc[0]
        assert f"at noise {noise:g} mm, scored as the farther of coverage 0 and 1; first: {first} (" in line
        assert f"_noise{noise:g}.json" in line and f"_noise{0.5 - noise:g}.json" not in line


def test_a_method_object_from_a_notebook(demo_data):
    import colonbench as cb

    class Half:  # defined here, importable from nowhere: it runs in this process
        name = "half"

        def estimate(self, points):
            return {"coverage": 0.5}

    result = cb.benchmark(Half(), "demo-v1", data=demo_data, progress=False, figures=False, workers=2)
    mine = result["summary"][result["summary"]["method"] == "half"]
    assert len(mine) == 2 and (mine["source"] != "shipped").all()
    # the folder it made is kept, and the markdown says where its pages are
    out = Path(result["out"])
    try:
        page = out / "suites" / "demo-v1" / "leaderboard.md"
        assert page.is_file() and str(page) in result["markdown"] and str(out / "leaderboard.md") in result["markdown"]
        assert "temporary folder" in result["markdown"]
        assert result["markdown"].startswith((out / "leaderboard.md").read_text())
    finally:
        shutil.rmtree(out)
    est = cb.load_method("constant").estimate(np.zeros((10, 3)))
    assert isinstance(est, cb.Estimate) and isinstance(cb.load_method("constant"), cb.Method)


def test_a_method_object_that_fails_everywhere_fails_the_run(demo_data, tmp_path):
    import colonbench as cb
    from colonbench.pipeline import RunFailed

    class Broken:
        name = "broken"

        def estimate(self, points):
            raise ValueError("no model here")

    with pytest.raises(RunFailed, match="broken failed on every sample .*no model here.*no leaderboard") as info:
        cb.benchmark(Broken(), "demo-v1", out=tmp_path / "b", data=demo_data, progress=False, figures=False)
    failures = info.value.failures
    assert len(failures) == 2 and (failures["failed"] == failures["samples"]).all()
    assert failures["first_error"].str.contains("no model here").all()
    assert sorted(p.name for p in (tmp_path / "b").iterdir()) == ["runs"]


def test_dask_gives_the_single_process_results(demo_data, tmp_path):
    from distributed import LocalCluster

    from colonbench.benchmark.evaluate import evaluate

    data = suites.data_dir(suites.get("demo-v1"), demo_data)
    one = evaluate(data, ["unwrap-pca", "constant"], tmp_path / "one", limit=6, progress=False)
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster:
        dask = evaluate(data, ["unwrap-pca", "constant"], tmp_path / "dask", limit=6, progress=False,
                        scheduler=cluster.scheduler_address)
    for m in ("unwrap-pca", "constant"):
        a = pd.read_csv(one / "results" / f"{m}.csv").drop(columns="seconds")
        b = pd.read_csv(dask / "results" / f"{m}.csv").drop(columns="seconds")
        pd.testing.assert_frame_equal(a, b)


# ------------------------------------------------------------------------------------------------ shipped results


def test_shipped_results_are_of_the_published_suites_and_todays_methods():
    from colonbench.benchmark.colon_evaluate import ALL_METHODS
    from colonbench.benchmark.registry import DEFAULT_METHODS, load_method

    versions = {}
    for suite, track in [(s, t) for s in suites.SUITES for t in tracks.TRACKS]:
        item = shipped.load(suite, track=track)
        if track != tracks.DEFAULT:   # the known-length track's, where they ship: held to the same checks
            assert suite.task != "colon" or not shipped.folder(suite, track).exists(), suite.id
            if item is None and not shipped.folder(suite, track).exists():
                continue
            assert item is not None and tracks.of_run(item[0]) == track, f"{suite.id}@{track}: other data or track"
        assert item is not None, f"no shipped results of {suite.id} (or made on other data)"
        run = item[0]
        assert run["suite"]["sha256"] == suite.sha256 and run["suite"]["verified"]
        assert "data_path" not in run
        built_in = set(ALL_METHODS if suite.task == "colon" else DEFAULT_METHODS)
        assert built_in <= set(run["methods"]), f"{suite.id}: no shipped rows of {built_in - set(run['methods'])}"
        for name, rec in run["methods"].items():
            if name not in versions:
                versions[name] = load_method(name).version
            assert rec["version"] == versions[name], f"{suite.id}: {name} shipped as {rec['version']}"
            own = rec.get("suite")      # rows made again on data within tolerance of the published data (0327)
            assert own is None or (suite.task != "colon" and own["check"] == "within tolerance"
                                   and own["bit_identical"] is False and own["sha256"] != suite.sha256
                                   and re.fullmatch(r"cb1-[0-9a-f]{64}", own["sha256"])
                                   and isinstance(own["tie_samples"], int)), f"{suite.id}: {name}'s data {own}"
        if track != tracks.DEFAULT:
            assert run["methods"]["completion"].get("takes_length"), f"{suite.id}@{track}: completion took no length"
        rows = item[1]
        assert len(rows) > 0 and rows["method"].isin(run["methods"]).all()


def test_cli_lists_suites_and_says_what_each_verb_does(capsys):
    assert main(["suites"]) == 0
    out = capsys.readouterr().out
    for s in suites.SUITES:
        assert s.id in out and s.sha256 in out
    from colonbench.cli import build_parser

    verbs = build_parser()._subparsers._group_actions[0].choices
    assert {"suites", "benchmark", "export", "score", "video", "estimate"} <= set(verbs)
    for verb in verbs:   # every verb's --help opens with one line saying what it does, then its usage
        with pytest.raises(SystemExit):
            main([verb, "--help"])
        lines = capsys.readouterr().out.splitlines()
        assert lines[0][0].isupper() and lines[0].endswith(".") and not lines[0].startswith("usage"), verb
        assert lines[2].startswith(f"usage: colonbench {verb}"), verb
    assert main(["benchmark", "--suites", "paper-v7", "--out", "x"]) == 2
    assert "unknown suite" in capsys.readouterr().err


def test_every_data_option_names_where_the_code_caches_suites(capsys, monkeypatch, tmp_path):
    """The --data help of every verb that reads suite data names the places default_data_root looks, in its order."""
    monkeypatch.delenv("COLONBENCH_DATA", raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    assert suites.default_data_root() == tmp_path / "colonbench" / "suites"
    for verb in ("suites", "benchmark", "export", "score"):
        with pytest.raises(SystemExit):
            main([verb, "--help"])
        text = " ".join(capsys.readouterr().out.split())
        places = [text.find(p) for p in ("$COLONBENCH_DATA", "$XDG_CACHE_HOME/colonbench/suites",
                                         "~/.cache/colonbench/suites")]
        assert -1 not in places and places == sorted(places), verb


def test_programs_that_cannot_run_and_predictions_that_match_nothing_say_so(demo_data, tmp_path, capsys):
    data = ["--suites", "demo-v1", "--data", str(demo_data), "--quiet", "--no-figures"]
    assert main(["benchmark", "--methods", "exec:no-such-program --fast", "--out", str(tmp_path / "a"), *data]) == 2
    assert "no program 'no-such-program'" in capsys.readouterr().err
    # a script the command line names that is not there: refused before anything runs or is written
    for spec in (f"exec:{sys.executable} {tmp_path / 'missing.py'}", f"mine=exec:{sys.executable} missing.py --fast"):
        assert main(["benchmark", "--methods", spec, "--out", str(tmp_path / "b"), *data]) == 2
        err = capsys.readouterr().err
        assert "missing.py" in err and "no such file" in err and "Traceback" not in err
        assert not (tmp_path / "b").exists()
    with pytest.raises(InputError, match="missing.py"):
        cb_evaluate(suites.data_dir(suites.get("demo-v1"), demo_data), [f"exec:{sys.executable} missing.py"],
                    tmp_path / "run", noise=[0], limit=1, progress=False)
    assert not (tmp_path / "run").exists()
    # a program that starts and fails on every input: its rows say why, and the command fails
    crash = tmp_path / "crash.py"
    crash.write_text("import sys\nprint('cannot load my model', file=sys.stderr)\nsys.exit(2)\n")
    assert main(["benchmark", "--methods", f"exec:{sys.executable} {crash}", "--out", str(tmp_path / "b"), *data]) == 2
    err = capsys.readouterr().err
    assert "failed on every sample" in err and "exited with status 2" in err and "cannot load my model" in err
    # a failed run writes no tables: only the run folder, whose rows say why, is left
    assert "no leaderboard was written" in err
    assert sorted(p.name for p in (tmp_path / "b").iterdir()) == ["runs"]
    errors = pd.read_csv(tmp_path / "b" / "runs" / "demo-v1" / "results" / "crash.csv")["error"]
    assert errors.str.contains("exited with status 2").all()    # the program's words are quoted once, on the first
    assert errors.str.contains("cannot load my model").sum() == 1
    assert errors.str.contains("its end is quoted on").sum() == len(errors) - 1
    # nor does it leave the tables of an earlier run there, which no longer describe the folder's runs
    good = ["--methods", f"exec:{sys.executable} {EXAMPLE}", "--out", str(tmp_path / "g"), *data]
    assert main(["benchmark", *good]) == 0 and (tmp_path / "g" / "leaderboard.md").is_file()
    assert main(["benchmark", "--methods", f"exec:{sys.executable} {crash}", "--out", str(tmp_path / "g"), *data]) == 2
    assert sorted(p.name for p in (tmp_path / "g").iterdir()) == ["runs", "suites"]
    assert not (tmp_path / "g" / "suites" / "demo-v1").exists()
    # the failed method is not this call's: the tables are written again, its cells missing
    assert main(["benchmark", *good]) == 0
    assert "| crash | " in (tmp_path / "g" / "leaderboard.md").read_text()
    capsys.readouterr()
    # predictions named otherwise than the export names its inputs
    preds = tmp_path / "preds"
    preds.mkdir()
    (preds / "segment1.json").write_text('{"coverage": 0.5}')
    assert main(["score", "demo-v1", str(preds), "--out", str(tmp_path / "c"), "--data", str(demo_data),
                 "--quiet"]) == 2
    assert "none of its 1 .json files is named by a sample id of demo-v1" in capsys.readouterr().err


def test_an_edited_script_is_another_version(demo_data, tmp_path):
    from colonbench.benchmark.evaluate import RunMismatch, evaluate

    script = tmp_path / "mine.py"
    script.write_text(EXAMPLE.read_text())
    data = suites.data_dir(suites.get("demo-v1"), demo_data)
    evaluate(data, [f"exec:{sys.executable} {script}"], tmp_path / "run", noise=[0], limit=2, progress=False)
    script.write_text(EXAMPLE.read_text().replace('"coverage": 0.8', '"coverage": 0.7'))
    with pytest.raises(RunMismatch, match="method 'mine' was evaluated as version"):
        evaluate(data, [f"exec:{sys.executable} {script}"], tmp_path / "run", noise=[0], limit=2, progress=False)


def test_a_reproduction_may_move_threshold_metrics_by_a_few_points_and_coverages_by_float_noise():
    """shipped.differences on rows of known answers: what another machine may change passes, what it may not fails."""
    ref = pd.DataFrame({"shard": ["s"] * 3, "index": [0, 1, 2], "noise_mm": [0.0] * 3, "coverage": [0.5, 0.7, 0.9],
                        "holes_recall_1mm": [0.5, 0.25, np.nan], "holes_true_n": [1000, 100, 0],
                        "holes_precision_1mm": [0.5, 0.5, np.nan], "holes_n": [10, 200, 0]})

    def moved(**cells):
        out = ref.copy()
        for col, (k, v) in cells.items():
            out.loc[k, col] = v
        return out

    assert shipped.differences(ref, ref).empty
    ok = moved(coverage=(0, 0.5 + 5e-7), holes_recall_1mm=(0, 0.5 + 3 / 1000), holes_n=(1, 203))
    assert shipped.differences(ok, ref).empty
    # rows made before the counts were kept: the counts of the other side
    assert shipped.differences(ok, ref.drop(columns=["holes_true_n", "holes_n"])).empty
    for col, (k, v) in {"coverage": (0, 0.5 + 3e-3), "holes_recall_1mm": (0, 0.5 + 4 / 1000),
                        "holes_precision_1mm": (0, 0.5 + 0.4), "holes_n": (1, 204),
                        "holes_recall_1mm ": (2, 0.0)}.items():
        diff = shipped.differences(moved(**{col.strip(): (k, v)}), ref)
        assert list(diff["column"]) == [col.strip()] and list(diff["index"]) == [k], col
    # a coverage counts vertices: one row of the three may move by a few vertices' share, not two, not by more
    assert shipped.differences(moved(coverage=(1, 0.7 + 1e-3)), ref).empty
    assert list(shipped.differences(moved(coverage=(1, 0.7 + 3e-3)), ref)["column"]) == ["coverage"]
    two = moved(coverage=(1, 0.7 + 1e-3))
    two.loc[2, "coverage"] = 0.9 - 1e-3
    assert len(shipped.differences(two, ref)) == 2
    # a method no float noise moves (EXACT) gets no flipped row; rows without counts on either side: float noise only
    assert list(shipped.differences(moved(coverage=(1, 0.7 + 1e-3)), ref, counted=False)["column"]) == ["coverage"]
    bare = ref.drop(columns=["holes_true_n", "holes_n"])
    assert list(shipped.differences(moved(holes_recall_1mm=(0, 0.9)).drop(columns=["holes_true_n", "holes_n"]),
                                    bare)["column"]) == ["holes_recall_1mm"]
    with pytest.raises(ValueError, match="other segments"):
        shipped.differences(ref.iloc[:2], ref)
