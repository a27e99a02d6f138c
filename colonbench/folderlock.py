"""One command at a time in a folder: an exclusive, non-blocking ``flock`` on a hidden file in it, removed after."""

from __future__ import annotations

import fcntl
import os
from contextlib import contextmanager
from pathlib import Path

from colonbench.errors import InputError


@contextmanager
def folder_lock(folder, name: str, what: str):
    """Hold ``folder/.<name>.lock`` for the duration; refuse if another process holds it.

    The file is made when the lock is taken and removed when it is given back, so a finished command leaves
    nothing behind. A process that opened the file just before its holder removed it finds, once it holds the
    lock, that the file is no longer there and takes the lock again on a new one: two processes never hold it
    at once.

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
        The lock is held. The kernel releases it when its holder exits, even killed (the file then stays,
        unheld, until the next command in the folder takes and removes it).
    """
    path = Path(folder) / f".{name}.lock"
    while True:
        guard = open(path, "a")
        try:
            fcntl.flock(guard, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            guard.close()
            raise InputError(f"{folder}: another {what} is running in this folder") from None
        try:
            same = os.stat(path).st_ino == os.fstat(guard.fileno()).st_ino
        except FileNotFoundError:
            same = False
        if same:
            break
        guard.close()  # its holder removed it while we waited on it: lock the file that is there now
    try:
        yield
    finally:
        try:
            path.unlink()  # still held: no one else can have taken it since
        except FileNotFoundError:
            pass
        guard.close()
