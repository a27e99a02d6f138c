"""Submitted results: results others add to the repository's ``results/`` registry by pull request.

A submitted result is one method's run on one published segment suite and track, kept as shipped results are
(:func:`colonbench.benchmark.shipped.write_results`)::

    results/<suite id>[@<track>]/<method>/run.json
    results/<suite id>[@<track>]/<method>/results/<method>.csv     one row per segment and noise level
    results/<suite id>[@<track>]/<method>/results/<method>.json    its summary

(``@length`` for the known-length track; the points-only track has no suffix). :func:`check` says whether a run
folder may be submitted (``colonbench results check``), :func:`add` copies a checked one into the registry
(``colonbench results add``), and :func:`leaderboard_items` gives the leaderboards the shipped results and, beside
them, the submitted ones of the same suite and track, each checked again, never another track's; a method of the
user's runs keeps its name and the submitted one of that name is left out, with a note saying so.

The registry lives in the repository, not in the installed package: :func:`registry` finds the one the tables
read (``$COLONBENCH_RESULTS``, else the ``results/`` folder beside the source when colonbench runs from a clone); an
installed colonbench has none, and its tables then hold the shipped results alone. :func:`add` writes where
:func:`target` says: ``--into``, else ``$COLONBENCH_RESULTS``, else the ``results/`` of the colonbench checkout the
current folder is in (:func:`checkout_results`), never that of a checkout colonbench was installed from elsewhere.
"""

from __future__ import annotations

import json
import math
import os
import re
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np
import pandas as pd

from colonbench.benchmark import tracks
from colonbench.benchmark.exchange import sample_id, with_sample_ids
from colonbench.benchmark.runfolder import RUN_FILE, read_rows, read_run
from colonbench.benchmark.summary import failed_every
from colonbench.errors import InputError

#: The repository's registry, where colonbench runs from a clone (a ``results/`` folder with its README.md).
REPOSITORY_RESULTS = Path(__file__).resolve().parents[1] / "results"
#: The environment variable naming another registry folder.
ENV = "COLONBENCH_RESULTS"
#: How a leaderboard labels a submitted result's run (``submitted <suite>[@track]/<method>``).
LABEL = "submitted"
#: A method name that is a folder name on every system.
PLAIN_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._+-]{0,99}$")
#: How far a row's true coverage may be from the published one: a sample decided otherwise at a near-tie
#: (``coverage_tie`` of the signature's tolerances) and float noise.
FLOAT = 1e-6


class NotSubmittable(InputError):
    """A run folder that :func:`check` refuses; the message names every reason."""


def registry(path=None) -> Path | None:
    """The registry folder: ``path`` where given, else ``$COLONBENCH_RESULTS``, else the repository's ``results/``
    (:data:`REPOSITORY_RESULTS`) where colonbench runs from a clone; None for an installed colonbench."""
    if path is not None:
        return Path(path)
    if os.environ.get(ENV):
        return Path(os.environ[ENV]).expanduser()
    return REPOSITORY_RESULTS if (REPOSITORY_RESULTS / "README.md").is_file() else None


def checkout_results(start=None) -> Path | None:
    """The ``results/`` folder of the colonbench checkout that ``start`` (default the current folder) is in: the
    git repository holding it (the nearest folder above with a ``.git``), where its ``pyproject.toml`` names the
    project colonbench and it has ``results/README.md``; None where it is in no such checkout."""
    import tomllib

    here = Path.cwd() if start is None else Path(start)
    here = here.resolve()
    root = next((d for d in (here, *here.parents) if (d / ".git").exists()), None)
    if root is None or not (root / "results" / "README.md").is_file():
        return None
    try:
        project = tomllib.loads((root / "pyproject.toml").read_text()).get("project", {})
    except (OSError, tomllib.TOMLDecodeError, UnicodeDecodeError):
        return None
    return root / "results" if isinstance(project, dict) and project.get("name") == "colonbench" else None


def target(into=None) -> tuple[Path, str]:
    """Where :func:`add` writes, and how that was chosen, in words: ``into`` (``--into``), else
    ``$COLONBENCH_RESULTS``, else the ``results/`` of the colonbench checkout the current folder is in
    (:func:`checkout_results`).

    Raises
    ------
    InputError
        None of them: the current folder is in no colonbench checkout.
    """
    if into is not None:
        return Path(into).expanduser(), "--into"
    if os.environ.get(ENV):
        return Path(os.environ[ENV]).expanduser(), f"${ENV}"
    found = checkout_results()
    if found is None:
        raise InputError(f"the current folder {Path.cwd()} is in no colonbench checkout (a git clone of the "
                         "repository, with results/README.md), whose results/ would take the run: run colonbench "
                         f"results add inside your clone, or give --into DIR (or set ${ENV})")
    return found, f"the results/ of the checkout {found.parent} (the current folder's)"


