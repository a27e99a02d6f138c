"""``colonbench suites``: list the suites, check the cached ones, archive a suite, fetch an archive, write a card,
build a suite from a dataset download (C3VD)."""

from __future__ import annotations

import argparse
import time

#: The datasets ``colonbench suites build`` reads (their layouts).
BUILDERS = ("c3vd", "hidden")
DATA_HELP = ("suite data folder (default $COLONBENCH_DATA, else $XDG_CACHE_HOME/colonbench/suites, else "
             "~/.cache/colonbench/suites)")


def cmd_suites(args):
    """List the named suites; with --check, check the named ones (default: every cached one) against their
    published signatures."""
    from colonbench.benchmark import suites
    from colonbench.errors import InputError

    if getattr(args, "action", None) == "archive":
        return _archive(args)
    if getattr(args, "action", None) == "fetch":
        return _fetch(args)
    if getattr(args, "action", None) == "card":
        return _card(args)
    if getattr(args, "action", None) == "build":
        return _build(args)
    from colonbench.benchmark import local_suites

    named = suites.parse(",".join(args.check), args.data) if args.check else None
    rows = suites.SUITES if args.all_versions else tuple(suites.latest().values())
    built = local_suites.found(args.data)
    if named is not None:   # only those, each with its data, or nothing is checked
        missing = [s for s in named if not (suites.data_dir(s, args.data) / "dataset.lock.json").is_file()]
        if missing:
            raise InputError("nothing to check: " + "; ".join(f"{s.id} has no data in {suites.data_dir(s, args.data)}"
                                                              for s in missing)
                             + " (colonbench benchmark --suites ID generates a suite's data, colonbench suites "
                               "fetch downloads them)")
        rows = [s for s in named if not isinstance(s, local_suites.LocalSuite)]
        built = [s for s in named if isinstance(s, local_suites.LocalSuite)]
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
    for s in built:
        what = "whole-colon reconstructions" if s.task == "colon" else "segments"
        print(f"{s.id} {s.samples:4d} {what} x noise {', '.join(f'{n:g}' for n in s.noise_mm)} mm; built here from a "
              f"download ({s.folder})\n          {s.tests}\n          cite as {s.citation}, importer {s.name} "
              f"{s.version}, with the dataset's own citation (docs/benchmark.md)\n")
    rows = tuple(rows) + tuple(built)
    if args.check is None:
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
        summary = result.summary()
        if isinstance(s, local_suites.LocalSuite):   # checked against the signature made when it was built
            summary = summary.replace("the published data", "the data as built")
        print(f"{s.id}: {'verified, ' if result.verified else ''}{summary} ({time.perf_counter() - t:.1f} s)")
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
    from colonbench.benchmark import cards, local_suites, suites
    from colonbench.errors import InputError

    for suite in suites.parse(args.suite, getattr(args, "data", None)):
        if isinstance(suite, local_suites.LocalSuite):
            raise InputError(f"{suite.id} was built here from a download: it has no card; its entry is "
                             f"{suite.folder}/{local_suites.FILE}")
        md, js = cards.write(suite, args.out)
        print(f"{suite.id}: wrote {md} and {js}")
    return 0


