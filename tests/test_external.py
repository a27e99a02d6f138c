"""Programs outside colonbench (exec:): failures that count, errors on the right input, retries, their own seconds."""

import json
import re
import shutil
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from colonbench.benchmark import suites
from colonbench.benchmark.evaluate import evaluate, result_columns, select
from colonbench.benchmark.exchange import sample_id
from colonbench.cli import main

#: A program that answers the exact truth from table.json, except where plan.json (beside it, not on its command
#: line: changing it changes no version) says how to fail, or gives its own seconds.
ORACLE = r'''
import json, sys, time
from pathlib import Path
here = Path(__file__).parent
table = json.loads((here / "table.json").read_text())
plan = json.loads((here / "plan.json").read_text()) if (here / "plan.json").is_file() else {}
args = sys.argv[1:]
out = Path(args[args.index("--out-dir") + 1]); out.mkdir(parents=True, exist_ok=True)
print("starting on", sum(a.endswith(".ply") for a in args), "inputs")
for f in (Path(a) for a in args if a.endswith(".ply")):
    sid, how = f.stem, plan.get(f.stem)
    if how == "error-file":
        (out / f"{sid}.error").write_text(f"cannot fit {sid}\n")
    elif how == "error-key":
        (out / f"{sid}.json").write_text(json.dumps({"error": f"no lumen in {sid}"}))
    elif how == "crash":
        print("Traceback (most recent call last):", file=sys.stderr)
        print(f"ValueError: bad cloud in {f}", file=sys.stderr)
        sys.exit(1)
    elif how == "die":
        print("Segmentation fault", file=sys.stderr)
        sys.exit(139)
    elif how == "slow":
        time.sleep(0.8)
        (out / f"{sid}.json").write_text(json.dumps({"coverage": 0.5}))
    else:
        answer = {"coverage": table.get(sid, 0.5)}
        if isinstance(how, dict):
            answer.update(how)
        (out / f"{sid}.json").write_text(json.dumps(answer))
'''


def oracle(folder: Path, table: dict, plan: dict) -> str:
    """Write the program, its truth table and its plan into ``folder``; its exec: spec."""
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "oracle.py").write_text(ORACLE)
    (folder / "table.json").write_text(json.dumps(table))
    (folder / "plan.json").write_text(json.dumps(plan))
    return f"exec:{sys.executable} {folder / 'oracle.py'}"


def truth(data: Path, limit=None, noise=(0.0, 0.5)) -> dict:
    """``{sample id: true coverage}`` of the inputs a run of ``data`` evaluates, in the order it gives them."""
    from colonbench.shards.reader import Shard

    _, picks = select(data, "test", limit)
    table = {}
    for shard_name, indices in picks:
        with Shard(data / shard_name) as shard:
            cov = {i: float(shard.geometry(i)["coverage"]) for i in indices}
        for s in noise:   # a program's inputs come unit by unit: a shard at one noise level
            table.update({sample_id(shard_name, i, s): cov[i] for i in indices})
    return table


@pytest.fixture(scope="module")
def failing_benchmark(demo_data, tmp_path_factory):
    """colonbench benchmark on demo-v1 of the exact truth, failing (its own .error) on every third input."""
    root = tmp_path_factory.mktemp("failing")
    table = truth(suites.data_dir(suites.get("demo-v1"), demo_data))
    failing = sorted(table)[::3]
    spec = oracle(root / "program", table, {sid: "error-file" for sid in failing})
    out = root / "bench"
    assert main(["benchmark", "--methods", spec, "--suites", "demo-v1", "--data", str(demo_data), "--out",
                 str(out), "--quiet", "--no-figures"]) == 0
    return root, spec, out, table, failing