def folder_name(suite_id: str, track: str = tracks.DEFAULT) -> str:
    """``<suite id>`` on the points-only track, ``<suite id>@<track>`` on another."""
    return suite_id if track == tracks.DEFAULT else f"{suite_id}@{track}"


def is_submitted(record: dict) -> bool:
    """Whether a leaderboard's method record (its ``run`` label) is a submitted result."""
    return str(record.get("run", "")).startswith(LABEL + " ")


# ---------------------------------------------------------------------------------------------------- the check


@dataclass
class Checked:
    """A run folder that may be submitted: its suite, track and, per method, its version and counts.

    Attributes
    ----------
    run_dir : Path
    suite : Suite
    track : str
    check : str
        ``bit-identical`` or ``within tolerance``.
    methods : dict
        ``{name: {"version", "rows", "failed"}}``.
    expected : int
        Rows every method must have: the suite's samples at each of its noise levels.
    """

    run_dir: Path
    suite: object
    track: str
    check: str
    methods: dict
    expected: int

    def lines(self) -> list[str]:
        """One OK line per method, with the counts."""
        s = self.suite
        return [f"OK {self.run_dir}: {name} (version {m['version']}) on {tracks.cite(s, self.track)}, data "
                f"{self.check}: {m['rows']} of {self.expected} segment evaluations ({s.samples} samples x "
                f"{len(s.noise_mm)} noise levels), {m['failed']} failed; versions and environment recorded"
                for name, m in self.methods.items()]


@lru_cache(maxsize=None)
def expected_rows(suite_id: str, signature: str, noise_mm: tuple) -> dict:
    """``{sample_id: true coverage}`` of every segment a run of the suite must have a row of: each sample of its
    published signature at each noise level."""
    from colonbench.benchmark import verification

    published = verification.load(suite_id, signature)
    if published is None:
        raise InputError(f"this colonbench has no published signature of {suite_id}: reinstall it")
    out = {}
    for rec in published["samples"]:
        base = rec["sample"].rsplit("_noise", 1)[0]
        for sigma in noise_mm:
            out[f"{base}_noise{float(sigma):g}"] = float(rec["coverage"])
    return out


def _published_suite(rec: dict, problems: list):
    """The published segment suite a run's suite record names, or None (with the reason in ``problems``)."""
    from colonbench.benchmark import suites
    from colonbench.benchmark.verification import record_problems

    if not rec:
        problems.append("it is not a run of a named suite (run.json has no suite record): make it with colonbench "
                        "benchmark --suites SUITE")
        return None
    found = [s for s in suites.SUITES if s.id == rec.get("id")]
    if rec.get("local") or not found:
        problems.append(f"{rec.get('id')!r} is not a published suite (the suites are "
                        f"{', '.join(s.id for s in suites.SUITES)}; one built on this machine has no published "
                        "signature)")
        return None
    suite = found[0]
    if suite.task == "colon":
        problems.append(f"{suite.id} is a whole-colon suite, whose results cannot be submitted yet (segment suites "
                        "only)")
        return None
    problems.extend(record_problems(rec, suite))
    return suite


def _protocol(run: dict, suite, problems: list) -> None:
    """The run's data and noise protocol are the suite's."""
    data = _dict(run.get("data"))
    try:
        noise = sorted(float(x) for x in run.get("noise_mm") or ())
    except (TypeError, ValueError):
        noise = run.get("noise_mm")
    if (data.get("split"), data.get("samples")) != (suite.split, suite.samples):
        problems.append(f"it evaluated {data.get('samples')} samples of split {data.get('split')!r}, {suite.id} "
                        f"scores {suite.samples} of split {suite.split!r}")
    if noise != sorted(suite.noise_mm) or run.get("noise_seed") != suite.noise_seed:
        problems.append(f"its noise levels {noise} mm (seed {run.get('noise_seed')}) are not {suite.id}'s "
                        f"{list(suite.noise_mm)} mm (seed {suite.noise_seed})")