def _build(args):
    from pathlib import Path

    if args.dataset == "hidden":
        return _build_hidden(args)
    if args.seed_file or args.publish or args.name:
        from colonbench.errors import InputError

        raise InputError("--seed-file, --publish and --name are for 'suites build hidden'")
    from colonbench.benchmark import c3vd_suite
    from colonbench.benchmark.local_suites import read_entry

    built = c3vd_suite.build_all(args.source_dir, args.data, frames_every=args.frames_every, width_px=args.width_px,
                                 workers=args.workers, intrinsics=args.intrinsics, progress=not args.quiet)
    skipped = []
    for k, (suite, new) in enumerate(built):
        entry = read_entry(Path(suite.folder))
        if k == 0:   # the download's skipped folders, named once
            skipped = entry["source"]["skipped"]
        if not new:
            print(f"{suite.id} is already built from this download in {suite.folder}: nothing to do")
            continue
        for name, seq in entry["source"]["sequences"].items():
            conv = seq.get("convention")
            if suite.task == "colon":
                if seq.get("skipped"):      # among the download's skipped folders, printed below
                    continue
                print(f"{name}: a screening withdrawal of {seq['poses']} poses over {seq['colon']}, camera centres "
                      f"{conv['inside_share']:.1%} inside its lumen with poses {conv['convention']}; "
                      f"{seq['observed_share']:.1%} of the phantom seen from {seq['frames_seen_from']} frames")
                continue
            check = (f"poses {conv['convention']}, depth on the mesh within {conv['median_mm']:.3f} mm (median)"
                     if conv else "no depth frames: no pose check, no fused partial")
            video = seq.get("video_check")
            if video:
                check += (f"; its fused partials reach {video['reach']:.1%} of the observed area within "
                          f"{video['tolerance_mm']:g} mm ({video['threshold']:.0%} needed"
                          + ("" if video["passed"] else ": its video samples left out") + ")")
            print(f"{name}: {seq['samples']} samples, {seq['observed_share']:.1%} of the phantom observed; {check}"
                  + (f"; {len(seq['skipped_segments'])} segment sample(s) left out" if seq["skipped_segments"] else ""))
        what = "whole-colon reconstructions" if suite.task == "colon" else "samples"
        print(f"built {suite.id}: {suite.samples} {what} in {suite.folder} ({entry['build_seconds']:.0f} s)")
    for s in skipped:
        print(f"skipped {s['folder']}: {s['reason']}")
    for suite, _ in built:
        print(f"score it: colonbench benchmark --suites {suite.id} --methods METHOD --out DIR"
              + (f" --data {args.data}" if args.data else ""))
    return 0


def _build_hidden(args):
    """``suites build hidden``: a suite generated from a manifest with a secret seed, or built from a C3VD
    download (--from a folder), truth under --data, inputs exported to --publish (colonbench.server.hidden)."""
    from pathlib import Path

    from colonbench.errors import InputError
    from colonbench.pipeline import export_suite
    from colonbench.server import hidden

    data = getattr(args, "data", None)
    if not data or not args.publish:
        raise InputError("suites build hidden needs --data DIR (the private folder of the truth, which only the "
                         "server reads) and --publish DIR (the inputs to publish)")
    if Path(args.publish).resolve().is_relative_to(Path(data).resolve()):
        raise InputError(f"--publish {args.publish} is inside --data {data}: publish the inputs elsewhere")
    if Path(data).resolve().is_relative_to(Path(args.publish).resolve()):
        raise InputError(f"--data {data} is inside --publish {args.publish}: the truth would be published with the "
                         "inputs; keep it elsewhere")
    publish = Path(args.publish)
    if publish.exists() and any(publish.iterdir()):
        raise InputError(f"{publish} is not empty: publish into a new or empty folder")
    if Path(args.source_dir).is_dir():     # a C3VD download, through its importer
        if args.seed_file or args.name:
            raise InputError(f"--from {args.source_dir} is a folder, read as a C3VD download: its suite has the "
                             "importer's id and no seed (--seed-file and --name are for manifests)")
        suite, new = hidden.build_c3vd(args.source_dir, data, frames_every=args.frames_every,
                                       width_px=args.width_px, workers=args.workers, intrinsics=args.intrinsics,
                                       progress=not args.quiet)
        keep = "it and the download are all the truth there is"
    else:
        if args.frames_every or args.width_px or args.intrinsics:
            raise InputError("--frames-every, --width-px and --intrinsics are for a C3VD download (--from DIR)")
        seed = hidden.read_seed(args.seed_file) if args.seed_file else hidden.new_seed()
        suite, new = hidden.build(args.source_dir, data, seed, name=args.name, workers=args.workers,
                                  progress=not args.quiet)
        keep = "it holds the secret seed"
    export_suite(suite.id, publish, data=data, progress=not args.quiet)
    inputs = hidden.seal_public(publish, suite)
    print(f"{'built' if new else 'found'} hidden suite {suite.id}: {suite.samples} segments, truth in {suite.folder} "
          f"(keep it private: {keep})\npublished inputs in {publish}: "
          f"{len(inputs['files'])} files, inputs sha256 {inputs['inputs_sha256']}\nserve it: colonbench serve "
          f"--suites {data} --db sqlite:///server.db")
    return 0


