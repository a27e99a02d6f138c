"""The known-length track (benchmark 1.1): each segment's nominal arc length given to the methods that take it."""

import json
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from colonbench.benchmark import shipped, suites, tracks
from colonbench.benchmark.evaluate import evaluate, load_results, noisy
from colonbench.benchmark.runfolder import RunMismatch
from colonbench.cli import main
from colonbench.errors import InputError
from colonbench.reports.leaderboard import write_leaderboard

#: A program that answers with the length it was given, as a coverage (50 mm -> 0.50), and 0.01 when given none;
#: every call's arguments go into calls.txt beside it.
ECHO = r'''
import json, sys
from pathlib import Path
args = sys.argv[1:]
with open(Path(__file__).with_name("calls.txt"), "a") as fh:
    fh.write(json.dumps(args) + "\n")
out = Path(args[args.index("--out-dir") + 1]); out.mkdir(parents=True, exist_ok=True)
length = float(args[args.index("--length-mm") + 1]) if "--length-mm" in args else None
for f in (Path(a) for a in args if a.endswith(".ply")):
    (out / f"{f.stem}.json").write_text(json.dumps({"coverage": 0.01 if length is None else length / 100,
                                                   "length_got": length}))
'''
#: A program that knows no --length-mm: argparse refuses the flag (exit status 2) before it answers anything.
STRICT = r'''
import argparse, json
from pathlib import Path
ap = argparse.ArgumentParser()
ap.add_argument("files", nargs="+")
ap.add_argument("--out-dir", required=True)
args = ap.parse_args()
for f in map(Path, args.files):
    Path(args.out_dir).mkdir(parents=True, exist_ok=True)
    (Path(args.out_dir) / f"{f.stem}.json").write_text(json.dumps({"coverage": 0.5}))
'''


class Ruler:
    """Answers with the length it is given (as a coverage), 0.01 without one."""

    name, version = "ruler", "1"

    def estimate(self, points, length_mm=None):
        return {"coverage": 0.01 if length_mm is None else length_mm / 100}


class Blind:
    """Takes no length."""

    name, version = "blind", "1"

    def estimate(self, points):
        return {"coverage": 0.5}


def program(folder: Path, text: str, name: str) -> str:
    folder.mkdir(parents=True, exist_ok=True)
    (folder / f"{name}.py").write_text(text)
    return f"exec:{sys.executable} {folder / name}.py"


@pytest.fixture(scope="module")
def demo(demo_data):
    return suites.data_dir(suites.get("demo-v1"), demo_data)


def test_a_python_method_gets_each_segments_length_on_the_length_track_only(demo, tmp_path):
    runs = {t: evaluate(demo, [Ruler(), Blind()], tmp_path / t, noise=(0.0,), limit=8, progress=False, examples=0,
                        track=t) for t in tracks.TRACKS}
    run, rows = load_results(runs["length"])
    ruler = rows[rows["method"] == "ruler"]
    assert run["track"] == "length" and set(ruler["length_mm"]) == {50.0, 60.0, 70.0}
    assert np.allclose(ruler["coverage"], ruler["length_mm"] / 100)            # the nominal length, per segment
    assert run["methods"]["ruler"]["takes_length"] is True and run["methods"]["blind"]["takes_length"] is False
    run, rows = load_results(runs["points"])
    assert run["track"] == "points" and np.allclose(rows.loc[rows["method"] == "ruler", "coverage"], 0.01)
    assert "takes_length" not in run["methods"]["ruler"]
    # the leaderboard of the length track says which method took no length; the points one has no such column
    text = write_leaderboard([runs["length"]], tmp_path / "lb", figures=False)["markdown"]
    assert "| blind | 1 | takes none |" in text and "| ruler | 1 | given |" in text
    assert "Known-length track" in text
    tab = pd.read_csv(tmp_path / "lb" / "leaderboard.csv")
    assert dict(zip(tab["method"], tab["takes_length"])) == {"blind": False, "ruler": True}
    assert "takes_length" not in pd.read_csv(write_leaderboard([runs["points"]], tmp_path / "lb0", figures=False)[
        "paths"][1]).columns