def _track(run: dict, run_dir: Path, names: list, problems: list) -> str:
    """The run's track, checking that it is known and that its methods' files and records are of it alone."""
    track = tracks.of_run(run)
    if track not in tracks.TRACKS:
        problems.append(f"its track {track!r} is unknown (the tracks are {', '.join(tracks.TRACKS)})")
        return track
    for name in names:
        path = run_dir / "results" / f"{name}.json"
        try:
            summary = json.loads(path.read_text())
        except (OSError, json.JSONDecodeError):
            problems.append(f"results/{name}.json, {name}'s summary, is missing or unreadable")
            continue
        other = tracks.of_run(_dict(summary))
        if other != track:
            problems.append(f"it mixes tracks: results/{name}.json is of the {tracks.label(other)}, run.json of the "
                            f"{tracks.label(track)}; a submitted run holds one track")
        given = "takes_length" in _dict(run["methods"][name])
        if given != (track != tracks.DEFAULT):
            problems.append(f"it mixes tracks: method {name}'s record {'has' if given else 'lacks'} takes_length, "
                            f"which a run of the known-length track records and no other")
    return track


def _records(run: dict, names: list, problems: list) -> None:
    """The run is finished, and each method's name, version, package versions and machine are recorded."""
    from colonbench.benchmark.registry import DEFAULT_METHODS

    if not run.get("complete"):
        problems.append("it is not finished (run.json has no complete: true): run the same command into it again")
    for name in names:
        rec = _dict(run["methods"][name])
        if not PLAIN_NAME.match(name):
            problems.append(f"the method's name {name!r} is not a plain folder name (letters, digits, . _ + -; "
                            "NAME= before the method names its row)")
        if name in DEFAULT_METHODS:
            problems.append(f"{name!r} is a built-in method's name, whose results ship: name your row otherwise "
                            "(NAME= before the method)")
        if str(rec.get("version") or "unversioned").strip() in ("", "unversioned"):
            problems.append(f"method {name} has no version: give it a version attribute (an exec: program's is "
                            "its command line's hash)")
        versions = rec.get("versions") or run.get("versions")
        if not isinstance(versions, dict) or not versions.get("colonbench") or not versions.get("python"):
            problems.append(f"the package versions {name} ran with are not recorded (run.json's versions)")
        environment = rec.get("environment") or run.get("environment")
        if not isinstance(environment, dict) or not environment.get("platform"):
            problems.append(f"the machine {name} ran on is not recorded (run.json's environment)")


def _dict(x) -> dict:
    """``x`` where it is a JSON object, else an empty one (a hand-edited record)."""
    return x if isinstance(x, dict) else {}


def _first(ids) -> str:
    """How many ids, and the first in order."""
    ids = sorted(map(str, ids))
    return f"{len(ids)} (first: {ids[0]})" if ids else "0"


def _rows(run_dir: Path, name: str, expected: dict, tie: float, problems: list) -> dict:
    """Check ``results/<name>.csv`` holds the results columns and one answered or failed row per expected segment,
    with the suite's truth, not all of them failed (:func:`~colonbench.benchmark.summary.failed_every`); its counts
    (``rows`` present of the expected, ``failed``)."""
    from colonbench.benchmark.evaluate import result_columns

    path = run_dir / "results" / f"{name}.csv"
    where = f"results/{name}.csv"
    try:
        head = list(pd.read_csv(path, nrows=0).columns)
    except (OSError, ValueError) as exc:
        problems.append(f"{where} is missing or unreadable ({type(exc).__name__}: {exc})")
        return {}
    want = result_columns()
    if head != want:
        missing, extra = [c for c in want if c not in head], [c for c in head if c not in want]
        problems.append(f"{where}'s columns are not the results columns (docs/formats.md): "
                        + "; ".join(x for x in (f"missing {', '.join(missing)}" if missing else "",
                                                f"extra {', '.join(extra)}" if extra else "",
                                                "in another order" if not missing and not extra else "") if x))
        return {}
    try:
        return _segments(read_rows(path), name, where, expected, tie, problems)
    except (OSError, ValueError, TypeError) as exc:
        problems.append(f"{where} holds a value that is not what its column holds ({type(exc).__name__}: {exc})")
        return {}