def _dataset(value: str) -> str:
    """The ``suites build`` dataset argument: a layout colonbench builds from, or an error saying what goes where
    (a folder given here is the download, which goes after --from)."""
    from pathlib import Path

    if value in BUILDERS:
        return value
    hint = f": the download's folder goes after --from, as in 'colonbench suites build c3vd --from {value}'"
    raise argparse.ArgumentTypeError(f"{value!r} is not a dataset colonbench builds suites from ({', '.join(BUILDERS)})"
                                     + (hint if Path(value).exists() else ""))


def add_parsers(sub) -> None:
    """Add ``suites`` (with its ``archive`` and ``fetch`` actions) to the ``colonbench`` subparsers."""
    p = sub.add_parser("suites", help="list the named, versioned suites; check, archive or fetch their data",
                       description="List the benchmark's named, versioned suites: what each tests, its size, how to "
                                   "cite it and the time to generate it. --check checks the cached data of each "
                                   "against its published signature; 'suites archive' writes a suite's data as one "
                                   "file and 'suites fetch' puts such a file into the suite cache.")
    p.add_argument("--data", help=DATA_HELP)
    p.add_argument("--check", nargs="*", metavar="SUITE",
                   help="check the cached data of the named suites (ids or names; default: every cached one) against "
                        "their published signatures: bit-identical, within tolerance, or what differs (exit 1 only "
                        "where data differ)")
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
    b = actions.add_parser("build", help="build a suite from your download of a dataset colonbench may not ship "
                                         "(C3VD / C3VDv2)",
                           description="Build suites from a C3VD or C3VDv2 download: every registered sequence "
                                       "checked (its depth frames reprojected with its poses must land on its mesh), "
                                       "its phantom cut into 50-70 mm segments along its centerline, truth from "
                                       "C3VD's per-face coverage, partials on the observed faces and from the depth "
                                       "frames fused by TSDF (suite c3vd-...); every screening withdrawal over a "
                                       "whole-colon mesh checked (its camera centres must lie inside the lumen), "
                                       "what colonbench's camera sees along its real trajectory as a whole partial "
                                       "colon, mapped and scored as colon-v1 (suite c3vd-colon-...). The suites go "
                                       "into the suite cache under ids made from the download's file digests; a "
                                       "refused download leaves nothing behind (docs/benchmark.md, 'Real "
                                       "trajectories: C3VD'). 'suites build hidden' generates a segment suite "
                                       "from a manifest with a secret seed, or builds a C3VD download's (--from "
                                       "its folder): its truth into --data, which only the evaluation server "
                                       "reads, its inputs (as export writes them) into --publish "
                                       "(docs/server.md).")
    b.add_argument("dataset", type=_dataset, metavar="DATASET",
                   help=f"the dataset's layout: {', '.join(BUILDERS)} (C3VD and C3VDv2; hidden: a generated suite "
                        "with a secret seed, its truth kept for the evaluation server, docs/server.md)")
    b.add_argument("--from", dest="source_dir", required=True, metavar="DIR",
                   help="the download's folder; hidden: a named segment suite (demo-v1), a segment manifest file "
                        "(procedural or naming your meshes), or a C3VD download's folder")
    b.add_argument("--publish", metavar="DIR", help="hidden: the folder of the published inputs (as colonbench "
                                                    "export writes them, without truth or seeds)")
    b.add_argument("--seed-file", metavar="FILE", help="hidden: a file holding the secret seed, an integer of at "
                                                       "least 2**40 (default: a new one drawn; it is kept only in "
                                                       "the suite's private folder)")
    b.add_argument("--name", help="hidden: the suite's name (default: the manifest's name with -hidden)")
    b.add_argument("--data", "--out", dest="data", default=argparse.SUPPRESS, help=DATA_HELP)
    b.add_argument("--frames-every", type=int, default=None, metavar="K",
                   help="fuse every K-th depth frame (default 2); a screening withdrawal's views: every K-th frame "
                        "(default 5)")
    b.add_argument("--width-px", type=int, default=None, metavar="W",
                   help="width of each of the five pinholes a fused fisheye frame is resampled into, 90 degrees "
                        "across (default 128)")
    b.add_argument("--intrinsics", metavar="FILE",
                   help="the camera's camera_intrinsics.txt for every sequence, in place of the download's own "
                        "(needed where it holds none beside its sequences)")
    b.add_argument("--workers", type=int, default=1, help="sequences built at a time (default 1)")
    b.add_argument("--quiet", action="store_true", help="no progress bars")
    c.add_argument("--out", default=".", metavar="DIR", help="folder to write them into (default: the current folder)")
