"""The ``colonbench`` command line.

Errors in user input are printed as one line naming the problem
(``colonbench: error: ...``) with exit status 2; a traceback means a bug.
"""

from __future__ import annotations

import argparse
import sys

from colonbench import __version__
from colonbench.errors import ColonbenchError


#: The verb groups, in the order ``colonbench --help`` lists them (data flow: data, model, maps, video, benchmark).
GROUPS = ("data", "model", "maps", "video", "evaluation", "suites", "benchmark", "results", "demo")


class VerbParser(argparse.ArgumentParser):
    """An argument parser whose ``--help`` opens with one line saying what the command does, then its usage."""

    def format_help(self) -> str:
        summary, self.description = self.description, None
        try:
            text = super().format_help()
        finally:
            self.description = summary
        return f"{summary}\n\n{text}" if summary else text


def build_parser() -> argparse.ArgumentParser:
    """The ``colonbench`` parser: each verb group's module adds its verbs (:mod:`colonbench.commands`)."""
    import importlib

    parser = VerbParser(
        prog="colonbench",
        description="colonbench: synthetic colonoscopy coverage data and a benchmark of coverage-estimation methods. "
                    "All geometry is in millimetres.")
    parser.add_argument("--version", action="version", version=f"colonbench {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=VerbParser)
    for group in GROUPS:
        importlib.import_module(f"colonbench.commands.{group}").add_parsers(sub)
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
    try:
        status = args.func(args)
    except ColonbenchError as exc:
        print(f"colonbench: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("colonbench: interrupted", file=sys.stderr)
        return 130
    return int(status or 0)


if __name__ == "__main__":
    sys.exit(main())

