"""completion.caltable: the interval calibration's table of estimates, and scripts/calibrate_intervals.py calibrating on
it (decision record 0178)."""

import importlib.util
import json
import shutil
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from colonbench.completion import caltable, intervals
from colonbench.completion.method import steps_version
from colonbench.completion.modelfile import model_path
from colonbench.errors import ColonbenchError, InputError
from colonbench.shards.schema import sha256_file


def script():
    spec = importlib.util.spec_from_file_location(
        "calibrate_intervals", Path(__file__).resolve().parents[1] / "scripts" / "calibrate_intervals.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


#: What a test's table was made of (the JSON file beside it).
MADE_OF = {"model_sha256": "ab" * 32, "steps": "steps=10", "manifests": {"calibration.yaml": "cd" * 32}}


def a_table(n: int = 6) -> pd.DataFrame:
    """``n`` rows of the calibration manifest, the last two of a real training colon; floats whose shortest repr is
    long (0.1 + 0.2, 1/3, an estimate as one was measured)."""
    est = np.array([0.1 + 0.2, 1 / 3, 0.8038993354453191, 2 / 3, 0.5, 0.9][:n])
    return pd.DataFrame({"manifest": "calibration", "shard": [f"validation/colon-{i:05d}-50mm.h5" for i in range(n)],
                         "index": 0, "noise_mm": 0.5, "colon_id": [1] * (n - 2) + [900010] * 2,
                         "hole_model": "camera", "segment_mm": 50.0, "true": est[::-1].copy(), "estimate": est,
                         "rims": 2, "spread": est / 7})


def test_a_table_reads_back_the_floats_it_was_written_with(tmp_path):
    table = a_table()
    caltable.write(table, tmp_path / "t.csv", MADE_OF)
    back = caltable.read(tmp_path / "t.csv", signals=("rims", "spread"))
    assert list(back.columns) == list(table.columns) and back["shard"].tolist() == table["shard"].tolist()
    for column in ("true", "estimate", "spread"):
        assert (back[column].to_numpy() == table[column].to_numpy()).all()      # to the last bit
    assert back.loc[0, "estimate"] == 0.1 + 0.2 != 0.3


@pytest.mark.parametrize("spoil, says", [
    (lambda t: t.drop(columns="estimate"), "lacks the columns estimate"),
    (lambda t: t.drop(columns="spread"), "lacks the columns spread"),                # a signal asked for
    (lambda t: pd.concat([t, t.iloc[[2]]]), "1 rows repeat"),
    (lambda t: t.assign(estimate=t["estimate"].where(t.index != 3, 1.5)), "fraction in \\[0, 1\\]"),
    (lambda t: t.assign(true=t["true"].where(t.index != 1, np.nan)), "fraction in \\[0, 1\\]"),
    (lambda t: t.assign(estimate=t["estimate"].astype(object).where(t.index != 1, "n/a")), "fraction in \\[0, 1\\]"),
    (lambda t: t.iloc[:0], "no rows"),
])
def test_a_spoilt_table_is_refused_saying_what_is_wrong(tmp_path, spoil, says):
    spoil(a_table()).to_csv(tmp_path / "t.csv", index=False)
    with pytest.raises(InputError, match=says):
        caltable.read(tmp_path / "t.csv", signals=("spread",))


@pytest.mark.parametrize("content", [b"", b"\x89PNG\r\n\x1a\n\x00\x00\xff\xfe"])
def test_a_file_that_is_no_table_is_refused(tmp_path, content):
    (tmp_path / "t.csv").write_bytes(content)
    with pytest.raises(InputError, match="t.csv: (not a table of calibration estimates|.*no rows)"):
        caltable.read(tmp_path / "t.csv")


def test_a_table_made_of_other_data_or_of_unknown_data_is_refused(tmp_path):
    caltable.write(a_table(), tmp_path / "t.csv", MADE_OF)
    assert caltable.read(tmp_path / "t.csv", made_of=MADE_OF)["estimate"].size == 6
    other = {**MADE_OF, "manifests": {"calibration.yaml": "ef" * 32}}
    with pytest.raises(InputError, match="made of another manifests than now; make it again .*--remake"):
        caltable.read(tmp_path / "t.csv", made_of=other)
    (tmp_path / "t.json").unlink()
    with pytest.raises(InputError, match="what it was made of is unknown"):
        caltable.read(tmp_path / "t.csv", made_of=MADE_OF)


def test_a_table_made_again_is_compared_row_by_row():
    old = a_table()
    new = old.copy()
    new.loc[1, "estimate"] += 1.4e-8                     # a last-bit move: under 1e-6, not counted
    new.loc[2, "estimate"] += 2e-6                       # over 1e-6, under a point
    new.loc[3, "estimate"] -= 0.2                        # a rim flipped, say: over a point
    new.loc[3, "rims"] = 1
    new.loc[4, "true"] += 1e-15                          # float noise in the truth: the same sample
    new.loc[2, "true"] += 0.03                           # a sample generated otherwise (a near-tie, say)
    new = pd.concat([new.drop(index=5), new.iloc[[0]].assign(shard="validation/colon-00099-50mm.h5")])
    out = caltable.compare(old, new)
    assert out == {"rows": 5, "only_old": 1, "only_new": 1, "truths": 1, "moved": {"1e-06": 2, "0.01": 1},
                   "largest": pytest.approx(0.2), "rims": 1}


def test_each_model_and_steps_have_a_table_of_their_own(tmp_path):
    one, two = tmp_path / "m.safetensors", tmp_path / "n.safetensors"
    one.write_bytes(b"one"), two.write_bytes(b"two")
    assert caltable.path_for(one, "steps=10").name == f"m.calibration-estimates-{sha256_file(one)[:12]}-steps=10.csv"
    sha_in_name = lambda m: caltable.path_for(m, "steps=10").name.split("-")[2]       # noqa: E731
    assert sha_in_name(two) == sha256_file(two)[:12] != sha_in_name(one)
    assert caltable.path_for(one, "steps=20") != caltable.path_for(one, "steps=10")


def test_a_table_of_rows_from_no_calibration_dataset_is_refused():
    with pytest.raises(ColonbenchError, match="must come from"):
        script().with_sets(a_table().assign(manifest="paper"))


@pytest.fixture
def mine(tmp_path, monkeypatch):
    """The script with a model of one's own in ``tmp_path`` and its calibration recorded, not made: (script, model,
    table path, what the script's calibration was given)."""
    module = script()
    model = tmp_path / "mine.safetensors"
    shutil.copy(model_path(None), model)
    seen = {"read": []}
    real_read = module.caltable.read

    def spy_read(*args, **kwargs):
        out = real_read(*args, **kwargs)
        seen["read"].append(out)
        return out

    def calibrate(df, level, source, keep):
        seen.update(df=df, source=source, keep=keep)
        return intervals.Intervals("marginal", level, {"all": {"low": -0.1, "high": 0.1, "n": 6}}, 0.3,
                                   {**source, "id": "marginal-test"})

    monkeypatch.setattr(module.caltable, "read", spy_read)
    monkeypatch.setattr(module, "calibrate", calibrate)
    return module, model, caltable.path_for(model, steps_version()), seen


def full(module) -> pd.DataFrame:
    return a_table().assign(**{s: 0.0 for s in module.SIGNALS if s not in a_table()})


def run(monkeypatch, module, *args):
    monkeypatch.setattr(sys, "argv", ["calibrate_intervals.py", *args])
    module.main()


def test_the_script_calibrates_on_the_models_table_and_touches_no_data(mine, monkeypatch, capsys):
    """With the model's table there, calibrate_intervals.py neither generates nor estimates: it calibrates on the table
    as read back, its rows in their sets, and records the table's name and sha256 in the file's source."""
    module, model, saved, seen = mine
    caltable.write(full(module), saved, module.table_source(model))
    monkeypatch.setattr(module, "calibration_data", lambda *a, **k: pytest.fail("data made though the table is there"))
    run(monkeypatch, module, "--model", str(model))
    assert f"calibrating on {saved}" in capsys.readouterr().out
    assert seen["df"]["estimate"].tolist() == seen["read"][-1]["estimate"].tolist() == a_table()["estimate"].tolist()
    assert seen["df"]["set"].tolist() == ["V_wide"] * 4 + ["train_real"] * 2         # the real training colon's rows
    assert seen["source"]["estimates_table"] == saved.name and seen["keep"] is None    # a model of one's own
    assert seen["source"]["estimates_sha256"] == sha256_file(saved)
    assert (model.parent / "mine.intervals.json").is_file()


def test_a_first_table_is_made_written_and_read_back(mine, monkeypatch, capsys):
    module, model, saved, seen = mine
    monkeypatch.setattr(module, "calibration_data", lambda root, workers: [("calibration", root)])
    monkeypatch.setattr(module, "table", lambda data, method: full(module))
    run(monkeypatch, module, "--model", str(model))
    assert f"wrote {saved}" in capsys.readouterr().out and len(seen["read"]) == 1
    assert seen["df"] is not None and seen["read"][0]["estimate"].tolist() == a_table()["estimate"].tolist()
    assert json.loads(caltable.made_of_path(saved).read_text()) == module.table_source(model)


@pytest.mark.parametrize("old_readable", [True, False])
def test_remake_estimates_again_says_what_moved_and_rewrites_the_table(mine, monkeypatch, capsys, old_readable):
    """--remake makes the table again though one is there, prints how it differs from the old one row by row (or
    that the old one could not be read), and calibrates on the new one as read back."""
    module, model, saved, seen = mine
    old = full(module)
    caltable.write(old, saved, module.table_source(model))
    if not old_readable:
        saved.write_bytes(b"\x00\xff not a table")
    new = old.copy()
    new.loc[2, "estimate"] += 0.05
    monkeypatch.setattr(module, "calibration_data", lambda root, workers: [("calibration", root)])
    monkeypatch.setattr(module, "table", lambda data, method: new)
    run(monkeypatch, module, "--model", str(model), "--remake")
    out = capsys.readouterr().out
    said = "'moved': {'1e-06': 1, '0.01': 1}" if old_readable else "the table before could not be read"
    assert said in out and f"wrote {saved}" in out
    assert seen["read"][-1].loc[2, "estimate"] == new.loc[2, "estimate"] == seen["df"].loc[2, "estimate"]


def test_the_script_says_what_is_wrong_with_a_table_instead_of_a_traceback(tmp_path):
    """Run as a program: a table made of other manifests is refused in one line naming --remake."""
    import subprocess

    model = tmp_path / "mine.safetensors"
    shutil.copy(model_path(None), model)
    saved = caltable.path_for(model, steps_version())
    caltable.write(a_table(), saved, {**MADE_OF})
    done = subprocess.run([sys.executable, str(Path(__file__).resolve().parents[1] / "scripts" /
                                                "calibrate_intervals.py"), "--model", str(model)],
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 1 and "Traceback" not in done.stderr
    assert "calibrate_intervals:" in done.stderr and "--remake" in done.stderr
