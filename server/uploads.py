"""An uploaded predictions archive checked before anything of it is stored.

The archive is a zip of ``<sample_id>.json`` files, the ``colonbench score`` contract (docs/formats.md): one per
evaluated cloud of the suite, each the JSON of ``colonbench estimate`` (or ``{"error": ...}``, the method's word
that it failed on that input, scored as a failure). It is refused, with every problem found named (up to
:data:`MAX_PROBLEMS`), when:

* it is larger than ``max_bytes`` (the app stops reading there) or not a zip;
* it holds more than ``max_files`` entries (checked on the central directory, before any entry is read);
* an entry's path is absolute, has a drive or backslash, or a ``..`` part (nothing may land outside it);
* an entry is a symbolic link or another special file (the zip's external attributes), or encrypted;
* an entry is over ``max_member_bytes`` unpacked, the whole over ``max_unpacked``, or an entry or the whole
  unpacks to more than ``max_ratio`` times its packed size (a zip bomb); sizes are checked as read, not trusted
  from the headers;
* a file is not ``<sample_id>.json`` of a sample of the suite, two entries name one sample, or a sample has no
  prediction;
* a file is not UTF-8 JSON or not the contract (:func:`colonbench.benchmark.exchange.read_prediction`'s checks).

What is kept of an accepted archive is :func:`canonical_zip` of its checked files (sorted, one folder level
removed), so what the worker scores is exactly what was checked.
"""

from __future__ import annotations

import hashlib
import io
import json
import stat
import tempfile
import zipfile
from dataclasses import dataclass
from pathlib import Path, PurePosixPath

MAX_PROBLEMS = 20


@dataclass(frozen=True)
class Limits:
    """The caps an upload is checked against."""

    max_bytes: int = 64 * 2 ** 20
    max_files: int = 5000
    max_member_bytes: int = 32 * 2 ** 20
    max_unpacked: int = 512 * 2 ** 20
    max_ratio: float = 100.0
    #: Entries and archives smaller than this unpacked are not held to ``max_ratio`` (a tiny file packs well).
    ratio_floor: int = 2 ** 20


class UploadError(Exception):
    """An upload refused: the HTTP status, a short code, a message and every problem found.

    Attributes
    ----------
    status : int
    code : str
    problems : list of str
    """

    def __init__(self, status: int, code: str, message: str, problems=()):
        super().__init__(message)
        self.status, self.code, self.message, self.problems = status, code, message, list(problems)[:MAX_PROBLEMS]

    def body(self) -> dict:
        """The JSON body of the refusal."""
        return {"error": self.code, "message": self.message, "problems": self.problems}


def _bad_path(name: str) -> str | None:
    if name.startswith(("/", "\\")) or "\\" in name or (len(name) > 1 and name[1] == ":"):
        return f"{name!r}: an absolute path or one with a drive or backslash"
    if ".." in PurePosixPath(name).parts:
        return f"{name!r}: a path outside the archive ('..')"
    if "\x00" in name:
        return f"{name!r}: a NUL in its name"
    return None


def _kind(info: zipfile.ZipInfo) -> str | None:
    kind = stat.S_IFMT(info.external_attr >> 16)     # the Unix file type, where the zip records one
    if kind == stat.S_IFLNK:
        return "a symbolic link"
    if kind and kind not in (stat.S_IFREG, stat.S_IFDIR):
        return "a special file (not a regular file)"
    if info.flag_bits & 0x1:
        return "encrypted"
    return None


def _entries(data: bytes, limits: Limits) -> list[zipfile.ZipInfo]:
    """The archive's file entries, after the checks on its central directory."""
    if len(data) > limits.max_bytes:
        raise UploadError(413, "too_large", f"the upload is over {limits.max_bytes} bytes")
    try:
        zf = zipfile.ZipFile(io.BytesIO(data))
        infos = zf.infolist()
    except (zipfile.BadZipFile, zipfile.LargeZipFile, ValueError, OSError) as exc:
        raise UploadError(400, "not_a_zip", f"the upload is not a readable zip archive ({exc})") from None
    if len(infos) > limits.max_files:
        raise UploadError(413, "too_many_files", f"the archive holds {len(infos)} entries, over the cap of "
                                                 f"{limits.max_files}")
    problems = []
    for info in infos:
        why = _bad_path(info.filename) or (f"{info.filename!r}: {k}" if (k := _kind(info)) else None)
        if why:
            problems.append(why)
    if problems:
        raise UploadError(400, "unsafe_entry", "the archive holds entries that are refused", problems)
    files = [i for i in infos if not i.is_dir()]
    declared = sum(i.file_size for i in files)
    for info in files:
        if info.file_size > limits.max_member_bytes:
            problems.append(f"{info.filename!r}: {info.file_size} bytes unpacked, over the cap of "
                            f"{limits.max_member_bytes}")
        elif info.file_size > limits.ratio_floor and info.file_size > limits.max_ratio * max(info.compress_size, 1):
            problems.append(f"{info.filename!r}: unpacks to {info.file_size / max(info.compress_size, 1):.0f} times "
                            f"its packed size, over the cap of {limits.max_ratio:g}")
    if declared > limits.max_unpacked:
        problems.append(f"the archive unpacks to {declared} bytes, over the cap of {limits.max_unpacked}")
    elif declared > limits.ratio_floor and declared > limits.max_ratio * max(len(data), 1):
        problems.append(f"the archive unpacks to {declared / len(data):.0f} times its size, over the cap of "
                        f"{limits.max_ratio:g}")
    if problems:
        raise UploadError(413, "zip_bomb", "the archive unpacks to too much", problems)
    return files


