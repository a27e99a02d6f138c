"""Methods outside colonbench's environment: a folder of predictions, or any program run on input files.

``predictions:DIR`` (:class:`PredictionMethod`) reads ``DIR/<sample_id>.json``
for each evaluated cloud (``colonbench export`` writes the inputs,
``colonbench score`` scores such a folder). ``exec:PROGRAM ARGS``
(:class:`ExecMethod`) runs the program exactly as ``colonbench estimate`` is
called, ``PROGRAM ARGS FILE... --out-dir DIR``, on batches of input PLYs named
by sample id (on the known-length track with ``--length-mm L`` appended, one
length per call), and then reads its predictions the same way. A missing or
malformed prediction, the program's own failure (``<sample_id>.error`` or an
``error`` key), a crash or a timeout is that segment's failure in the results
(its message says which, :mod:`colonbench.benchmark.calls`), never the run's.
Each call's standard output and error are kept in ``<run>/logs/<method>/``.

Both are matched to the clouds they answer by sample id; in a whole-colon map,
where the benchmark cuts the segments itself, a segment's cloud is matched by
its content (:func:`content_key`) to the id it was written under.
"""

from __future__ import annotations

import hashlib
import shlex
import shutil
import tempfile
import threading
from pathlib import Path

import numpy as np

from colonbench.benchmark import calls
from colonbench.benchmark.exchange import one_line, read_prediction, write_input
from colonbench.errors import InputError

#: Inputs per program call by default, and seconds allowed per input.
BATCH = 64
TIMEOUT_S = 300.0
#: Each input's seconds, one ``sample_id,seconds,source`` line per input and call, in its predictions folder:
#: source ``program`` (its JSON's own ``seconds``) or ``call`` (the call's wall time over its inputs).
SECONDS_NAME = "seconds.csv"
#: Interpreters whose next argument names the method (``exec:python my_method.py`` is ``my_method``).
INTERPRETERS = {"python", "python3", "bash", "sh", "Rscript", "julia", "node", "conda", "uv", "pixi", "env",
                "matlab", "octave"}
#: Endings of a script's name: a word of an ``exec:`` command line that ends so names a file, which must be there.
SCRIPT_SUFFIXES = {".py", ".R", ".r", ".jl", ".js", ".mjs", ".cjs", ".ts", ".sh", ".bash", ".m", ".pl", ".rb",
                   ".lua"}


def content_key(points) -> str:
    """A key of a cloud's exact values (the same array gives the same key)."""
    return hashlib.sha1(np.ascontiguousarray(points, dtype=np.float64).tobytes()).hexdigest()


class PredictionMethod:
    """Predictions read from a folder of ``<sample_id>.json`` files (docs/formats.md).

    Parameters
    ----------
    folder : path
    name : str
    version : str, optional
        Default: a sha256 of the folder's prediction files (``files:<12 hex>``), so that another set of
        predictions is another version.
    """

    #: The benchmark gives this method its sample ids (:meth:`predicted`) instead of clouds.
    by_sample = True
    #: It returns no completed mesh: in a whole-colon map it is given each segment's own points.
    completes_surface = False

    def __init__(self, folder, name: str = "predictions", version: str | None = None):
        self.folder = Path(folder)
        self.name = name
        self.version = version if version is not None else f"files:{_folder_digest(self.folder)}"
        self.lookup: dict[str, str] = {}
        self._timing: dict[str, float] = {}

    def predicted(self, sid: str):
        """The checked estimate of sample ``sid`` (:func:`colonbench.benchmark.exchange.read_prediction`), with
        its seconds: the prediction's own ``seconds``, else its call's wall time over its inputs where a call
        timed it (``seconds["program"]``).

        Raises
        ------
        InputError
            Why there is none: the program's own failure (``<sid>.error``, or an ``error`` key in its JSON), why
            its call left it unanswered (``<sid>.unanswered``), or what is wrong with its file.
        """
        failure = self.folder / f"{sid}.error"
        if failure.is_file():
            raise InputError(f"{failure.name} says: {one_line(failure.read_text(errors='replace'))}")
        note = self.folder / f"{sid}{calls.UNANSWERED}"
        if note.is_file() and not (self.folder / f"{sid}.json").is_file():
            raise InputError(note.read_text(errors="replace").strip())
        est = read_prediction(self.folder / f"{sid}.json", self.name)
        seconds = self._seconds(sid)
        if not est.seconds and seconds is not None:
            est.seconds = {"program": seconds}
        return est

    def timing(self) -> dict[str, tuple[float, str]]:
        """``{sample id: (seconds, source)}`` of :data:`SECONDS_NAME`, the latest line of each input (lines
        without a source are the call's)."""
        path = self.folder / SECONDS_NAME
        if not path.is_file():
            return {}
        out = {}
        for line in path.read_text().splitlines():
            sid, _, rest = line.partition(",")
            value, _, source = rest.partition(",")
            try:
                out[sid] = (float(value), source.strip() or "call")
            except ValueError:
                continue
        return out

    def _seconds(self, sid: str) -> float | None:
        """The seconds of ``sid`` its call recorded, read again when the file has grown (a later call)."""
        path = self.folder / SECONDS_NAME
        size = path.stat().st_size if path.is_file() else 0
        if size != getattr(self, "_timing_size", 0):
            self._timing, self._timing_size = {k: v for k, (v, _) in self.timing().items()}, size
        return self._timing.get(sid)

    def estimate(self, points):
        """The prediction of a cloud the benchmark wrote under a sample id (:attr:`lookup`)."""
        sid = self.lookup.get(content_key(points))
        if sid is None:
            raise InputError(f"method {self.name!r} answers by sample id; this cloud is not one of the inputs it "
                             "was given (run it with colonbench benchmark, evaluate or score)")
        return self.predicted(sid)


