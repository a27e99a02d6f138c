"""One call of an ``exec:`` program on a batch of inputs: run with its output kept, followed, and settled per input.

:func:`run_call` starts the program in its own process group with its standard output and error written to
``<logs>/call-<k>.stdout.txt`` and ``.stderr.txt`` (kept, with ``call-<k>.json``: its command, inputs, exit status
and seconds), reports each input it answers while it runs, and stops it at its time limit. :func:`settle` then
says what became of each input of the call (docs/formats.md, "A program as a method"):

* ``<sample_id>.json`` without an ``error`` key: answered (whether the answer is valid is checked when it is
  read);
* ``<sample_id>.error``, or an ``error`` key in its JSON: the program's own failure, in its own words (kept as
  the program wrote it);
* neither: unanswered. colonbench writes ``<sample_id>.unanswered``, saying why in one line: the call exited
  with status 0 without answering it; or it crashed, and then the crash is put on the input it was on when the
  call's output (standard error and output) names exactly one of the unanswered inputs, and otherwise the line
  says that the call crashed before answering it and which input it failed on could not be told; where the
  output names several unanswered inputs (a program that went on past them), each quotes its own lines (from
  one naming it to the next naming another input);
  or it was stopped at its time limit, or could not start. Each names the call's kept standard error.
"""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import time
from dataclasses import dataclass, field
from pathlib import Path

from colonbench.benchmark.exchange import one_line, program_seconds

#: Seconds between two looks at what a running call has answered.
POLL_S = 0.5
#: Endings of the files a program answers an input with.
ANSWERS = (".json", ".error")
#: colonbench's own note on an input its call left without an answer.
UNANSWERED = ".unanswered"
#: The most characters of a call's output a note quotes.
QUOTE = 200


@dataclass
class Call:
    """What one program call did.

    Attributes
    ----------
    name : str
        ``call-<k>``, the stem of its log files.
    sids : list of str
        Its inputs' sample ids, in the order given.
    folder, logs : Path
        Where it answers, where its output is kept.
    status : int or None
        Its exit status; None when it was stopped or could not start (``why`` says which).
    seconds : float
        Wall time from its start to its end.
    why : str
        "" when it ran to its end, else why not.
    started : bool
        Whether the program started at all.
    answered : set of str
        The inputs it had answered when last looked at.
    """

    name: str
    sids: list
    folder: Path
    logs: Path
    status: int | None = None
    seconds: float = 0.0
    why: str = ""
    started: bool = True
    answered: set = field(default_factory=set)

    @property
    def stderr(self) -> Path:
        """The kept standard error of the call."""
        return self.logs / f"{self.name}.stderr.txt"

    @property
    def stdout(self) -> Path:
        """The kept standard output of the call."""
        return self.logs / f"{self.name}.stdout.txt"


def _new_call(logs: Path) -> str:
    """The next free ``call-<k>`` of a logs folder, claimed by creating its record (safe across processes)."""
    logs.mkdir(parents=True, exist_ok=True)
    taken = [int(m.group(1)) for p in logs.glob("call-*.json") if (m := re.fullmatch(r"call-(\d+)\.json", p.name))]
    k = max(taken, default=0) + 1
    while True:
        try:
            os.close(os.open(logs / f"call-{k:04d}.json", os.O_CREAT | os.O_EXCL | os.O_WRONLY))
            return f"call-{k:04d}"
        except FileExistsError:
            k += 1


def done(folder: Path, sid: str) -> bool:
    """Whether the program has answered input ``sid`` in ``folder`` (a JSON or an ``.error``)."""
    return any((folder / f"{sid}{end}").is_file() for end in ANSWERS)


