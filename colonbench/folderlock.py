"""One command at a time in a folder: an exclusive, non-blocking ``flock`` on a hidden file in it."""

from __future__ import annotations

import fcntl
from contextlib import contextmanager
from pathlib import Path

from colonbench.errors import InputError


@contextmanager
def folder_lock(folder, name: str, what: str):
    """Hold ``folder/.<name>.lock`` for the duration; refuse if another process holds it.

    Parameters
    ----------
    folder : path
        Existing folder.
    name : str
        Lock name (``generate``, ``evaluate``).
    what : str
        What the holder does, for the message: "another {what} is running in this folder".

    Raises
    ------
    InputError
        The lock is held. The kernel releases it when its holder exits, even killed.
    """
    folder = Path(folder)
    with open(folder / f".{name}.lock", "w") as guard:
        try:
            fcntl.flock(guard, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            raise InputError(f"{folder}: another {what} is running in this folder") from None
        yield