class ExecMethod(PredictionMethod):
    """Any program that takes input files and writes ``<out-dir>/<name>.json`` as ``colonbench estimate`` does.

    Parameters
    ----------
    command : str
        ``PROGRAM ARGS``, split as a shell would (no shell runs it).
    predictions : path
        Folder its outputs go to (``<run>/predictions``); this method's own subfolder is made in it.
    name : str, optional
        Default: the program's file stem (after an interpreter such as ``python``).

    Its version is a hash of the command line and of the files it names (:func:`command_version`): editing the
    script makes another version, which a run folder refuses to mix with the old one. Changes it cannot see
    (a package the script imports) need a new run folder.
    timeout : float
        Seconds allowed per input file; a call gets that times its number of files.
    batch : int
        Input files per call.
    """

    def __init__(self, command: str, predictions=None, name: str | None = None, timeout: float = TIMEOUT_S,
                 batch: int = BATCH):
        self.argv = check_command(command)
        if timeout <= 0 or batch < 1:
            raise InputError(f"exec: timeout must be positive and batch at least 1, got {timeout} and {batch}")
        self.command, self.timeout, self.batch = command, float(timeout), int(batch)
        self._lock = threading.Lock()
        name = name or default_name(self.argv)
        root = Path(predictions) if predictions is not None else Path(tempfile.mkdtemp(prefix="colonbench-exec-"))
        super().__init__(root / name, name, command_version(self.argv))
        #: Each call's standard output and error and its record (:mod:`colonbench.benchmark.calls`).
        self.logs = (root.parent if predictions is not None else root) / "logs" / name

    def missing(self, sids) -> list[str]:
        """The ids among ``sids`` with neither an answer (a prediction, the program's ``.error``) nor a note of
        why its call left it unanswered."""
        return [s for s in sids if not calls.done(self.folder, s)
                and not (self.folder / f"{s}{calls.UNANSWERED}").is_file()]

    def forget(self, sids) -> None:
        """Remove what the program answered for ``sids`` and the notes on them, so that they run again."""
        for sid in sids:
            for end in (*calls.ANSWERS, calls.UNANSWERED):
                (self.folder / f"{sid}{end}").unlink(missing_ok=True)

    def run(self, items, workers: int = 1, progress=None) -> None:
        """Run the program on ``items`` (``(sample id, points)`` pairs) that have no answer yet, in batches.

        Parameters
        ----------
        items : iterable of (str, (n, 3) float) or (str, (n, 3) float, float or None)
            Inputs, each with the segment's length in mm where it is given (the known-length track): the inputs
            of one length are called together, with ``--length-mm L`` appended to the command line.
        workers : int
            Calls at the same time.
        progress : callable, optional
            Called with the number of inputs answered, as the calls answer them (and 0 now and then while they
            run).
        """
        from concurrent.futures import ThreadPoolExecutor

        by_length: dict = {}
        for s, p, *length in items:
            if self.missing([s]):
                by_length.setdefault(length[0] if length else None, []).append((s, p))
        if not by_length:
            return
        self.folder.mkdir(parents=True, exist_ok=True)
        batches = [(todo[k:k + self.batch], length) for length, todo in by_length.items()
                   for k in range(0, len(todo), self.batch)]

        def report(n: int) -> None:
            if progress is not None:
                with self._lock:
                    progress(n)

        with ThreadPoolExecutor(max(1, workers)) as pool:
            list(pool.map(lambda b: self._call(*b, report), batches))

    def _call(self, batch, length, report) -> None:
        sids = [sid for sid, _ in batch]
        known = [] if length is None else ["--length-mm", f"{float(length):.10g}"]
        with tempfile.TemporaryDirectory(prefix="colonbench-inputs-") as tmp:
            files = [str(write_input(Path(tmp) / f"{sid}.ply", pts)) for sid, pts in batch]
            call = calls.run_call(self.argv + files + ["--out-dir", str(self.folder)] + known, sids, self.folder,
                                  self.logs, self.timeout * len(files), report)
        seconds = calls.settle(call)
        with self._lock, open(self.folder / SECONDS_NAME, "a") as fh:
            fh.writelines(f"{sid},{s:.4f},{source}\n" for sid, (s, source) in seconds.items())

    def seconds_from(self, sids) -> dict[str, int]:
        """How many of ``sids`` have the program's own seconds (``program``) and how many the call's wall time
        over its inputs (``call``), by :data:`SECONDS_NAME`."""
        timing = self.timing()
        sources = [timing[s][1] for s in sids if s in timing]
        return {"program": sources.count("program"), "call": sources.count("call")}