def test_failing_on_a_third_scores_clearly_worse_than_answering_all(failing_benchmark, demo_data, tmp_path):
    _, _, out, table, failing = failing_benchmark
    spec = oracle(tmp_path / "program", table, {})
    assert main(["benchmark", "--methods", spec, "--suites", "demo-v1", "--data", str(demo_data), "--out",
                 str(tmp_path / "all"), "--quiet", "--no-figures"]) == 0
    every = pd.read_csv(tmp_path / "all" / "leaderboard.csv").set_index(["method", "noise_mm"]).loc["oracle"]
    some = pd.read_csv(out / "leaderboard.csv").set_index(["method", "noise_mm"]).loc["oracle"]
    assert (every["mae"] == 0).all() and (every["failed"] == 0).all()
    assert (some["failed"] == 8).all() and some["failed"].sum() == len(failing) == 16
    # each failure scored as the farther of coverage 0 and 1: worse than the constant guess, far behind answering
    rows = pd.read_csv(out / "runs" / "demo-v1" / "results" / "oracle.csv")
    for noise, g in rows.groupby("noise_mm"):
        t = g.loc[g["error"].notna(), "true_coverage"]
        assert some.loc[noise, "mae"] == pytest.approx(100 * np.maximum(t, 1 - t).sum() / len(g))
        assert some.loc[noise, "mae"] > 10
    # the headline table says how many failed, and ranks the method by the score with its failures
    headline = (out / "leaderboard.md").read_text()
    section = headline.split("## Noise sigma = 0 mm")[1].split("##")[0]
    assert re.search(r"\| oracle \| command:\w+ \| [\d.]+ \[[\d.]+, [\d.]+\] \(8 failed\) \|", section)
    assert section.index("| completion ") < section.index("| oracle |")
    page = (out / "suites" / "demo-v1" / "leaderboard.md").read_text()
    (line,) = [x for x in page.split("## Noise sigma = 0.5 mm")[1].splitlines() if x.startswith("| oracle |")][:1]
    cells = [c.strip() for c in line.strip("|").split("|")]
    assert cells[8:10] == ["0", "8"]    # undefined, failed: the failures are their own column
    assert "failed segment" in page and "farther of coverage 0 and 1" in page


def test_the_right_error_lands_on_the_right_input(demo_data, tmp_path, capsys):
    data = suites.data_dir(suites.get("demo-v1"), demo_data)
    table = truth(data, limit=12, noise=(0.0,))
    sids = list(table)
    plan = {sids[1]: "error-file", sids[2]: "error-key", sids[4]: "crash",  # call 1: sids[0:6]
            sids[8]: "die"}                                                  # call 2: sids[6:12], says nothing of it
    spec = oracle(tmp_path / "program", table, plan)
    own = tmp_path / "run" / "predictions" / "oracle" / f"{sids[1]}.error"
    assert main(["evaluate", str(data), "--methods", spec, "--out", str(tmp_path / "run"), "--noise", "0",
                 "--limit", "12", "--batch", "6", "--quiet"]) == 0
    rows = pd.read_csv(tmp_path / "run" / "results" / "oracle.csv").fillna({"error": ""})
    assert list(rows.columns) == result_columns() and list(rows["sample_id"]) == sids
    err = dict(zip(rows["sample_id"], rows["error"]))
    logs = tmp_path / "run" / "logs" / "oracle"
    assert [err[s] for s in (sids[0], sids[3], sids[6], sids[7])] == [""] * 4
    assert err[sids[1]] == f"{sids[1]}.error says: cannot fit {sids[1]}"
    assert own.read_text() == f"cannot fit {sids[1]}\n"               # the program's own file, kept as written
    assert err[sids[2]] == f"{sids[2]}.json says: no lumen in {sids[2]}"
    # the crash is put on the input it was on, its stderr quoted there and nowhere else
    assert "exited with status 1 on this input" in err[sids[4]] and "bad cloud in" in err[sids[4]]
    assert str(logs / "call-0001.stderr.txt") in err[sids[4]]
    assert f"exited with status 1 on {sids[4]}" in err[sids[5]] and "bad cloud" not in err[sids[5]]
    # a crash whose output names no input: said plainly, its stderr's end quoted once
    assert "which input it failed on, its output does not say" in err[sids[8]] and "Segmentation fault" in err[sids[8]]
    for s in sids[9:]:
        assert "exited with status 139" in err[s] and "Segmentation fault" not in err[s]
        assert f"its end is quoted on {sids[8]}" in err[s] and str(logs / "call-0002.stderr.txt") in err[s]
    # every call's standard error and output are kept, with what it was given
    assert "ValueError: bad cloud in" in (logs / "call-0001.stderr.txt").read_text()
    assert (logs / "call-0002.stdout.txt").read_text() == "starting on 6 inputs\n"
    record = json.loads((logs / "call-0002.json").read_text())
    assert record["inputs"] == sids[6:] and record["status"] == 139
    warning = [x for x in capsys.readouterr().err.splitlines() if x.startswith("colonbench: warning: oracle")]
    assert len(warning) == 1 and "failed on 8 segment(s)" in warning[0] and str(logs) in warning[0]


