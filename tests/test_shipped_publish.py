"""Publishing the shipped results (decision record 0327): a method's rows may be made again on data that verify within
tolerance of the published data, each with its own suite record; the whole run only on the published data."""

import json

import pytest

from colonbench.benchmark import shipped, suites
from colonbench.benchmark.runfolder import RUN_FILE, read_run, write_json
from colonbench.cli import main
from colonbench.errors import InputError


def bench(demo_data, out, methods="constant"):
    """A points-track run of demo-v1 on its published data (bit-identical, as the fixture generated it)."""
    assert main(["benchmark", "--methods", methods, "--suites", "demo-v1", "--data", str(demo_data), "--out", str(out),
                 "--quiet", "--no-figures"]) == 0
    return out / "runs" / "demo-v1"


def as_elsewhere(run_dir, ties=2, redrawn=6, **changed):
    """The run's suite record as a machine whose data verified within tolerance writes it (another content hash),
    with ``changed`` keys of it set otherwise."""
    run = read_run(run_dir)
    run["suite"] = {**run["suite"], "check": "within tolerance", "bit_identical": False, "tie_samples": ties,
                    "redrawn_samples": redrawn, "sha256": "cb1-" + "0" * 64, **changed}
    write_json(run_dir / RUN_FILE, run)
    return run_dir


def test_a_method_published_again_from_data_within_tolerance_keeps_its_own_suite_record(demo_data, tmp_path,
                                                                                        monkeypatch):
    suite = suites.get("demo-v1")
    monkeypatch.setattr(shipped, "SHIPPED_DIR", tmp_path / "shipped")
    there = as_elsewhere(bench(demo_data, tmp_path / "there"))
    # nothing shipped yet: rows within tolerance have no published run to join, and a whole run needs the published data
    with pytest.raises(InputError, match="no shipped results made on the published data"):
        shipped.publish(there, suite, methods=["constant"])
    with pytest.raises(InputError, match=r"published data \(bit-identical; its suite"):
        shipped.publish(there, suite)
    here = bench(demo_data, tmp_path / "here")
    where = shipped.publish(here, suite)
    published = read_run(where)["suite"]
    assert published["sha256"] == suite.sha256 and "suite" not in read_run(where)["methods"]["constant"]

    shipped.publish(there, suite, methods=["constant"])
    run = read_run(where)
    assert run["suite"] == published                  # the run's record stays that of the published data
    assert run["methods"]["constant"]["suite"] == {"check": "within tolerance", "bit_identical": False,
                                                   "tie_samples": 2, "redrawn_samples": 6, "diverged_samples": 0,
                                                   "sha256": "cb1-" + "0" * 64}
    assert shipped.own_data(suite, "constant") == run["methods"]["constant"]["suite"]
    loaded, rows, _ = shipped.load(suite)
    assert set(rows["method"]) == {"constant"} and len(rows) == 48
    # a leaderboard that merges them says so below its table
    assert main(["benchmark", "--methods", "unwrap-pca", "--suites", "demo-v1", "--data", str(demo_data), "--out",
                 str(tmp_path / "mine"), "--quiet", "--no-figures"]) == 0
    text = (tmp_path / "mine" / "suites" / "demo-v1" / "leaderboard.md").read_text()
    assert ("The shipped rows of constant were made on data within tolerance of the published data (2 samples "
            "decided otherwise at a near-tie, 6 redrawn on the same surface).") in text
    assert "The shipped rows of unwrap-pca" not in text
    assert main(["leaderboard", str(tmp_path / "mine"), "--out", str(tmp_path / "site"), "--html", "--no-figures"]) == 0
    page = (tmp_path / "site" / "methods" / "constant.html").read_text()
    assert "within tolerance of the published data (2 samples decided otherwise at a near-tie, 6 redrawn" in page
    assert "within tolerance" not in (tmp_path / "site" / "methods" / "unwrap-pca.html").read_text()
    # published again from the published data, the method's own record goes
    shipped.publish(here, suite, methods=["constant"])
    assert "suite" not in read_run(where)["methods"]["constant"] and shipped.own_data(suite, "constant") is None


def test_rows_of_data_that_verified_against_another_signature_are_refused(demo_data, tmp_path, monkeypatch):
    suite = suites.get("demo-v1")
    monkeypatch.setattr(shipped, "SHIPPED_DIR", tmp_path / "shipped")
    shipped.publish(bench(demo_data, tmp_path / "here"), suite)
    before = (shipped.folder(suite) / RUN_FILE).read_text()
    other = bench(demo_data, tmp_path / "other")
    for changed in ({"signature": "cbs1-000000000000"}, {"published_sha256": "cb1-" + "1" * 64},
                    {"bit_identical": True}, {"check": "differs"}):
        with pytest.raises(InputError, match="or within tolerance of its signature"):
            shipped.publish(as_elsewhere(other, **changed), suite, methods=["constant"])
    unverified = bench(demo_data, tmp_path / "unverified")
    run = read_run(unverified)
    write_json(unverified / RUN_FILE, {**run, "suite": {**run["suite"], "verified": False}})
    with pytest.raises(InputError, match="not a run of demo-v1"):
        shipped.publish(unverified, suite, methods=["constant"])
    assert (shipped.folder(suite) / RUN_FILE).read_text() == before and json.loads(before)["suite"]["sha256"] == \
        suite.sha256
    # shipped results that are not of the published data take no rows, not even bit-identical ones
    write_json(shipped.folder(suite) / RUN_FILE, {**json.loads(before), "suite": {**json.loads(before)["suite"],
                                                                                   "sha256": "cb1-" + "2" * 64}})
    with pytest.raises(InputError, match="publish a whole run made on them first"):
        shipped.publish(tmp_path / "here" / "runs" / "demo-v1", suite, methods=["constant"])


def test_a_run_whose_suite_record_counted_fewer_kinds_of_difference_resumes(demo_data, tmp_path, capsys):
    """A run folder of an earlier version (its suite record without ``redrawn_samples``, ``diverged_samples``) takes
    more methods; one whose record differs in what it has is still refused."""
    run_dir = bench(demo_data, tmp_path / "b")
    run = read_run(run_dir)
    old = {k: v for k, v in run["suite"].items() if k not in ("redrawn_samples", "diverged_samples")}
    write_json(run_dir / RUN_FILE, {**run, "suite": old})
    assert bench(demo_data, tmp_path / "b", methods="unwrap-pca") == run_dir
    assert read_run(run_dir)["suite"] == run["suite"] and set(read_run(run_dir)["methods"]) == {"constant",
                                                                                                 "unwrap-pca"}
    write_json(run_dir / RUN_FILE, {**read_run(run_dir), "suite": {**old, "tie_samples": 1}})
    assert main(["benchmark", "--methods", "thresholding", "--suites", "demo-v1", "--data", str(demo_data), "--out",
                 str(tmp_path / "b"), "--quiet", "--no-figures"]) == 2
    assert "is a run with other suite" in capsys.readouterr().err