def _read(zf: zipfile.ZipFile, info: zipfile.ZipInfo, limits: Limits) -> bytes:
    """An entry's bytes, read no further than its declared size (a lying header is refused)."""
    cap = min(info.file_size, limits.max_member_bytes)
    try:
        with zf.open(info) as f:
            out = f.read(cap + 1)
    except (zipfile.BadZipFile, NotImplementedError, RuntimeError, ValueError, OSError, EOFError) as exc:
        raise UploadError(400, "bad_entry", f"{info.filename!r}: cannot be unpacked ({exc})") from None
    if len(out) > cap:
        raise UploadError(413, "zip_bomb", f"{info.filename!r}: unpacks to more than its header says")
    return out


def _check_prediction(name: str, raw: bytes, workdir: Path) -> str | None:
    """What is wrong with one prediction file's bytes under the score contract, or None."""
    from colonbench.benchmark.exchange import read_prediction
    from colonbench.errors import InputError

    try:
        obj = json.loads(raw.decode("utf-8"))
    except UnicodeDecodeError:
        return f"{name}: not UTF-8 text"
    except json.JSONDecodeError as exc:
        return f"{name}: not valid JSON ({exc})"
    if isinstance(obj, dict) and obj.get("error") not in (None, "", False):
        return None if isinstance(obj["error"], str) else f"{name}: 'error' must be a message (a string)"
    path = workdir / "prediction.json"
    path.write_bytes(raw)
    try:
        read_prediction(path)
    except InputError as exc:
        return f"{name}: {str(exc).removeprefix('prediction.json: ').removeprefix('prediction.json')}".strip()
    return None


def check(data: bytes, known: set[str], limits: Limits = Limits()) -> dict[str, bytes]:
    """Check an uploaded archive against a suite's sample ids.

    Parameters
    ----------
    data : bytes
        The upload.
    known : set of str
        The suite's sample ids (:func:`colonbench.server.hidden.sample_ids`).
    limits : Limits

    Returns
    -------
    dict
        Each sample id's prediction bytes, every one of ``known`` present.

    Raises
    ------
    UploadError
        Any of the module's refusals, with every problem found.
    """
    files = _entries(data, limits)
    zf = zipfile.ZipFile(io.BytesIO(data))
    out, problems, where = {}, [], {}
    for info in files:
        base = PurePosixPath(info.filename).name
        stem, suffix = base[:-5], base[-5:]
        if suffix != ".json":
            problems.append(f"{info.filename!r}: not a <sample_id>.json prediction")
        elif stem not in known:
            problems.append(f"{info.filename!r}: {stem!r} is not a sample id of this suite")
        elif stem in where:
            problems.append(f"{info.filename!r}: a second prediction of {stem} (also {where[stem]!r})")
        else:
            where[stem] = info.filename
    if problems:
        raise UploadError(422, "bad_names", "the archive's files are not this suite's <sample_id>.json", problems)
    missing = sorted(known - set(where))
    if missing:
        raise UploadError(422, "missing_samples", f"{len(missing)} sample(s) have no prediction (write "
                          "{\"error\": \"...\"} for a sample the method failed on)", missing)
    with tempfile.TemporaryDirectory(prefix="colonbench-upload-") as tmp:
        for info in files:
            raw = _read(zf, info, limits)
            stem = PurePosixPath(info.filename).name[:-5]
            why = _check_prediction(f"{stem}.json", raw, Path(tmp))
            if why:
                problems.append(why)
            out[stem] = raw
    if problems:
        raise UploadError(422, "bad_predictions", "predictions that are not the score contract (docs/formats.md)",
                          problems)
    return out


def canonical_zip(predictions: dict[str, bytes]) -> tuple[bytes, str]:
    """The checked predictions as one deterministic zip (sorted, flat, fixed times) and its sha256."""
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as zf:
        for sid in sorted(predictions):
            info = zipfile.ZipInfo(f"{sid}.json", date_time=(2000, 1, 1, 0, 0, 0))
            info.compress_type = zipfile.ZIP_DEFLATED
            info.external_attr = (stat.S_IFREG | 0o644) << 16
            zf.writestr(info, predictions[sid])
    data = buf.getvalue()
    return data, hashlib.sha256(data).hexdigest()


def unpack_canonical(data: bytes, folder: Path) -> int:
    """Write a stored canonical zip's files into ``folder`` (their names were checked when it was accepted)."""
    folder.mkdir(parents=True, exist_ok=True)
    with zipfile.ZipFile(io.BytesIO(data)) as zf:
        for info in zf.infolist():
            name = PurePosixPath(info.filename).name
            (folder / name).write_bytes(zf.read(info))
        return len(zf.infolist())