def _segments(rows: pd.DataFrame, name: str, where: str, expected: dict, tie: float, problems: list) -> dict:
    """:func:`_rows` of rows with the results columns."""
    if set(rows["method"]) != {name}:
        problems.append(f"{where} holds rows of {', '.join(sorted(map(str, set(rows['method']) - {name})))}")
    ids = [sample_id(s, i, n) for s, i, n in zip(rows["shard"], rows["index"], rows["noise_mm"])]
    rows = rows.assign(sample_id=ids)
    dup = rows["sample_id"].duplicated()
    if dup.any():
        problems.append(f"{where}: {_first(set(rows.loc[dup, 'sample_id']))} segments have more than one row")
    cov = rows["coverage"].to_numpy(float)
    failed = rows["error"].ne("").to_numpy()
    answered = np.isfinite(cov) & ~failed
    blank = ~answered & ~failed
    if blank.any():
        problems.append(f"{where}: {_first(rows.loc[blank, 'sample_id'])} rows have neither a coverage nor an error")
    present = set(rows.loc[~blank, "sample_id"])
    missing = set(expected) - present
    if missing:
        problems.append(f"{where}: {_first(missing)} of the suite's {len(expected)} segments (every sample at every "
                        "noise level) have no row; each needs its estimate, or its failure with the error")
    stray = set(ids) - set(expected)
    if stray:
        problems.append(f"{where}: {_first(stray)} rows are of no segment of the suite")
    outside = (cov[answered] < 0) | (cov[answered] > 1)
    if outside.any():
        problems.append(f"{where}: {int(outside.sum())} coverages outside [0, 1]")
    true = rows["true_coverage"].to_numpy(float)
    published = np.array([expected.get(x, math.nan) for x in ids])
    off = np.isfinite(published) & ~(np.abs(true - published) <= tie + FLOAT)
    if off.any():
        k = int(np.flatnonzero(off)[0])
        problems.append(f"{where}: {int(off.sum())} rows' true_coverage is not the suite's (first: {ids[k]}, "
                        f"{true[k]:.6f}, published {published[k]:.6f})")
    err = rows["coverage_error"].to_numpy(float)
    wrong = answered & ~(np.abs(cov - true - err) <= FLOAT)
    if wrong.any():
        problems.append(f"{where}: {int(wrong.sum())} rows' coverage_error is not coverage - true_coverage (first: "
                        f"{ids[int(np.flatnonzero(wrong)[0])]})")
    if failed_every(len(rows), int(failed.sum())):
        problems.append(f"method {name} failed on every one of its {len(rows)} segment evaluations "
                        f"({int(failed.sum())} failed; first: {rows.loc[failed, 'error'].iloc[0]}): colonbench "
                        "benchmark calls such a method failed and writes no leaderboard of it; fix it and run again")
    return {"rows": int(len(present & set(expected))), "failed": int(failed.sum())}


def check(run_dir, method: str | None = None) -> Checked:
    """Whether a run folder may be submitted: its suite record verified against the published signature (and the
    suite's content hash), every segment of the suite present (answered, or failed with its error), each method's
    version and the run's package versions and machine recorded, one known track, the results columns.

    Parameters
    ----------
    run_dir : path
        A run folder (``colonbench benchmark --out DIR``'s ``DIR/runs/<suite id>``, ``evaluate``, ``score``).
    method : str, optional
        The method to check; default every method of the run.

    Returns
    -------
    Checked

    Raises
    ------
    NotSubmittable
        What is wrong, every reason in one message.
    InputError
        Not a run folder (a benchmark folder: the message names its runs), or no such method in it.
    """
    run_dir = Path(run_dir)
    if not (run_dir / RUN_FILE).is_file() and run_dir.is_dir():
        inner = sorted(str(p.parent) for p in run_dir.glob(f"runs/*/{RUN_FILE}"))
        if inner:
            raise InputError(f"{run_dir} is a colonbench benchmark folder: check one of its runs ({', '.join(inner)})")
    run = read_run(run_dir)
    if not isinstance(run.get("methods"), dict) or not run["methods"]:
        raise NotSubmittable(f"{run_dir} cannot be submitted: its run.json names no methods")
    if run.get("task") == "colon":
        raise NotSubmittable(f"{run_dir} cannot be submitted: it is a whole-colon run, whose results cannot be "
                             "submitted yet (segment suites only)")
    if method is not None and method not in run["methods"]:
        raise InputError(f"{run_dir} holds no method {method!r}; it holds {', '.join(run['methods']) or 'none'}")
    names = [method] if method is not None else list(run["methods"])
    problems: list[str] = []
    suite = _published_suite(_dict(run.get("suite")), problems)
    track = _track(run, run_dir, names, problems)
    _records(run, names, problems)
    counts, expected = {}, {}
    if suite is not None:
        _protocol(run, suite, problems)
        published = expected_rows(suite.id, suite.signature, tuple(suite.noise_mm))
        from colonbench.benchmark.signature import TOLERANCES

        for name in names:
            counts[name] = {"version": _dict(run["methods"][name]).get("version"),
                            **_rows(run_dir, name, published, TOLERANCES.coverage_tie, problems)}
        expected = published
    if problems:
        raise NotSubmittable(f"{run_dir} cannot be submitted: " + "; ".join(problems))
    return Checked(run_dir, suite, track, run["suite"]["check"], counts, len(expected))


