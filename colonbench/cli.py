"""The ``colonbench`` command line.

Errors in user input are printed as one line naming the problem
(``colonbench: error: ...``) with exit status 2; a traceback means a bug.
A mistyped option of a verb is refused with that verb's usage. The library
speaks through :mod:`logging`; the command line shows its ``colonbench``
messages of level INFO and above on stderr (WARNING and above with
``--quiet``), each as its bare message.
"""

from __future__ import annotations

import argparse
import logging
import sys

from colonbench import __version__
from colonbench.errors import ColonbenchError, did_you_mean


#: The verb groups, in the order ``colonbench --help`` lists them (data flow: data, model, maps, video, benchmark).
GROUPS = ("data", "model", "maps", "video", "evaluation", "suites", "benchmark", "results", "server", "demo")


class VerbParser(argparse.ArgumentParser):
    """An argument parser whose ``--help`` opens with one line saying what the command does, then its usage."""

    def format_help(self) -> str:
        summary, self.description = self.description, None
        try:
            text = super().format_help()
        finally:
            self.description = summary
        return f"{summary}\n\n{text}" if summary else text


class _Refused(Exception):
    """A verb parser's error, held until it is known whether an unrecognised option should be named first."""


class _Verb(VerbParser):
    """A verb's parser: what it does not recognise is refused here, with the verb's usage and, for a mistyped
    option, the closest of its options (argparse would hand the leftovers to the top-level parser, whose usage
    names no option of the verb). An unrecognised option is named before any other error (a mistyped required
    option would otherwise be reported as missing). No option is taken by an abbreviation of its name."""

    _holding = False

    def __init__(self, *args, **kwargs):
        # an option is taken by its whole name only: argparse's prefix matching would read ``submit --token
        # SECRET`` as ``--token-file SECRET``, and any new option could change what an abbreviation means
        kwargs.setdefault("allow_abbrev", False)
        super().__init__(*args, **kwargs)

    def error(self, message):
        if self._holding:
            raise _Refused(message)
        super().error(message)

    def parse_known_args(self, args=None, namespace=None):
        args = list(sys.argv[1:] if args is None else args)
        message = None
        self._holding = True
        try:
            namespace, extras = super().parse_known_args(args, namespace)
        except _Refused as refused:
            message, extras = str(refused), self._leftovers(args)
        finally:
            self._holding = False
        if extras:
            self.error(f"unrecognized arguments: {' '.join(extras)}{self._did_you_mean(extras)}")
        if message:
            self.error(message)
        return namespace, extras

    def _leftovers(self, args) -> list:
        """What a parse that requires nothing leaves unrecognised in ``args`` (none if it fails otherwise)."""
        required = [a for a in self._actions if a.required]
        for a in required:
            a.required = False
        self._holding = True
        try:
            return super().parse_known_args(args, None)[1]
        except _Refused:
            return []
        finally:
            for a in required:
                a.required = True

    def _did_you_mean(self, extras) -> str:
        options = [o for o in self._option_string_actions if o.startswith("--")]
        for arg in extras:
            if arg.startswith("-") and (close := did_you_mean(arg.split("=", 1)[0], options)):
                return close
        return ""


class _Top(VerbParser):
    """The ``colonbench`` parser: a mistyped verb is refused naming the closest verb, where one is close."""

    verbs: dict = {}

    def parse_known_args(self, args=None, namespace=None):
        args = list(sys.argv[1:] if args is None else args)
        word = next((a for a in args if not a.startswith("-")), None)
        if word is not None and self.verbs and word not in self.verbs and (close := did_you_mean(word, self.verbs)):
            self.error(f"argument COMMAND: invalid choice: {word!r}{close}; colonbench --help lists the commands")
        return super().parse_known_args(args, namespace)


def build_parser() -> argparse.ArgumentParser:
    """The ``colonbench`` parser: each verb group's module adds its verbs (:mod:`colonbench.commands`)."""
    import importlib

    parser = _Top(
        prog="colonbench",
        description="colonbench: synthetic colonoscopy coverage data and a benchmark of coverage-estimation methods. "
                    "All geometry is in millimetres.")
    parser.add_argument("--version", action="version", version=f"colonbench {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Verb)
    for group in GROUPS:
        importlib.import_module(f"colonbench.commands.{group}").add_parsers(sub)
    parser.verbs = sub.choices
    for action in sub._choices_actions:  # each verb's help line opens its --help
        verb = sub.choices[action.dest]
        if verb.description is None and action.help:
            verb.description = action.help[0].upper() + action.help[1:] + "."
    return parser


def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 0
    handler = _log_to_stderr(logging.WARNING if getattr(args, "quiet", False) else logging.INFO)
    try:
        status = args.func(args)
    except ColonbenchError as exc:
        print(f"colonbench: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("colonbench: interrupted", file=sys.stderr)
        return 130
    finally:
        handler.close()
    return int(status or 0)


class _Stderr(logging.StreamHandler):
    """A handler writing each record's bare message to whatever ``sys.stderr`` is when it is written."""

    def __init__(self):
        super().__init__()
        self.setFormatter(logging.Formatter("%(message)s"))

    @property
    def stream(self):
        return sys.stderr

    @stream.setter
    def stream(self, value):
        pass

    def close(self):
        logger = logging.getLogger("colonbench")
        logger.removeHandler(self)
        logger.setLevel(self.previous_level)
        super().close()


def _log_to_stderr(level: int) -> _Stderr:
    """Show the library's ``colonbench`` log records at ``level`` and above on stderr, for one command (the
    returned handler's ``close()`` undoes it): a Python user of the library sees them only where they configure
    logging themselves."""
    logger = logging.getLogger("colonbench")
    handler = _Stderr()
    handler.previous_level = logger.level
    logger.addHandler(handler)
    logger.setLevel(level)
    return handler


if __name__ == "__main__":
    sys.exit(main())

