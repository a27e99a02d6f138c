"""Progress bars: a bar where stderr is a terminal, a line now and then where it is not, nothing when asked for none.

Every progress bar in colonbench comes from :func:`bar`, which decides it in one place. On a terminal it is a
tqdm bar on stderr. Elsewhere (a log file, a pipe, CI) it redraws nothing: it logs a line at INFO on the
logger ``colonbench.progress`` (``generate: 12/40 shard (30 %, 48 s)``) when another tenth of the way is done or
a minute has passed, never two within 10 s, and the last one when it closes, so that a short stage leaves one
line and a long one a line a minute at most; the command line shows such lines on stderr, a Python user sees
them only if they configure logging. The count only goes forwards: an update past the total stops at it.
"""

from __future__ import annotations

import logging
import sys
import time

logger = logging.getLogger(__name__)

#: A log line when this share of the total more is done ...
STEP = 0.1
#: ... or this many seconds have passed while the count moved ...
EVERY_S = 60.0
#: ... but never two lines within this many seconds (except the last, at close).
QUIET_S = 10.0


def on_terminal(stream=None) -> bool:
    """Whether ``stream`` (default: the current ``sys.stderr``) is a terminal, where a bar may redraw itself."""
    stream = sys.stderr if stream is None else stream
    try:
        return bool(stream.isatty())
    except (AttributeError, ValueError):   # no isatty, or a closed stream
        return False


def bar(iterable=None, total=None, desc: str = "", unit: str = "it", enabled: bool = True, initial: int = 0):
    """A progress bar: tqdm on a terminal, log lines elsewhere, nothing when ``enabled`` is false.

    Parameters
    ----------
    iterable : iterable, optional
        Iterate over the bar to count each item (``total`` defaults to its length).
    total : int, optional
    desc, unit : str
        What is counted: ``desc: n/total unit``.
    enabled : bool
        False: no bar and no lines (``--quiet``, ``progress=False``).
    initial : int
        Already done (a resumed run).

    Returns
    -------
    An object with ``update(n=1)``, ``set_postfix(**values)``, ``close()``, ``n``, a settable ``total``; a context
    manager, and iterable when given an iterable.
    """
    if total is None and iterable is not None and hasattr(iterable, "__len__"):
        total = len(iterable)
    if enabled and on_terminal():
        from tqdm.auto import tqdm

        return _Forward(tqdm(iterable, total=total, initial=initial, desc=desc, unit=unit, dynamic_ncols=True))
    return _Lines(iterable, total, desc, unit, initial, enabled)


class _Forward:
    """A tqdm bar whose count only goes forwards and stops at its total."""

    def __init__(self, bar):
        self._bar = bar

    n = property(lambda self: self._bar.n)
    total = property(lambda self: self._bar.total, lambda self, value: setattr(self._bar, "total", value))

    def update(self, n=1):
        if self._bar.total is not None:
            n = min(n, self._bar.total - self._bar.n)
        if n > 0:
            self._bar.update(n)

    def set_postfix(self, **values):
        self._bar.set_postfix(**values)

    def close(self):
        self._bar.close()

    def __iter__(self):
        yield from self._bar

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


class _Lines:
    """Progress as a log line now and then (STEP, EVERY_S, QUIET_S) and at close; silent when not enabled."""

    def __init__(self, iterable, total, desc, unit, initial, enabled):
        self.iterable, self.total, self.desc, self.unit, self.n = iterable, total, desc, unit, int(initial)
        self.enabled = enabled
        self._start = self._said_at = time.monotonic()
        self._said_n, self._said_step, self._postfix, self._closed = self.n, self._step(), "", False

    def _step(self) -> int:
        return int(self.n / self.total / STEP + 1e-9) if self.total else 0

    def _say(self) -> None:
        self._said_at, self._said_n, self._said_step = time.monotonic(), self.n, self._step()
        if not self.enabled:
            return
        n, total, unit = self.n, self.total, self.unit
        if unit == "B":   # bytes, in MiB
            n, total, unit = f"{n / 2**20:.1f}", None if total is None else f"{total / 2**20:.1f}", "MiB"
        count = f"{n}/{total}" if self.total else f"{n}"
        share = f"{100 * self.n / self.total:.0f} %, " if self.total else ""
        logger.info("%s: %s %s (%s%.0f s)%s", self.desc or "progress", count, unit, share,
                    time.monotonic() - self._start, self._postfix)

    def update(self, n=1):
        if self.total is not None:
            n = min(n, self.total - self.n)
        if n <= 0:
            return
        self.n += n
        since = time.monotonic() - self._said_at
        if since >= EVERY_S or (since >= QUIET_S and self._step() > self._said_step):
            self._say()

    def set_postfix(self, **values):
        self._postfix = "; " + ", ".join(f"{k} {v}" for k, v in values.items()) if values else ""

    def close(self):
        if not self._closed and self.n != self._said_n:
            self._say()
        self._closed = True

    def __iter__(self):
        try:
            for item in self.iterable:
                yield item
                self.update(1)
        finally:
            self.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
