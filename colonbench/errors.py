"""Exceptions that carry a message meant for the user.

Every check on user input raises :class:`InputError` with a sentence that names
the problem (which file, which field, which value, what was expected), so the
command line can print it without a traceback.
"""


class ColonbenchError(Exception):
    """Base class of all errors raised on purpose by colonbench."""


class InputError(ColonbenchError, ValueError):
    """Bad user input: a file, a config value or an argument that cannot be used."""
