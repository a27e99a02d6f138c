"""Results others can add (benchmark 1.1): a run folder checked for submission (colonbench results check), added to
the results/ registry (colonbench results add), and shown on the leaderboards, marked, on its own suite and track."""

import json
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from colonbench.benchmark import submitted, suites
from colonbench.benchmark.evaluate import evaluate, load_results
from colonbench.cli import main

#: The checkout these tests are in.
REPOSITORY = Path(__file__).resolve().parents[1]


class Halfway:
    """Answers 0.6 everywhere but fails on its third segment (a failure is scored, and counts as present)."""

    name, version = "halfway", "1"

    def __init__(self):
        self.calls = 0

    def estimate(self, points):
        self.calls += 1
        if self.calls == 3:
            raise ValueError("the third segment")
        return {"coverage": 0.6}


@pytest.fixture(scope="module")
def run(demo_data, tmp_path_factory):
    """A finished run folder of demo-v1 (every sample at both noise levels) with one failed segment."""
    data = suites.data_dir(suites.get("demo-v1"), demo_data)
    return evaluate(data, [Halfway()], tmp_path_factory.mktemp("results") / "run", noise=(0.0, 0.5), progress=False,
                    examples=0)


def _json(path, change):
    obj = json.loads(path.read_text())
    change(obj)
    path.write_text(json.dumps(obj))


def _rows(path, change):
    rows = pd.read_csv(path, dtype={"error": str})
    change(rows).to_csv(path, index=False)


def _del(d, *keys):
    for k in keys[:-1]:
        d = d[k]
    del d[keys[-1]]


def _set(d, keys, value):
    for k in keys[:-1]:
        d = d[k]
    d[keys[-1]] = value


def _failed_row_blank(rows):
    rows.loc[rows["error"].notna(), "error"] = np.nan
    return rows


def _word(rows):
    rows["coverage"] = rows["coverage"].astype(object)
    rows.loc[4, "coverage"] = "most"
    return rows


def _truth_moved(rows):
    rows.loc[5, "true_coverage"] += 0.1
    return rows


#: Broken copies of the run: (what, how, the reason the check must give).
BROKEN = [
    ("a deleted row", lambda d: _rows(d / "results" / "halfway.csv", lambda r: r.drop(index=7)),
     "1 (first: test_colon-00003-50mm_003_noise0.5) of the suite's 48 segments (every sample at every noise level) "
     "have no row"),
    ("a changed suite sha256", lambda d: _json(d / "run.json", lambda r: _set(r, ("suite", "sha256"), "cb1-0" * 8)),
     "says bit-identical, but its content hash"),
    ("another published hash", lambda d: _json(d / "run.json", lambda r: _set(r, ("suite", "published_sha256"), "x")),
     "names the published content hash 'x'"),
    ("unverified data", lambda d: _json(d / "run.json", lambda r: r["suite"].update(verified=False, check="differs")),
     "its data did not verify against demo-v1's published signature"),
    ("another signature", lambda d: _json(d / "run.json", lambda r: _set(r, ("suite", "signature"), "cbs1-0")),
     "names the signature 'cbs1-0'"),
    ("a missing version", lambda d: _json(d / "run.json", lambda r: _del(r, "methods", "halfway", "version")),
     "method halfway has no version"),
    ("no package versions", lambda d: _json(d / "run.json", lambda r: _del(r, "versions")),
     "the package versions halfway ran with are not recorded"),
    ("no environment", lambda d: _json(d / "run.json", lambda r: _del(r, "environment")),
     "the machine halfway ran on is not recorded"),
    ("a mixed track", lambda d: _json(d / "results" / "halfway.json", lambda r: _set(r, ("track",), "length")),
     "it mixes tracks: results/halfway.json is of the known-length track, run.json of the points-only track"),
    ("an unknown track", lambda d: _json(d / "run.json", lambda r: _set(r, ("track",), "lengths")),
     "its track 'lengths' is unknown"),
    ("other columns", lambda d: _rows(d / "results" / "halfway.csv", lambda r: r.drop(columns=["review"])),
     "columns are not the results columns (docs/formats.md): missing review"),
    ("a failure without its error", lambda d: _rows(d / "results" / "halfway.csv", _failed_row_blank),
     "1 (first: test_colon-00003-50mm_002_noise0) rows have neither a coverage nor an error"),
    ("another truth", lambda d: _rows(d / "results" / "halfway.csv", _truth_moved),
     "1 rows' true_coverage is not the suite's"),
    ("an unfinished run", lambda d: _json(d / "run.json", lambda r: _del(r, "complete")), "it is not finished"),
    ("a word for a coverage", lambda d: _rows(d / "results" / "halfway.csv", _word),
     "results/halfway.csv holds a value that is not what its column holds"),
    ("no methods", lambda d: _json(d / "run.json", lambda r: _set(r, ("methods",), [])), "its run.json names no methods"),
    ("a suite record that is not one", lambda d: _json(d / "run.json", lambda r: _set(r, ("suite",), "demo-v1")),
     "it is not a run of a named suite"),
]