def run_call(argv: list[str], sids: list[str], folder: Path, logs: Path, limit: float, progress=None) -> Call:
    """Run one call of a program, its output kept in ``logs``, reporting each input it answers as it goes.

    Parameters
    ----------
    argv : list of str
        The whole command line (inputs and ``--out-dir`` included).
    sids : list of str
        The sample ids of its inputs.
    folder : Path
        Where it writes its answers.
    logs : Path
        Where its standard output and error and its record are kept.
    limit : float
        Seconds it may run; then its process group is killed.
    progress : callable, optional
        Called with the number of inputs newly answered, while it runs and once at its end (the rest, so that
        the calls add up to ``len(sids)``).

    Returns
    -------
    Call
    """
    call = Call(_new_call(logs), list(sids), Path(folder), Path(logs))
    t = time.perf_counter()
    report = progress or (lambda n: None)
    with open(call.stdout, "wb") as out, open(call.stderr, "wb") as err:
        try:
            proc = subprocess.Popen(argv, stdout=out, stderr=err, start_new_session=True)
        except OSError as exc:
            call.why, call.started = f"the program could not start: {exc.strerror or exc}: {argv[0]}", False
            err.write(call.why.encode() + b"\n")
        else:
            while True:
                try:
                    call.status = proc.wait(timeout=POLL_S)
                    break
                except subprocess.TimeoutExpired:
                    if time.perf_counter() - t > limit:
                        os.killpg(proc.pid, signal.SIGKILL)
                        proc.wait()
                        call.why = (f"the program was stopped after {limit:.0f} s, the time allowed for its "
                                    f"{len(sids)} input(s)")
                        break
                new = {s for s in sids if s not in call.answered and done(call.folder, s)}
                call.answered |= new
                report(len(new))   # 0 too: a progress bar shows the time going by
    call.seconds = time.perf_counter() - t
    report(len(sids) - len(call.answered))
    record = {"command": argv, "inputs": call.sids, "status": call.status, "seconds": round(call.seconds, 3),
              "stopped": call.why}
    (logs / f"{call.name}.json").write_text(json.dumps(record, indent=1))
    return call


def _answer(folder: Path, sid: str) -> tuple[str, float | None]:
    """``("answered" | "own" | "none", the program's own seconds or None)`` of one input after its call."""
    if (folder / f"{sid}.error").is_file():
        return "own", None
    path = folder / f"{sid}.json"
    if not path.is_file():
        return "none", None
    try:
        obj = json.loads(path.read_text())
        seconds = program_seconds(obj.get("seconds"), path.name) if isinstance(obj, dict) else {}
    except Exception:  # noqa: BLE001 - a malformed answer is an answer; reading it says what is wrong
        return "answered", None
    if isinstance(obj, dict) and obj.get("error") not in (None, "", False):
        return "own", None
    return "answered", (sum(seconds.values()) if seconds else None)


def _owned(call: Call) -> dict[str, list[str]]:
    """Each input's lines of the call's standard error and output (each stream on its own): from a line that names
    it (:func:`_names`) to the next that names another of the call's inputs; only inputs named have an entry."""
    owned: dict[str, list[str]] = {}
    for path in (call.stderr, call.stdout):
        try:
            lines = [x for x in path.read_text(errors="replace").splitlines() if x.strip()]
        except OSError:
            continue
        owners: list[str] = []
        for line in lines:
            owners = [s for s in call.sids if _names(s, line)] or owners
            for sid in owners:
                owned.setdefault(sid, []).append(line)
    return owned


def _names(sid: str, line: str) -> bool:
    """Whether a line names input ``sid``: its id, or its file's name, and not a longer id (``..._noise0`` is not
    ``..._noise0.5``)."""
    return re.search(rf"(?<![\w-]){re.escape(sid)}(?!\.?\d)", line) is not None


def _quote(lines: list[str], limit: int = QUOTE) -> str:
    """The end of ``lines`` as one line of at most ``limit`` characters, each line's spaces collapsed: whole lines,
    from the last back; where the one before does not fit whole, its end from a word's start after ``...``, never
    from inside a word (a file's name)."""
    out: list[str] = []
    for line in reversed([" ".join(x.split()) for x in lines]):
        room = limit - len(" ".join(out)) - (1 if out else 0)
        if len(line) <= room:
            out.insert(0, line)
            continue
        words: list[str] = []
        for word in reversed(line.split(" ")):
            if len(" ".join(["...", word, *words])) > room:
                break
            words.insert(0, word)
        if words:
            out.insert(0, " ".join(["...", *words]))
        break
    return " ".join(out)


