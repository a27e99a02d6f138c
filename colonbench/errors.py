"""Exceptions that carry a message meant for the user.

Every check on user input raises :class:`InputError` with a sentence that names
the problem (which file, which field, which value, what was expected), so the
command line can print it without a traceback.
"""


class ColonbenchError(Exception):
    """Base class of all errors raised on purpose by colonbench."""


class InputError(ColonbenchError, ValueError):
    """Bad user input: a file, a config value or an argument that cannot be used."""


def listing(names, most: int = 4) -> str:
    """Names for a message, comma-separated: all of them where there are at most ``most``, else the first
    ``most`` and how many more (never a bare "...", which reads as more where there is none).

    Examples
    --------
    >>> listing(["a.zip"])
    'a.zip'
    >>> listing(["a", "b", "c", "d", "e", "f"])
    'a, b, c, d and 2 more'
    """
    names = [str(n) for n in names]
    if len(names) <= most:
        return ", ".join(names)
    return f"{', '.join(names[:most])} and {len(names) - most} more"


def did_you_mean(word: str, choices) -> str:
    """`` (did you mean CHOICE?)`` naming the choice closest to a mistyped ``word``, or ``""`` where none is close
    (:func:`difflib.get_close_matches`): the one way colonbench suggests a verb, an option, a method or a suite."""
    import difflib

    close = difflib.get_close_matches(str(word), [str(c) for c in choices], n=1, cutoff=0.6)
    return f" (did you mean {close[0]}?)" if close else ""
