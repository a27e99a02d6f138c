"""The segment suites' tracks: what a method is given besides the partial cloud.

* ``points`` (the default): the cloud alone. A cloud that is a complete shorter segment cannot be told from one
  whose end nobody saw.
* ``length``, the known-length track: the cloud and the segment's nominal arc length along the centerline (the
  sample's ``length_mm``, the length it was cut at), as in the paper's pipeline, which splits a colon into
  segments of a given arc length. The same suites: the same data, signatures and truth.

A Python method is given the length as ``estimate(points, length_mm=L)`` where its ``estimate`` has a
``length_mm`` parameter (:func:`takes_length`); one without answers as on the points track, and its run records
``takes_length: false`` so that the tables say so. An ``exec:`` program is called with ``--length-mm L``
appended, once per length (docs/formats.md). A run folder records its track (``track`` in run.json; ``points``
where it names none), and a leaderboard never mixes tracks. The whole-colon suite has no known-length track:
its map cuts the segments and knows their planes itself.
"""

from __future__ import annotations

import inspect

from colonbench.errors import InputError

#: The tracks, the default first.
TRACKS = ("points", "length")
DEFAULT = "points"
#: How a citation or a table names a track.
LABELS = {"points": "points-only track", "length": "known-length track"}


def check(track, suite=None) -> str:
    """``track`` if it is one of :data:`TRACKS` (and ``suite``, when given, has it), else an :class:`InputError`."""
    track = DEFAULT if track is None else str(track).strip()
    if track not in TRACKS:
        raise InputError(f"unknown track {track!r}; the tracks are {', '.join(TRACKS)}")
    if suite is not None and track != DEFAULT and getattr(suite, "task", "segments") == "colon":
        raise InputError(f"{suite.id} has no {LABELS[track]}: its map cuts the segments and knows their planes "
                         f"itself (docs/mapping.md); give a segment suite, or --track {DEFAULT}")
    return track


def of_run(run: dict) -> str:
    """A run record's track (``points`` where it names none: runs made before tracks)."""
    return str(run.get("track") or DEFAULT)


def takes_length(method) -> bool:
    """Whether ``method`` is given a segment's length on the known-length track: a method that answers by sample id
    (``exec:`` programs get ``--length-mm``; ``predictions:`` were made from an export that listed it), or one whose
    ``estimate`` has a ``length_mm`` parameter."""
    if getattr(method, "by_sample", False):
        return True
    try:
        return "length_mm" in inspect.signature(method.estimate).parameters
    except (TypeError, ValueError):
        return False


def label(track) -> str:
    """A track in words: ``known-length track``."""
    return LABELS.get(str(track), f"{track} track")


def cite(suite, track=DEFAULT) -> str:
    """How a paper cites results of a suite on a track: ``real-v1 (cbs1-...)``, with ``, known-length track`` after
    it on that track."""
    return suite.citation + ("" if (track or DEFAULT) == DEFAULT else f", {label(track)}")


def cite_record(record: dict, track=DEFAULT) -> str:
    """:func:`cite` of a run's suite record (``id``, ``signature``)."""
    text = f"{record['id']} ({record.get('signature') or record.get('published_sha256', '')})"
    return text + ("" if (track or DEFAULT) == DEFAULT else f", {label(track)}")
