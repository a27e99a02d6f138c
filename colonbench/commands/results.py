"""``colonbench results``: check a run folder for submission to the repository's ``results/`` registry, and add it
there (:mod:`colonbench.benchmark.submitted`)."""

from __future__ import annotations


def cmd_results(args):
    """Check a run folder for submission (``check``), or copy a checked one into the registry (``add``)."""
    from colonbench.benchmark import submitted
    from colonbench.errors import ColonbenchError

    if args.action is None:
        raise ColonbenchError("give an action: colonbench results check RUN [--method NAME], or colonbench results "
                              "add RUN --method NAME")
    checked = submitted.check(args.run, args.method)
    if args.action == "check":
        print("\n".join(checked.lines()))
        return
    _, how = submitted.target(args.into)    # refused before anything is written where there is none
    out = submitted.add(args.run, args.method, args.into)
    print(f"added {args.method} on {checked.suite.id}"
          + ("" if checked.track == "points" else f", {checked.track} track") + f" to {out} ({how}): commit that "
          "folder and open a pull request (docs/benchmark.md, Submitting results)")


def add_parsers(sub) -> None:
    """Add ``results`` (with its ``check`` and ``add`` actions) to the ``colonbench`` subparsers."""
    p = sub.add_parser("results", help="check a run for submission to the results/ registry, and add it there",
                       description="Check a run folder for submission to the repository's results/ registry (its "
                                   "suite verified against the published signature, every segment present or "
                                   "failed, versions and machine recorded, one track), and add a checked one "
                                   "there for a pull request (docs/benchmark.md, Submitting results).")
    p.set_defaults(func=cmd_results, action=None)
    actions = p.add_subparsers(dest="action", metavar="ACTION")
    c = actions.add_parser("check", help="check a run folder for submission; exit 0 with one OK line per method",
                           description="Check a run folder for submission: refused, naming every reason, unless its "
                                       "suite record verified against the published signature and is the suite's "
                                       "content hash, every sample at every noise level has a row (an estimate or "
                                       "a failure with its error), each method's version, the package versions and "
                                       "the machine are recorded, it holds one known track and its rows have the "
                                       "results columns.")
    c.add_argument("run", metavar="RUN", help="a run folder: colonbench benchmark --out DIR's DIR/runs/<suite id>, "
                                              "or a colonbench evaluate or score run")
    c.add_argument("--method", help="the method to check (default: every method of the run)")
    a = actions.add_parser("add", help="copy a checked run of one method into the results/ registry",
                           description="Copy a checked run of one method into the results/ registry, as "
                                       "results/<suite id>[@<track>]/<method>/ (run.json and its results/<method>.csv "
                                       "and .json), replacing what that folder held; refused, and nothing written, "
                                       "where the check fails.")
    a.add_argument("run", metavar="RUN", help="the run folder (as for check)")
    a.add_argument("--method", required=True, help="the method to add")
    a.add_argument("--into", metavar="DIR", help="the registry folder (default $COLONBENCH_RESULTS, else the "
                                                 "results/ of the colonbench checkout the current folder is in; "
                                                 "refused in none)")