def _tail(call: Call) -> str:
    """The last two non-empty lines of the call's standard error, as one line (:func:`_quote`)."""
    try:
        lines = [x for x in call.stderr.read_text(errors="replace").splitlines() if x.strip()]
    except OSError:
        return ""
    return _quote(lines[-2:])


def unanswered_message(call: Call, sid: str, answered: int, named: dict, first: str) -> str:
    """Why input ``sid`` of ``call`` has no answer, in one line naming the call's kept standard error.

    The end of the call's standard error is quoted once: on the input the call crashed on, or, where its output
    does not tell which, on the first unanswered input (``first``); the others name that input. Where its output
    names several of the unanswered inputs (a program that went on past them), each of them quotes the end of its
    own lines instead (:func:`_owned`), and the others say that it names them not.

    Parameters
    ----------
    call : Call
    sid : str
    answered : int
        How many of the call's inputs it answered (its own failures included).
    named : dict
        The unanswered inputs its output names, each with its lines (:func:`_owned`).
    first : str
        The first unanswered input of the call.
    """
    where = f"its standard error: {call.stderr}"
    tail = _tail(call)
    ends = f"; it ends: {tail}" if tail else ""
    what = f"the program's {call.name} ({len(call.sids)} inputs, {answered} answered)"
    if not call.started:
        return call.why
    if call.why:
        return f"{call.why} ({call.name}, {answered} answered) before it answered {sid}; {where}"
    if call.status == 0:
        return f"{what} exited with status 0 without writing {sid}.json or {sid}.error; {where}"
    if list(named) == [sid]:
        return (f"{what} exited with status {call.status} on this input (the only unanswered input its output "
                f"names) before answering it; {where}{ends}")
    if len(named) == 1:
        return (f"{what} exited with status {call.status} on {next(iter(named))} (the only unanswered input its "
                f"output names) before it answered this one; {where}")
    if sid in named:
        own = _quote(named[sid])
        return (f"{what} exited with status {call.status} before answering this input, one of {len(named)} "
                f"unanswered inputs its output names; its output names it: {own}; {where}")
    if named:
        return (f"{what} exited with status {call.status} after {call.seconds:.1f} s before answering this input; "
                f"its output names {len(named)} other unanswered inputs (each quotes its lines), not this one; "
                f"{where}")
    quoted = ends if sid == first else f" (its end is quoted on {first})"
    return (f"{what} exited with status {call.status} after {call.seconds:.1f} s before answering this input; "
            f"which input it failed on, its output does not say; {where}{quoted}")


def settle(call: Call) -> dict[str, tuple[float, str]]:
    """What became of each input of a finished call: an ``.unanswered`` note written for each input the program
    left without an answer (never over one of its own), and each input's seconds.

    Returns
    -------
    dict
        ``{sample id: (seconds, source)}``: the program's own ``seconds`` of that input where its JSON gives one
        (source ``"program"``), else the call's wall time over its inputs (``"call"``).
    """
    answers = {s: _answer(call.folder, s) for s in call.sids}
    missing = [s for s, (kind, _) in answers.items() if kind == "none"]
    owned = _owned(call) if missing and call.status not in (0, None) else {}
    named = {s: owned[s] for s in missing if s in owned}
    for sid in missing:
        note = unanswered_message(call, sid, len(call.sids) - len(missing), named, missing[0])
        (call.folder / f"{sid}{UNANSWERED}").write_text(one_line(note, 1000) + "\n")
    share = call.seconds / max(1, len(call.sids))
    return {s: (own, "program") if own is not None else (share, "call") for s, (_, own) in answers.items()}