def test_a_run_folder_keeps_its_track_and_a_leaderboard_never_mixes_tracks(demo, tmp_path, capsys):
    a = evaluate(demo, [Blind()], tmp_path / "points", noise=(0.0,), limit=3, progress=False, examples=0)
    b = evaluate(demo, [Ruler()], tmp_path / "length", noise=(0.0,), limit=3, progress=False, examples=0,
                 track="length")
    with pytest.raises(RunMismatch, match="is a run of the known-length track, not the points-only track"):
        evaluate(demo, [Blind()], b, noise=(0.0,), limit=3, progress=False, examples=0)
    with pytest.raises(RunMismatch, match="is a run of the points-only track, not the known-length track"):
        evaluate(demo, [Ruler()], a, noise=(0.0,), limit=3, progress=False, examples=0, track="length")
    with pytest.raises(InputError, match="a leaderboard never mixes tracks"):
        write_leaderboard([a, b], tmp_path / "lb", figures=False)
    assert main(["leaderboard", str(a), str(b), "--out", str(tmp_path / "lb"), "--no-figures"]) == 2
    assert "never mixes tracks" in capsys.readouterr().err
    with pytest.raises(InputError, match="unknown track 'lengths'"):
        evaluate(demo, [Ruler()], tmp_path / "x", noise=(0.0,), limit=3, progress=False, track="lengths")


def test_an_exec_program_gets_length_mm_once_per_length(demo, tmp_path):
    spec = program(tmp_path / "echo", ECHO, "echo")
    run = evaluate(demo, [spec], tmp_path / "run", noise=(0.0, 0.5), limit=6, progress=False, examples=0,
                   track="length")
    _, rows = load_results(run)
    assert (rows["error"] == "").all() and np.allclose(rows["coverage"], rows["length_mm"] / 100)
    got = {p.stem: json.loads(p.read_text())["length_got"] for p in (run / "predictions" / "echo").glob("*.json")}
    assert got == dict(zip(rows["sample_id"], rows["length_mm"]))
    calls = [json.loads(x) for x in (tmp_path / "echo" / "calls.txt").read_text().splitlines()]
    lengths = [c[c.index("--length-mm") + 1] for c in calls]
    assert sorted(lengths) == ["50", "60", "70"]             # one call per length (the batch holds all of each)
    assert all(c[-2] == "--length-mm" for c in calls)         # appended after --out-dir DIR
    # on the points track, the same program is given no length
    (tmp_path / "echo" / "calls.txt").unlink()
    run = evaluate(demo, [spec], tmp_path / "points", noise=(0.0,), limit=6, progress=False, examples=0)
    assert np.allclose(load_results(run)[1]["coverage"], 0.01)
    assert not any("--length-mm" in x for x in (tmp_path / "echo" / "calls.txt").read_text().splitlines())


def test_a_program_that_rejects_the_flag_fails_its_inputs_with_its_own_error(demo, tmp_path):
    spec = program(tmp_path / "strict", STRICT, "strict")
    assert (load_results(evaluate(demo, [spec], tmp_path / "points", noise=(0.0,), limit=4, progress=False,
                                  examples=0))[1]["error"] == "").all()    # it runs on the points track
    run = evaluate(demo, [spec], tmp_path / "length", noise=(0.0,), limit=4, progress=False, examples=0,
                   track="length")
    _, rows = load_results(run)
    assert (rows["error"] != "").all() and rows["coverage"].isna().all()
    assert all("exited with status 2" in e for e in rows["error"])
    assert sum("unrecognized arguments: --length-mm" in e for e in rows["error"]) >= 1   # its stderr, quoted
    from colonbench.benchmark.summary import summarize

    s = summarize(rows).iloc[0]
    t = rows["true_coverage"]
    assert s["failed"] == 4 and s["coverage_mae"] == pytest.approx(100 * np.maximum(t, 1 - t).mean())


def test_completion_on_the_length_track_is_the_known_length_estimate(demo, tmp_path):
    from colonbench.completion.method import CompletionMethod
    from colonbench.shards.reader import Shard

    runs = {t: evaluate(demo, ["completion"], tmp_path / t, noise=(0.0,), limit=9, progress=False, examples=0,
                        track=t) for t in tracks.TRACKS}
    a, b = (load_results(runs[t])[1].set_index("sample_id") for t in tracks.TRACKS)
    assert (a["coverage"] - b["coverage"]).abs().max() > 0.01        # at least one segment's estimate moved
    method = CompletionMethod()
    for sid, r in b.iterrows():                                      # each as estimate(points, length_mm=L) gives
        with Shard(demo / r["shard"]) as shard:
            geo = shard.geometry(int(r["index"]))
        assert geo["length_mm"] == r["length_mm"]
        est = method.estimate(noisy(geo["partial_points"], 0.0, 0, r["shard"], r["index"]), length_mm=r["length_mm"])
        assert est.coverage == pytest.approx(r["coverage"], abs=1e-9), sid