def check_command(command: str) -> list[str]:
    """The words of an ``exec:`` command line, checked before anything runs: its program is an executable file
    or on ``PATH``, and every word that names a script (ends in one of :data:`SCRIPT_SUFFIXES`, not an option)
    is a file that is there (relative to the current folder, where the program runs).

    Raises
    ------
    InputError
        The line cannot be split, is empty, or names a program or a script that is not there.
    """
    try:
        argv = shlex.split(command)
    except ValueError as exc:
        raise InputError(f"exec:{command}: cannot split the command line ({exc})") from None
    if not argv:
        raise InputError("exec: needs a program, e.g. exec:python my_method.py")
    if shutil.which(argv[0]) is None:
        raise InputError(f"exec:{command}: no program {argv[0]!r} here (not an executable file, not on PATH)")
    for word in argv[1:]:
        path = Path(word)
        if not word.startswith("-") and path.suffix in SCRIPT_SUFFIXES and not path.is_file():
            where = "" if path.is_absolute() else f" (relative to {Path.cwd()}, where the program runs)"
            raise InputError(f"exec:{command}: no such file {word!r}{where}; nothing was run")
    return argv


def command_version(argv: list[str]) -> str:
    """``command:<12 hex>``: a sha256 of the command line and of the contents of the files it names (a script, a
    model), so that an edited script is another version (a run refuses to mix two)."""
    h = hashlib.sha256(shlex.join(argv).encode())
    for word in argv[1:]:
        path = Path(word)
        if path.is_file():
            h.update(hashlib.sha256(path.read_bytes()).digest())
    return "command:" + h.hexdigest()[:12]


def default_name(argv: list[str]) -> str:
    """A method name from a command line: the program's stem, or the script's after an interpreter."""
    words = [w for w in argv if not w.startswith("-")]
    first = Path(words[0]).name if words else "exec"
    if first in INTERPRETERS and len(words) > 1:
        first = words[1]
    return Path(first).stem or "exec"


def _folder_digest(folder: Path) -> str:
    h = hashlib.sha256()
    if folder.is_dir():
        for p in sorted(folder.glob("*.json")):
            h.update(p.name.encode())
            h.update(hashlib.sha256(p.read_bytes()).digest())
    return h.hexdigest()[:12]