# ---------------------------------------------------------------------------------------------------- the registry


def add(run_dir, method: str, root=None) -> Path:
    """Copy a checked run's method into the registry :func:`target` names (``root``, else ``$COLONBENCH_RESULTS``,
    else the current folder's checkout's ``results/``): ``<registry>/<suite id>[@<track>]/<method>/``, replacing
    what that folder held.

    Raises
    ------
    NotSubmittable
        The run does not pass :func:`check`; nothing is written.
    InputError
        No registry: no ``root``, no ``$COLONBENCH_RESULTS``, and the current folder is in no colonbench checkout.
    """
    checked = check(run_dir, method)
    where, _ = target(root)
    run = read_run(run_dir)
    rec = run["methods"][method]
    one = {**run, "methods": {method: {**rec, "versions": rec.get("versions") or run.get("versions"),
                                       "environment": rec.get("environment") or run.get("environment")}}}
    from colonbench.benchmark.shipped import write_results

    out = where / folder_name(checked.suite.id, checked.track) / method
    return write_results(run_dir, one, out)


def load(suite, track: str = tracks.DEFAULT, root=None) -> tuple[list, list[str]]:
    """The submitted results of a suite on a track, each checked again (:func:`check`).

    Returns
    -------
    items : list of (run record, results DataFrame, label)
        As :func:`colonbench.reports.leaderboard.merge_runs` takes them; the label ``submitted <folder>/<method>``.
    notes : list of str
        One per folder left out, with the reason.
    """
    where = registry(root)
    if where is None or getattr(suite, "task", "segments") == "colon":
        return [], []
    base = where / folder_name(suite.id, track)
    items, notes = [], []
    for d in sorted(p for p in base.glob("*") if p.is_dir() and not p.name.startswith(".")):
        name = d.name
        try:
            checked = check(d, name)
        except InputError as exc:
            notes.append(f"submitted {name}: {exc}")
            continue
        if checked.suite.id != suite.id or checked.track != track:
            notes.append(f"submitted {name}: {d} holds a run of {folder_name(checked.suite.id, checked.track)}")
            continue
        run = read_run(d)
        run = {**run, "methods": {name: run["methods"][name]}}
        rows = with_sample_ids(read_rows(d / "results" / f"{name}.csv"))
        items.append((run, rows, f"{LABEL} {base.name}/{name}"))
    return items, notes


def leaderboard_items(suite, track: str = tracks.DEFAULT, mine=(), shipped: bool = True, submitted: bool = True,
                      root=None) -> tuple[list, list[str]]:
    """What a leaderboard of ``suite`` on ``track`` adds to the user's runs: the shipped results less the methods
    in ``mine``, then the submitted ones (:func:`load`) less any whose name is taken, by a method of ``mine`` (the
    user's wins) or a shipped one.

    Returns
    -------
    items : list
        Loaded runs, as :func:`colonbench.reports.leaderboard.merge_runs` takes them.
    notes : list of str
        The submitted results left out and why, for the tables to say.
    """
    from colonbench.benchmark.shipped import shipped_items

    mine = set(mine)
    items = shipped_items(suite, exclude=mine, track=track) if shipped else []
    taken = {m for item in items for m in item[0]["methods"]}
    notes: list[str] = []
    if submitted:
        found, notes = load(suite, track, root)
        for item in found:
            name = next(iter(item[0]["methods"]))
            if name in mine:
                notes.append(f"submitted {name}: a method of the runs given has its name")
            elif name in taken:
                notes.append(f"submitted {name}: a shipped method has its name")
            else:
                items.append(item)
    return items, notes