def test_a_finished_run_checks_and_a_failed_segment_counts_as_present(run, capsys):
    _, rows = load_results(run)
    assert len(rows) == 48 and (rows["error"] != "").sum() == 1         # the failure is a row, with its error
    checked = submitted.check(run)
    assert checked.methods == {"halfway": {"version": "1", "rows": 48, "failed": 1}} and checked.expected == 48
    assert main(["results", "check", str(run)]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out == [f"OK {run}: halfway (version 1) on demo-v1 (cbs1-0cd018e664f0), data bit-identical: 48 of 48 "
                   "segment evaluations (24 samples x 2 noise levels), 1 failed; versions and environment recorded"]


def test_a_run_within_tolerance_on_another_machine_checks(run, tmp_path):
    """Data that verified within tolerance (another CPU) has its own content hash: it may be submitted."""
    copy = tmp_path / "copy"
    shutil.copytree(run, copy)
    _json(copy / "run.json", lambda r: r["suite"].update(check="within tolerance", bit_identical=False, tie_samples=1,
                                                         sha256="cb1-" + "0" * 64))
    assert submitted.check(copy).lines()[0].endswith("demo-v1 (cbs1-0cd018e664f0), data within tolerance: 48 of 48 "
                                                     "segment evaluations (24 samples x 2 noise levels), 1 failed; "
                                                     "versions and environment recorded")


@pytest.mark.parametrize("what, breaks, reason", BROKEN, ids=[b[0] for b in BROKEN])
def test_a_broken_copy_is_refused_with_its_reason(run, tmp_path, capsys, what, breaks, reason):
    copy = tmp_path / "copy"
    shutil.copytree(run, copy)
    assert main(["results", "check", str(copy), "--method", "halfway"]) == 0      # the copy itself checks
    capsys.readouterr()
    breaks(copy)
    assert main(["results", "check", str(copy)]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"colonbench: error: {copy} cannot be submitted: ") and "Traceback" not in err
    assert reason in err, err


class Dead:
    """Fails on every segment: a failed method, to colonbench benchmark."""

    name, version = "dead", "1"

    def estimate(self, points):
        raise ValueError("nothing here")


def test_a_run_whose_method_failed_on_every_segment_is_refused_as_benchmark_calls_it_failed(demo_data, tmp_path,
                                                                                             capsys):
    from colonbench.pipeline import RunFailed, run_benchmark

    out = tmp_path / "bench"
    with pytest.raises(RunFailed, match="dead failed on every sample"):
        run_benchmark([Dead()], "demo-v1", out, data=demo_data, figures=False, progress=False)
    run_dir = out / "runs" / "demo-v1"
    assert main(["results", "check", str(run_dir)]) == 2
    err = capsys.readouterr().err
    assert ("method dead failed on every one of its 48 segment evaluations (48 failed; first: ValueError: nothing "
            "here)") in err
    assert "colonbench benchmark calls such a method failed" in err and "Traceback" not in err
    assert main(["results", "add", str(run_dir), "--method", "dead", "--into", str(tmp_path / "results")]) == 2
    assert not (tmp_path / "results").exists()


def test_what_is_not_a_run_of_a_segment_suite_is_named(run, tmp_path, capsys):
    assert main(["results", "check", str(run.parent)]) == 2                        # no run.json
    assert "not a colonbench run" in capsys.readouterr().err
    bench = tmp_path / "bench"
    shutil.copytree(run, bench / "runs" / "demo-v1")
    assert main(["results", "check", str(bench)]) == 2
    assert f"a colonbench benchmark folder: check one of its runs ({bench / 'runs' / 'demo-v1'})" in \
        capsys.readouterr().err
    assert main(["results", "check", str(run), "--method", "mine"]) == 2
    assert "holds no method 'mine'; it holds halfway" in capsys.readouterr().err
    named = tmp_path / "named"
    shutil.copytree(run, named)
    _json(named / "run.json", lambda r: r.update(suite=None))
    assert main(["results", "check", str(named)]) == 2
    assert "not a run of a named suite" in capsys.readouterr().err


def test_add_copies_a_checked_run_into_the_registry_layout(run, tmp_path, monkeypatch, capsys):
    registry = tmp_path / "results"
    monkeypatch.setenv(submitted.ENV, str(registry))
    assert main(["results", "add", str(run), "--method", "halfway"]) == 0
    dest = registry / "demo-v1" / "halfway"
    assert f"to {dest}" in capsys.readouterr().out
    assert sorted(str(p.relative_to(dest)) for p in dest.rglob("*") if p.is_file()) == \
        ["results/halfway.csv", "results/halfway.json", "run.json"]
    record = json.loads((dest / "run.json").read_text())
    assert "data_path" not in record and list(record["methods"]) == ["halfway"]
    assert record["methods"]["halfway"]["versions"]["colonbench"] and record["methods"]["halfway"]["environment"]
    assert submitted.check(dest, "halfway").methods["halfway"]["rows"] == 48      # what was added checks again
    # an unchecked run is refused and nothing is written
    broken = tmp_path / "broken"
    shutil.copytree(run, broken)
    _json(broken / "run.json", lambda r: _del(r, "methods", "halfway", "version"))
    shutil.rmtree(registry)
    assert main(["results", "add", str(broken), "--method", "halfway"]) == 2
    assert "has no version" in capsys.readouterr().err and not registry.exists()


def test_an_installed_colonbench_has_no_registry_and_its_tables_hold_the_shipped_results(run, tmp_path, monkeypatch,
                                                                                         capsys):
    monkeypatch.delenv(submitted.ENV)
    monkeypatch.setattr(submitted, "REPOSITORY_RESULTS", tmp_path / "site-packages" / "results")
    monkeypatch.chdir(tmp_path)                                                   # in no checkout
    assert submitted.registry() is None
    items, notes = submitted.leaderboard_items(suites.get("demo-v1"))
    assert [item[2] for item in items] == ["shipped demo-v1"] and notes == []
    assert main(["results", "add", str(run), "--method", "halfway"]) == 2
    err = capsys.readouterr().err
    assert f"{tmp_path} is in no colonbench checkout" in err and "--into DIR" in err and "Traceback" not in err
    assert main(["results", "check", str(run)]) == 0                              # checking needs none


def _checkout(root):
    """A colonbench checkout as git leaves one: .git, pyproject.toml naming colonbench, results/README.md."""
    (root / ".git").mkdir(parents=True)
    (root / "pyproject.toml").write_text('[project]\nname = "colonbench"\n')
    (root / "results").mkdir()
    (root / "results" / "README.md").write_text("# Submitted results\n")
    return root


def test_add_writes_into_the_checkout_it_runs_in_not_the_one_colonbench_came_from(run, tmp_path, monkeypatch,
                                                                                  capsys):
    """A clone with colonbench installed (editable) from another checkout: add writes into the clone it runs in,
    and says where."""
    monkeypatch.delenv(submitted.ENV)
    installed = _checkout(tmp_path / "installed")
    monkeypatch.setattr(submitted, "REPOSITORY_RESULTS", installed / "results")
    clone = _checkout(tmp_path / "clone")
    (clone / "docs").mkdir()
    monkeypatch.chdir(clone / "docs")                                             # anywhere inside the clone
    assert main(["results", "add", str(run), "--method", "halfway"]) == 0
    out = capsys.readouterr().out
    dest = clone / "results" / "demo-v1" / "halfway"
    assert (dest / "run.json").is_file() and not (installed / "results" / "demo-v1").exists()
    assert f"to {dest}" in out and f"the results/ of the checkout {clone} (the current folder's)" in out
    # --into names another folder, wherever the command runs
    monkeypatch.chdir(tmp_path)
    assert main(["results", "add", str(run), "--method", "halfway", "--into", str(tmp_path / "mine")]) == 0
    out = capsys.readouterr().out
    assert f"to {tmp_path / 'mine' / 'demo-v1' / 'halfway'} (--into)" in out
    # a git repository that is not colonbench's is no checkout of it
    other = tmp_path / "other"
    (other / ".git").mkdir(parents=True)
    (other / "results").mkdir()
    monkeypatch.chdir(other)
    assert main(["results", "add", str(run), "--method", "halfway"]) == 2
    assert f"{other} is in no colonbench checkout" in capsys.readouterr().err
    assert not (other / "results" / "demo-v1").exists()


def test_a_submitted_result_joins_the_leaderboards_marked_and_the_users_method_wins(run, tmp_path, monkeypatch,
                                                                                    capsys):
    monkeypatch.setenv(submitted.ENV, str(tmp_path / "results"))
    submitted.add(run, "halfway")
    out = tmp_path / "bench"           # no methods: the shipped results and the submitted ones, no data made
    assert main(["benchmark", "--suites", "demo-v1", "--out", str(out), "--no-figures", "--quiet"]) == 0
    summary = pd.read_csv(out / "leaderboard.csv")
    mine = summary[summary["method"] == "halfway"]
    assert list(mine["source"]) == ["submitted", "submitted"] and mine["failed"].sum() == 1
    assert set(summary.loc[summary["method"] != "halfway", "source"]) == {"shipped"}
    assert "| halfway ‡ | 1 |" in (out / "leaderboard.md").read_text()
    assert "| halfway ‡ | 1 | 24 |" in (out / "suites" / "demo-v1" / "leaderboard.md").read_text()
    # the same numbers as the run's own table
    own = pd.read_csv(submitted_table(run, tmp_path / "own"))
    assert np.allclose(mine.sort_values("noise_mm")["mae"], own.sort_values("noise_mm")["coverage_mae"])
    assert main(["benchmark", "--suites", "demo-v1", "--out", str(tmp_path / "b2"), "--no-figures", "--quiet",
                 "--no-submitted"]) == 0
    assert "halfway" not in set(pd.read_csv(tmp_path / "b2" / "leaderboard.csv")["method"])
    # a run of the user's with the same name: theirs is in the table, and the table says the submitted one is not
    lb = tmp_path / "lb"
    assert main(["leaderboard", str(run), "--out", str(lb), "--no-figures", "--shipped", "--submitted"]) == 0
    text = (lb / "leaderboard.md").read_text()
    assert "Left out of this table: submitted halfway: a method of the runs given has its name." in text
    assert "| halfway | 1 |" in text and "‡" not in text
    assert json.loads((lb / "leaderboard.json").read_text())["methods"]["halfway"]["run"] == str(run)


def submitted_table(run_dir, out):
    from colonbench.reports.leaderboard import write_leaderboard

    return write_leaderboard([run_dir], out, figures=False)["paths"][1]


def test_submitted_results_are_never_merged_across_tracks(run, tmp_path, monkeypatch):
    monkeypatch.setenv(submitted.ENV, str(tmp_path / "results"))
    length = tmp_path / "length"       # the same rows, as a run of the known-length track
    shutil.copytree(run, length)
    _json(length / "run.json", lambda r: (r.update(track="length"), r["methods"]["halfway"].update(takes_length=False)))
    _json(length / "results" / "halfway.json", lambda r: r.update(track="length"))
    assert submitted.check(length).track == "length"
    assert submitted.add(length, "halfway") == tmp_path / "results" / "demo-v1@length" / "halfway"
    suite = suites.get("demo-v1")
    items, notes = submitted.leaderboard_items(suite, "points", shipped=False)
    assert items == [] and notes == []
    submitted.add(run, "halfway")
    for track, label in (("points", "submitted demo-v1/halfway"), ("length", "submitted demo-v1@length/halfway")):
        items, notes = submitted.leaderboard_items(suite, track, shipped=False)
        assert [item[2] for item in items] == [label] and notes == []
        assert items[0][0]["track"] == track
    # a folder under another track's name, or another method's, is left out, and the tables say why
    wrong = tmp_path / "wrong"
    shutil.copytree(tmp_path / "results" / "demo-v1" / "halfway", wrong / "demo-v1@length" / "halfway")
    shutil.copytree(tmp_path / "results" / "demo-v1" / "halfway", wrong / "demo-v1" / "other")
    for track, note in (("length", "submitted halfway: "), ("points", "submitted other: ")):
        items, notes = submitted.leaderboard_items(suite, track, shipped=False, root=wrong)
        assert items == [] and len(notes) == 1 and notes[0].startswith(note)
    assert notes[0].endswith("holds no method 'other'; it holds halfway")
    assert submitted.leaderboard_items(suite, "length", shipped=False, root=wrong)[1][0].endswith(
        "holds a run of demo-v1")


def test_every_submitted_result_in_the_repository_checks():
    """What a pull request adds to results/ must check, in the folder its suite and track name."""
    root = REPOSITORY / "results"          # this checkout's, not the one colonbench may be installed from
    assert (root / "README.md").is_file()
    for d in sorted(p for p in root.glob("*/*") if p.is_dir()):
        checked = submitted.check(d, d.name)
        assert d.parent.name == submitted.folder_name(checked.suite.id, checked.track), d
        assert sorted(p.name for p in d.rglob("*") if p.is_file()) == sorted(
            ["run.json", f"{d.name}.csv", f"{d.name}.json"]), d


def test_the_results_verb_says_what_it_does(capsys):
    for argv in (["results", "--help"], ["results", "check", "--help"], ["results", "add", "--help"]):
        with pytest.raises(SystemExit):
            main(argv)
        lines = capsys.readouterr().out.splitlines()
        assert lines[0][0].isupper() and lines[0].endswith(".") and lines[2].startswith(f"usage: colonbench "
                                                                                         f"{' '.join(argv[:-1])}")
    assert main(["results"]) == 2
    assert "give an action" in capsys.readouterr().err


def test_a_suites_leaderboard_says_where_each_row_came_from(run, tmp_path, monkeypatch):
    """Its CSV's source column and its markdown's marks, as the page says it: † shipped, ‡ submitted."""
    lb = tmp_path / "lb"
    assert main(["leaderboard", str(run), "--out", str(lb), "--no-figures", "--shipped"]) == 0
    tab = pd.read_csv(lb / "leaderboard.csv")
    source = dict(zip(tab["method"], tab["source"]))
    assert source.pop("halfway") == str(run) and set(source.values()) == {"shipped"} and "completion" in source
    rows = json.loads((lb / "leaderboard.json").read_text())["rows"]
    assert {(r["method"], r["source"]) for r in rows} == set(zip(tab["method"], tab["source"]))
    text = (lb / "leaderboard.md").read_text()
    assert "| completion † |" in text and "| constant * † |" in text and "| halfway |" in text
    assert "Rows marked † are the shipped reference results" in text and "‡" not in text
    # a submitted result beside them, in colonbench benchmark's page of the suite
    monkeypatch.setenv(submitted.ENV, str(tmp_path / "results"))
    submitted.add(run, "halfway")
    assert main(["benchmark", "--suites", "demo-v1", "--out", str(tmp_path / "b"), "--no-figures", "--quiet"]) == 0
    page = tmp_path / "b" / "suites" / "demo-v1"
    tab = pd.read_csv(page / "leaderboard.csv")
    assert set(tab.loc[tab["method"] == "halfway", "source"]) == {"submitted"}
    assert set(tab.loc[tab["method"] != "halfway", "source"]) == {"shipped"}
    text = (page / "leaderboard.md").read_text()
    assert "| halfway ‡ |" in text and "| completion † |" in text and "Rows marked † are the shipped" in text