def test_export_writes_the_lengths_only_on_the_length_track_and_score_keeps_the_track(demo_data, tmp_path, capsys):
    base = ["--data", str(demo_data), "--quiet"]
    assert main(["export", "demo-v1", "--out", str(tmp_path / "points"), *base]) == 0
    assert main(["export", "demo-v1", "--out", str(tmp_path / "length"), "--track", "length", *base]) == 0
    points, length = (pd.read_csv(tmp_path / t / "index.csv") for t in ("points", "length"))
    assert "length_mm" not in points.columns and list(points.columns) == ["sample_id", "file", "noise_mm", "points"]
    assert list(length.columns) == [*points.columns, "length_mm"] and set(length["length_mm"]) == {50, 60, 70}
    assert json.loads((tmp_path / "length" / "suite.json").read_text())["track"] == "length"
    assert json.loads((tmp_path / "points" / "suite.json").read_text())["track"] == "points"
    assert "--track length" in capsys.readouterr().out
    # a prediction from the exported length; scored as of the length track
    preds = tmp_path / "preds"
    preds.mkdir()
    for _, r in length.iterrows():
        (preds / f"{r['sample_id']}.json").write_text(json.dumps({"coverage": r["length_mm"] / 100}))
    assert main(["score", "demo-v1", str(preds), "--out", str(tmp_path / "run"), "--track", "length", *base]) == 0
    run, rows = load_results(tmp_path / "run")
    assert run["track"] == "length" and np.allclose(rows["coverage"], rows["length_mm"] / 100)
    # the whole-colon suite has no such track
    assert main(["export", "colon-v1", "--out", str(tmp_path / "colon"), "--track", "length", *base]) == 2
    assert "colon-v1 has no known-length track" in capsys.readouterr().err


def test_benchmark_on_the_length_track_cites_it_and_merges_only_its_shipped_results(demo_data, tmp_path, capsys,
                                                                                     monkeypatch):
    suite = suites.get("demo-v1")
    spec = program(tmp_path / "echo", ECHO, "echo")
    out = tmp_path / "bench"
    assert main(["benchmark", "--methods", spec, "--suites", "demo-v1", "--data", str(demo_data), "--out", str(out),
                 "--track", "length", "--quiet", "--no-figures"]) == 0
    _, rows = load_results(out / "runs" / "demo-v1")
    assert len(rows) == 48 and np.allclose(rows["coverage"], rows["length_mm"] / 100)
    summary = pd.read_csv(out / "leaderboard.csv")
    published = shipped.load(suite, track="length")       # none until scripts/reference_results.py makes them
    assert set(summary["method"]) == {"echo"} | (set(published[0]["methods"]) if published else set())
    text = (out / "leaderboard.md").read_text()
    assert text.startswith("# colonbench benchmark, known-length track")
    assert f"- `{suite.citation}, known-length track`" in text
    page = (out / "suites" / "demo-v1" / "leaderboard.md").read_text()
    assert f"cite as `{suite.citation}, known-length track`" in page
    # a rerun of the points track into the same folder is refused; the whole-colon suite has no length track
    assert main(["benchmark", "--methods", spec, "--suites", "demo-v1", "--data", str(demo_data), "--out", str(out),
                 "--quiet", "--no-figures"]) == 2
    assert "a run folder holds one track" in capsys.readouterr().err
    assert main(["benchmark", "--methods", spec, "--suites", "colon-v1", "--out", str(tmp_path / "c"),
                 "--track", "length", "--quiet"]) == 2
    assert "colon-v1 has no known-length track" in capsys.readouterr().err
    # published beside the points track's, merged only into the length track's tables
    monkeypatch.setattr(shipped, "SHIPPED_DIR", tmp_path / "shipped")
    with pytest.raises(InputError, match="not the points-only track"):
        shipped.publish(out / "runs" / "demo-v1", suite, track="points")
    where = shipped.publish(out / "runs" / "demo-v1", suite)
    assert where == tmp_path / "shipped" / "demo-v1@length" and shipped.load(suite) is None
    assert sorted(str(p.relative_to(where)) for p in where.rglob("*") if p.is_file()) == \
        ["results/echo.csv", "results/echo.json", "run.json"]            # the run's working files are not kept
    assert "data_path" not in json.loads((where / "run.json").read_text())
    run, rows, label = shipped.load(suite, track="length")
    assert tracks.of_run(run) == "length" and set(rows["method"]) == {"echo"} and label == "shipped demo-v1@length"
    site = tmp_path / "site"
    assert main(["leaderboard", str(out), "--out", str(site), "--html", "--no-figures"]) == 0
    assert json.loads((site / "site.json").read_text())["pages"] == ["demo-v1/length"]
    assert f"{suite.citation}, known-length track" in (site / "demo-v1" / "length" / "index.html").read_text()
