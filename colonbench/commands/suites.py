"""``colonbench suites``: list the suites, check the cached ones, archive a suite, fetch an archive, write a card."""

from __future__ import annotations

import argparse
import time

DATA_HELP = ("suite data folder (default $COLONBENCH_DATA, else $XDG_CACHE_HOME/colonbench/suites, else "
             "~/.cache/colonbench/suites)")


def cmd_suites(args):
    """List the named suites; with --check, check every cached one against its published signature."""
    from colonbench.benchmark import suites
    from colonbench.errors import InputError

    if getattr(args, "action", None) == "archive":
        return _archive(args)
    if getattr(args, "action", None) == "fetch":
        return _fetch(args)
    if getattr(args, "action", None) == "card":
        return _card(args)
    rows = suites.SUITES if args.all_versions else tuple(suites.latest().values())
    for s in rows:
        here = suites.data_dir(s, args.data)
        state = "cached" if (here / "dataset.lock.json").is_file() else "not generated"
        what = "whole-colon reconstructions" if s.task == "colon" else "segments"
        noise = ", ".join(f"{n:g}" for n in s.noise_mm)
        print(f"{s.id:<9} {s.samples:4d} {what} x noise {noise} mm; generates in {s.generate_seconds:.0f} s on "
              f"2 cores ({state} in {here})\n          {s.tests}\n          manifest {s.manifest}, split {s.split}"
              + (f", {s.limit} spread evenly" if s.limit else "")
              + f"\n          cite as {s.citation}; content hash of the published data {s.sha256}"
              + (f"\n          archive {s.archive_url} (sha256 {s.archive_sha256})" if s.archive_url else "") + "\n")
    if not args.check:
        return 0
    differs = 0
    for s in rows:
        here = suites.data_dir(s, args.data)
        if not (here / "dataset.lock.json").is_file():
            continue
        t = time.perf_counter()
        try:
            result = suites.check(s, here)
        except InputError as exc:   # not finished, say: nothing to compare yet, and no difference found
            print(f"{s.id}: not checked: {exc}")
            continue
        differs += not result.verified
        print(f"{s.id}: {'verified, ' if result.verified else ''}{result.summary()} ({time.perf_counter() - t:.1f} s)")
    return 1 if differs else 0


def _archive(args):
    from colonbench.benchmark import archive, suites

    suite = suites.get(args.suite)
    data = suites.ensure_data(suite, args.data, workers=args.workers, progress=not args.quiet)
    info = archive.write_archive(suite, data, args.out)
    how = "bit-identical to" if info["bit_identical"] else "within tolerance of"
    print(f"wrote {args.out}: {suite.citation}, {info['samples']} samples, {info['bytes'] / 2**20:.1f} MiB, {how} the "
          f"published data\nsha256 {info['sha256_archive']}")
    return 0


def _fetch(args):
    from colonbench.benchmark import archive, suites

    suite = suites.get(args.suite)
    where = archive.fetch(suite, args.url, args.sha256, args.data, progress=not args.quiet)
    print(f"{suite.id} fetched into {where}, verified against {suite.signature}")
    return 0


def _card(args):
    from colonbench.benchmark import cards, suites

    for suite in suites.parse(args.suite):
        md, js = cards.write(suite, args.out)
        print(f"{suite.id}: wrote {md} and {js}")
    return 0


def add_parsers(sub) -> None:
    """Add ``suites`` (with its ``archive`` and ``fetch`` actions) to the ``colonbench`` subparsers."""
    p = sub.add_parser("suites", help="list the named, versioned suites; check, archive or fetch their data",
                       description="List the benchmark's named, versioned suites: what each tests, its size, how to "
                                   "cite it and the time to generate it. --check checks the cached data of each "
                                   "against its published signature; 'suites archive' writes a suite's data as one "
                                   "file and 'suites fetch' puts such a file into the suite cache.")
    p.add_argument("--data", help=DATA_HELP)
    p.add_argument("--check", action="store_true",
                   help="check the cached data of each suite against its published signature: bit-identical, within "
                        "tolerance, or what differs (exit 1 only where data differ)")
    p.add_argument("--all-versions", action="store_true", help="also list older versions of the suites")
    p.set_defaults(func=cmd_suites, action=None)
    actions = p.add_subparsers(dest="action", metavar="ACTION")
    a = actions.add_parser("archive", help="write a suite's scored data as one file and print its sha256",
                           description="Write a suite's scored data (inputs, truth, sample ids; the suite's shards "
                                       "holding only its scored samples) as one tar file, and print its sha256: what "
                                       "'colonbench suites fetch' takes. The data are generated where missing.")
    a.add_argument("suite", help="suite id or name (colonbench suites)")
    a.add_argument("--out", required=True, help="archive file to write")
    a.add_argument("--data", default=argparse.SUPPRESS, help=DATA_HELP)
    a.add_argument("--workers", type=int, default=1, help="processes generating missing data (default 1)")
    a.add_argument("--quiet", action="store_true", help="no progress bars")
    f = actions.add_parser("fetch", help="download a suite's archive into the suite cache, checked",
                           description="Download a suite's archive (colonbench suites archive) into the suite cache, "
                                       "refusing it unless its sha256 is --sha256 and its data verify against the "
                                       "suite's published signature; then benchmark, evaluate, export and score use "
                                       "it as they use generated data. A refused download leaves nothing behind.")
    f.add_argument("suite", help="suite id or name (colonbench suites)")
    f.add_argument("--url", required=True, help="http(s) address of the archive")
    f.add_argument("--sha256", required=True, help="the archive's sha256 (64 hex digits)")
    f.add_argument("--data", default=argparse.SUPPRESS, help=DATA_HELP)
    f.add_argument("--quiet", action="store_true", help="no progress bar")
    c = actions.add_parser("card", help="write a suite's dataset card (Markdown) and Croissant metadata (JSON-LD)",
                           description="Write a suite's dataset card, DIR/<suite id>.md (what it tests, how it is "
                                       "made, what a sample holds, licence and attribution, how to cite it, its "
                                       "signature), and its Croissant 1.0 metadata, DIR/<suite id>.croissant.json, "
                                       "from the suite registry, its manifest and its published signature; no data "
                                       "are needed. The project keeps every suite's pair in docs/suites/.")
    c.add_argument("suite", help="suite id or name (colonbench suites), comma-separated ones, or all")
    c.add_argument("--out", default=".", metavar="DIR", help="folder to write them into (default: the current folder)")