def test_retry_failed_brings_the_score_to_answering_all_and_keeps_the_other_rows(failing_benchmark, demo_data,
                                                                                  tmp_path, capsys):
    root, spec, first, table, failing = failing_benchmark
    out = tmp_path / "bench"
    shutil.copytree(first, out)
    run = out / "runs" / "demo-v1"
    before = pd.read_csv(run / "results" / "oracle.csv")
    args = ["benchmark", "--methods", spec, "--suites", "demo-v1", "--data", str(demo_data), "--out", str(out),
            "--quiet", "--no-figures"]
    assert main(args) == 0          # a rerun without --retry-failed: the failures stick
    assert (pd.read_csv(out / "leaderboard.csv").set_index("method").loc["oracle", "failed"] == 8).all()
    (root / "program" / "plan.json").write_text("{}")   # the program's environment fixed; its version is the same
    capsys.readouterr()
    assert main([*args, "--retry-failed"]) == 0
    assert "warning: oracle" not in capsys.readouterr().err
    summary = pd.read_csv(out / "leaderboard.csv").set_index("method").loc["oracle"]
    assert (summary["mae"] == 0).all() and (summary["failed"] == 0).all()
    after = pd.read_csv(run / "results" / "oracle.csv")
    assert after["error"].isna().all() and (after["coverage_error"] == 0).all()
    kept = ~before["sample_id"].isin(failing)
    # the answered rows, seconds and all, untouched
    pd.testing.assert_frame_equal(after[kept].drop(columns="error"), before[kept].drop(columns="error"))
    assert before.loc[kept, "error"].isna().all() and before.loc[~kept, "error"].notna().all()
    # only the failed inputs ran again, in one call of their own
    calls = sorted((run / "logs" / "oracle").glob("call-*.json"))
    assert len(calls) == 2 and sorted(json.loads(calls[-1].read_text())["inputs"]) == sorted(failing)
    assert not list((run / "predictions" / "oracle").glob("*.error"))
    assert "(8 failed)" not in (out / "leaderboard.md").read_text()


def test_a_programs_own_seconds_are_its_rows_seconds(demo_data, tmp_path):
    data = suites.data_dir(suites.get("demo-v1"), demo_data)
    table = truth(data, limit=5, noise=(0.0,))
    sids = list(table)
    plan = {sids[0]: {"seconds": 7.25}, sids[1]: {"seconds": {"network": 1.0, "rest": 0.5}},
            sids[2]: {"seconds": "fast"}, sids[3]: {"coverage_interval": [0.0, 1.0], "review": ["look again"]}}
    run = evaluate(data, [oracle(tmp_path / "program", table, plan)], tmp_path / "run", noise=[0], limit=5,
                   progress=False)
    rows = pd.read_csv(run / "results" / "oracle.csv").fillna({"error": ""}).set_index("sample_id")
    assert rows.loc[sids[0], "seconds"] == 7.25 and rows.loc[sids[1], "seconds"] == 1.5
    assert "seconds 'fast' is not a number of seconds" in rows.loc[sids[2], "error"]
    share = rows.loc[sids[3:], "seconds"]      # no seconds of its own: the call's wall time over its 5 inputs
    assert share.nunique() == 1 and 0 < share.iloc[0] < 1.5
    record = json.loads((run / "logs" / "oracle" / "call-0001.json").read_text())
    assert share.iloc[0] == pytest.approx(record["seconds"] / 5, abs=1e-3)
    methods = json.loads((run / "run.json").read_text())["methods"]
    assert methods["oracle"]["seconds_from"] == {"program": 2, "call": 3}
    # a program's review reasons are counted as a Python method's are (none said: n/a)
    assert rows.loc[sids[3], "review"] == 1 and rows.loc[sids[3], "interval_high"] == 1.0
    assert rows.loc[sids[4], "review"] != rows.loc[sids[4], "review"]


def test_a_long_call_reports_each_input_as_it_answers_it(tmp_path):
    from colonbench.benchmark.external import ExecMethod

    table = {f"in{k}": 0.5 for k in range(3)}
    method = ExecMethod(oracle(tmp_path / "program", table, {s: "slow" for s in table})[5:],
                        predictions=tmp_path / "run" / "predictions")
    seen = []
    method.run([(s, np.random.default_rng(0).normal(size=(20, 3))) for s in table],
               progress=lambda n: seen.append((time.perf_counter(), n)))
    done = [(t, n) for t, n in seen if n]
    assert sum(n for _, n in done) == 3 and len(done) >= 2     # not all at once at the call's end
    assert done[0][0] < seen[-1][0] - 0.5
    assert (tmp_path / "run" / "logs" / "oracle" / "call-0001.stdout.txt").is_file()


#: A program that goes on past the inputs it cannot do, saying on its standard error which and why, then exits 1;
#: on lost-* it says nothing; on crash-* it says what it read and crashes, naming none of its inputs.
PARTWAY = r'''
import json, sys
from pathlib import Path
args = sys.argv[1:]
out = Path(args[args.index("--out-dir") + 1])
failed = 0
for f in (Path(a) for a in args if a.endswith(".ply")):
    if f.stem.startswith("bad"):
        print(f"reading {f}", file=sys.stderr)
        print(f"error: no lumen found after {len(f.stem)} tries", file=sys.stderr)
        failed += 1
    elif f.stem.startswith("crash"):
        print(f"reading /data/inputs/{'a-rather-long-name-' * 3}.ply", file=sys.stderr)
        print(f"error: no lumen found in /data/inputs/{'a-rather-long-name-' * 3}.ply after trying every seed it "
              "was given, and then both of its fallbacks, the sphere fit and the plain cylinder", file=sys.stderr)
        print("Segmentation fault", file=sys.stderr)
        sys.exit(139)
    elif not f.stem.startswith("lost"):     # lost-*: no answer, and nothing said
        (out / f"{f.stem}.json").write_text(json.dumps({"coverage": 0.5}))
sys.exit(1 if failed else 0)
'''


def test_a_call_that_fails_partway_puts_each_named_input_on_its_own_lines(tmp_path):
    from colonbench.benchmark.external import ExecMethod

    (tmp_path / "partway.py").write_text(PARTWAY)
    long = "a-rather-long-segment-name-as-a-whole-colon-map-cuts-them"
    sids = ["good-1", f"bad-{long}-0001", "good-2", f"bad-{long}-0002", "bad-3", "lost-4"]
    method = ExecMethod(f"{sys.executable} {tmp_path / 'partway.py'}", predictions=tmp_path / "run" / "predictions")
    cloud = np.random.default_rng(0).normal(size=(20, 3))
    method.run([(s, cloud) for s in sids])
    notes = {s: (method.folder / f"{s}.unanswered").read_text().strip() for s in sids[1:] if s.startswith("bad")}
    assert not (method.folder / "good-1.unanswered").exists()
    for sid, note in notes.items():
        assert "its output does not say" not in note, note
        own = note.split("its output names it: ", 1)[1]
        assert own.startswith("reading ") and f"/{sid}.ply error: no lumen found after {len(sid)} tries;" in own
        assert all(other not in own for other in notes if other != sid), note              # no other's lines
    lost = (method.folder / "lost-4.unanswered").read_text()
    assert "its output names 3 other unanswered inputs (each quotes its lines), not this one" in lost
    # a crash naming no input, its last lines longer than the quote: from a line's start or a word's, not mid-name
    method = ExecMethod(f"{sys.executable} {tmp_path / 'partway.py'}", predictions=tmp_path / "run2" / "predictions")
    method.run([("crash-1", cloud), ("good-3", cloud)])
    note = (method.folder / "crash-1.unanswered").read_text().strip()
    tail = note.split("; it ends: ", 1)[1]
    assert tail.startswith("... ") and tail.endswith("the plain cylinder Segmentation fault") and len(tail) <= 200
    assert tail[4:].split()[0] in ("after trying every seed it was given, and then both of its fallbacks, the sphere "
                                   "fit and the plain cylinder").split(), tail                # a whole word
