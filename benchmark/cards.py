"""Dataset cards of the suites: a Markdown card and Croissant 1.0 metadata (JSON-LD) per suite.

Both are built from what the project already records of a suite, never from text typed per suite: its
:class:`~colonbench.benchmark.suites.Suite` record (id, what it tests, sizes, hashes, generation time), its
manifest (generator version, seed, colons, real meshes, segment lengths, hole models), its published signature
(``benchmark/signatures/<id>.json.gz``: digest, tolerances and the samples' truth), the shard schema
(:mod:`colonbench.shards.schema`: what a sample holds) and the real meshes' attribution
(``data_manifests/meshes/README.md``). ``colonbench suites card SUITE`` writes them; the project keeps every
suite's pair in ``docs/suites/`` (``make cards``), and a test checks that they are what this module writes.
"""

from __future__ import annotations

import hashlib
import json
import re
from collections import Counter
from pathlib import Path

import numpy as np
import yaml

from colonbench.benchmark import suites as registry
from colonbench.benchmark import verification
from colonbench.shards import schema

#: The Croissant 1.0 JSON-LD context, as the specification gives it.
CROISSANT_CONTEXT = {
    "@language": "en", "@vocab": "https://schema.org/", "citeAs": "cr:citeAs", "column": "cr:column",
    "conformsTo": "dct:conformsTo", "cr": "http://mlcommons.org/croissant/",
    "rai": "http://mlcommons.org/croissant/RAI/", "data": {"@id": "cr:data", "@type": "@json"},
    "dataType": {"@id": "cr:dataType", "@type": "@vocab"}, "dct": "http://purl.org/dc/terms/",
    "equivalentProperty": "cr:equivalentProperty", "examples": {"@id": "cr:examples", "@type": "@json"},
    "extract": "cr:extract", "field": "cr:field", "fileProperty": "cr:fileProperty", "fileObject": "cr:fileObject",
    "fileSet": "cr:fileSet", "format": "cr:format", "includes": "cr:includes", "isLiveDataset": "cr:isLiveDataset",
    "jsonPath": "cr:jsonPath", "key": "cr:key", "md5": "cr:md5", "parentField": "cr:parentField", "path": "cr:path",
    "recordSet": "cr:recordSet", "references": "cr:references", "regex": "cr:regex", "repeated": "cr:repeated",
    "replace": "cr:replace", "samplingRate": "cr:samplingRate", "sc": "https://schema.org/",
    "separator": "cr:separator", "source": "cr:source", "subField": "cr:subField", "transform": "cr:transform",
}
CROISSANT_CONFORMS_TO = "http://mlcommons.org/croissant/1.0"
#: The licences, by SPDX id: the project's code (LICENSE) and the real colon meshes (their README).
LICENSES = {"MIT": "https://spdx.org/licenses/MIT.html", "CC-BY-4.0": "https://spdx.org/licenses/CC-BY-4.0.html"}
#: What a segment suite's sample exposes (shard paths, :data:`colonbench.shards.schema.FIELDS`).
SEGMENT_RECORD = ("samples/partial_points", "samples/coverage", "samples/hole_points", "segments/centerline",
                  "samples/hole_model", "samples/noise_mm")
GENERATED = ("Written by `colonbench suites card {id}` (`colonbench.benchmark.cards`) from the suite registry, its "
             "manifest and its published signature; regenerate it (`make cards`), do not edit it.")


def _sha256(path: Path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def _rel(path: Path) -> str:
    """A project file's path as the repository spells it (``data_manifests/...``, ``benchmark/...``)."""
    path = Path(path).resolve()
    places = ((registry.manifest_dir(), "data_manifests"), (verification.SIGNATURE_DIR, "benchmark/signatures"))
    for base, name in places:
        if path.is_relative_to(base.resolve()):
            return f"{name}/{path.relative_to(base.resolve()).as_posix()}"
    return path.name


def mesh_attribution(names) -> dict:
    """The source and attribution of the real colon meshes ``names``, as ``data_manifests/meshes/README.md`` keeps it.

    Returns
    -------
    dict
        ``sources``: {mesh name: the atlas model it is, e.g. ``EdinGCA_3D_00060``}; ``lines``: the README's
        sentences naming the source collection, the data paper, the licence and the attribution rule (the HuBMAP
        sentence only where a HuBMAP mesh is used); ``license``: the SPDX id.

    Raises
    ------
    ValueError
        The README no longer says one of these things the way this reads it (the cards would drift).
    """
    text = (registry.manifest_dir() / "meshes" / "README.md").read_text()
    sources = {}
    for name in names:
        row = re.search(rf"^\| `{re.escape(name)}_large_intestine_mm\.ply`[^|]*\| (\S+)", text, re.M)
        if row is None:
            raise ValueError(f"data_manifests/meshes/README.md has no row of {name}")
        sources[name] = row.group(1)
    para = re.search(r"^Source: .*?(?:\n\n|\Z)", text, re.M | re.S)
    if para is None:
        raise ValueError("data_manifests/meshes/README.md has no 'Source:' paragraph")
    sentences = re.split(r"(?<=[.)])\s+(?=[A-Z])", " ".join(para.group(0).split()))
    hubmap = any(s.startswith("HuBMAP") for s in sources.values())
    keep = [sentences[0].split(";")[0].rstrip(".") + "."]
    keep += [s for s in sentences[1:] if "et al." in s or s.startswith(("License:", "Keep "))
             or (hubmap and s.startswith("HuBMAP"))]
    if not any("et al." in s for s in keep) or not any("CC BY 4.0" in s for s in keep):
        raise ValueError("data_manifests/meshes/README.md's 'Source:' paragraph names no data paper or no CC BY 4.0")
    return {"sources": sources, "lines": keep, "license": "CC-BY-4.0"}


def facts(suite) -> dict:
    """Everything a suite's card says, gathered from the project's records.

    Parameters
    ----------
    suite : str or Suite
        Id or name (:func:`colonbench.benchmark.suites.get`).

    Raises
    ------
    InputError
        No such suite, or no published signature of it.
    """
    suite = registry.get(suite)
    manifest_file = registry.manifest_path(suite)
    manifest = yaml.safe_load(manifest_file.read_text())
    split = manifest["splits"][suite.split]
    meshes = {n: manifest["meshes"][n] for n in split.get("meshes", [])}
    published = registry.published_signature(suite)
    samples = published["samples"]
    first, count = split["colons"]["first"], split["colons"]["count"]
    coverage = np.array([s["coverage"] for s in samples])
    inputs = np.array([s["points"]["input@0"]["n"] for s in samples])
    return {
        "suite": suite, "manifest": manifest, "manifest_file": manifest_file, "split": split,
        "noiseless": set(map(float, split["noise_mm"])) == {0.0},
        "procedural": list(range(first, first + count)), "meshes": meshes,
        "attribution": mesh_attribution(meshes) if meshes else None,
        "published": published, "signature_file": verification.SIGNATURE_DIR / f"{suite.id}.json.gz",
        "hole_models": Counter(s["hole_model"] for s in samples),
        "lengths": Counter(s["length_mm"] for s in samples) if suite.task != "colon" else Counter(),
        "coverage": {"min": coverage.min(), "median": float(np.median(coverage)), "mean": coverage.mean(),
                     "max": coverage.max()},
        "points": {"min": int(inputs.min()), "median": int(np.median(inputs)), "max": int(inputs.max())},
    }


def _fields(suite) -> list:
    """The stored fields a sample exposes, in the schema's words."""
    if suite.task == "colon":
        return list(schema.COLON_FIELDS)
    by_path = {f.path: f for f in schema.FIELDS}
    return [by_path[p] for p in SEGMENT_RECORD]


def _shape(f) -> str:
    dims = [{"rows": "N" if f.group == "samples" else "M", "flat": "total"}.get(s, str(s)) for s in f.shape]
    return "(" + ", ".join(dims) + ("," if len(dims) == 1 else "") + ")"


def _field_text(f, noiseless: bool) -> str:
    """A field's meaning, unit and storage, from its schema entry; where the suite's data are stored noiseless
    (its manifest's noise 0: the benchmark adds each noise level when it scores), its points and their noise say
    so, as the card's metrics sentence does."""
    doc = "; ".join(x for x in f.doc.split("; ") if "train and validation" not in x)   # suites are test splits
    if noiseless and f.name == "noise_mm":
        doc += "; 0 in this suite's data: its noise levels are added when it is scored, not stored"
    elif noiseless:
        doc = doc.replace("noise included", "stored noiseless (the benchmark adds each noise level when it scores)")
    unit = "" if f.unit == "-" else f"; unit {f.unit}"
    frame = "" if f.frame in ("-", "") else f", frame: {f.frame}"
    where = f"stored at `{f.path}` {_shape(f)} {f.dtype}"
    if f.ragged:
        where += f", ragged: row i is `{f.name}[o[i]:o[i+1]]` with o = `{f.path}_offsets`"
    if f.group == "segments":
        where += "; a sample's row is `samples/segment`"
    elif f.group == "colon":
        where += "; one per shard (colon), shared by its samples"
    return f"{doc}{unit}{frame} ({where})"


def _licence_rows(f: dict) -> list[str]:
    out = ["- **Code, manifests and this card**: MIT (`LICENSE`). The data are made by that code on your machine "
           "from the manifest"]
    if not f["meshes"]:
        out[0] += "; this suite holds no third-party data."
        return out
    att = f["attribution"]
    names = ", ".join(f"`{n}` ({att['sources'][n]})" for n in f["meshes"])
    out[0] += "."
    out += [f"- **Real colons**: {names}, from `data_manifests/meshes/` (see its README). Their surfaces and "
            "midlines, and the samples cut from them, are [CC BY 4.0](https://creativecommons.org/licenses/by/4.0/) "
            "data; keep this attribution with any copy:", ""]
    out += ["  > " + " ".join(att["lines"])]
    return out


def card(suite) -> str:
    """A suite's dataset card, Markdown.

    Parameters
    ----------
    suite : str or Suite
        Id or name.
    """
    f = facts(suite)
    s, man, split, pub = f["suite"], f["manifest"], f["split"], f["published"]
    colon = s.task == "colon"
    unit = "whole-colon reconstructions" if colon else "segments"
    noise = ", ".join(f"{n:g}" for n in s.noise_mm)
    mfile = _rel(f["manifest_file"])
    out = [f"# {s.id}: dataset card", "", f"<!-- {GENERATED.format(id=s.id)} -->", "",
           "| | |", "|---|---|",
           f"| suite | `{s.id}` (name `{s.name}`, version {s.version}) |",
           f"| cite as | `{s.citation}` |",
           f"| samples | {s.samples} {unit} of the `{s.split}` split"
           + (f" ({s.limit} spread evenly over it)" if s.limit else "") + f", each at input noise {noise} mm |",
           f"| manifest | `{mfile}` (`{man['name']}`, generator {man['generator_version']}, seed {man['seed']}) |",
           "| licence | MIT (code)" + (f"; CC BY 4.0 (real colons {', '.join(f['meshes'])})" if f["meshes"] else "")
           + " |",
           f"| signature | `{s.signature}` |", f"| content hash | `{s.sha256}` |", "",
           "## What it tests", "", s.tests[0].upper() + s.tests[1:] + ".", "",
           "Metrics: " + "; ".join(s.metrics) + f". Each sample is scored at Gaussian input noise {noise} mm "
           f"(noise seed {s.noise_seed}), added by the benchmark to the stored "
           + ("noiseless points." if f["noiseless"] else "points.")
           + (f" Tracks: context margins {', '.join(f'{c:g}' for c in s.contexts_mm)} mm, {s.segment_mm:g} mm "
              "segments." if colon else ""), "",
           "## How it is made", "", " ".join(man["description"].split()), ""]
    colons = []
    if f["procedural"]:
        p = f["procedural"]
        colons.append(f"{len(p)} procedural colons ({p[0]}-{p[-1]}, indices under the manifest's seed)")
    if f["meshes"]:
        colons.append(", ".join(f"the real CT colon `{n}`" for n in f["meshes"]))
    out.append(f"- Colons: {' and '.join(colons)}.")
    seg = man["config"]["segments"]
    if colon:
        whole = man["config"].get("whole", {})
        out.append(f"- Whole partial reconstructions: {split['permutations']} per colon, "
                   f"{whole.get('point_density', seg['point_density']):g} points/mm^2.")
    else:
        per, perm = split.get("segments_per_length"), split["permutations"]
        lo, hi = seg.get("point_density_scale", (1.0, 1.0))
        out.append(f"- Segments: {', '.join(f'{x:g}' for x in seg['lengths_mm'])} mm long, "
                   + ("every segment along each colon" if per is None else f"{per} per length per colon, spread "
                      "evenly") + f"; {perm} hole permutation{'s' if perm > 1 else ''} each; {seg['point_density']:g} "
                   + ("" if lo == hi == 1 else f"x {lo:g}-{hi:g} ") + "points/mm^2, GT hole points "
                   f"{seg['hole_point_density']:g}/mm^2, GT centerline every {seg['centerline_spacing_mm']:g} mm.")
    shares = ", ".join(f"`{k}` {v:g}" for k, v in split["hole_models"].items())
    out += [f"- Hole models (manifest shares): {shares}.", "",
            "The data are made again on your machine from the manifest (never downloaded"
            + (f", unless fetched from its archive {s.archive_url}" if s.archive_url else "") + ") and checked "
            "sample by sample against the published signature:", "", "```bash",
            f"colonbench benchmark --suites {s.id} --methods constant --out runs/{s.id}   # generates it where missing",
            f"colonbench generate {mfile} --out data/{man['name']} --splits {s.split} --workers 2",
            "colonbench suites --check                  # the cached suites against their signatures", "```", "",
            f"Generating it takes about {s.generate_seconds:.0f} s with `--workers 2` on the project's 2-core "
            "machine.", "", "## What a sample holds", ""]
    if colon:
        out += ["A sample of this suite is **not a segment**: it is one *whole* partial reconstruction of a colon "
                "(its points and the withdrawal trajectory), scored against the exact *per-face* truth of the "
                "colon's complete surface (which faces were observed). A method sees the segments `colonbench "
                "map` cuts from the noisy reconstruction ([docs/mapping.md](../mapping.md)); each segment is "
                "scored against the true coverage of the same stretch of the true surface.", ""]
    else:
        out += ["One partial reconstruction of a colon segment: the method's input is the partial point cloud "
                "(mm, noise added at the suite's levels); the truth is the coverage (observed share of the "
                "complete segment surface, a fraction in [0, 1]), points on the unobserved surface and the "
                "centerline.", ""]
    out += ["| field | meaning |", "|---|---|"]
    out += [f"| `{x.name}` | {_field_text(x, f['noiseless'])} |" for x in _fields(s)]
    cov, pts = f["coverage"], f["points"]
    out += ["", "Contracts: [docs/formats.md](../formats.md) (estimate JSON, export folder); every stored field: "
            "[docs/shards.md](../shards.md#shard-format-version-2). All geometry is in millimetres.", "",
            f"Its Croissant metadata, [{s.id}.croissant.json]({s.id}.croissant.json), holds one record per sample "
            "(record set `samples`: its shard and row, hole model, " + ("" if colon else "length, ")
            + "true coverage and input points, from the published signature), which Croissant tools read from it "
            "alone; the arrays above are in the HDF5 shards (record set `arrays`), which they do not read: "
            f"`{_reader(s)}` does.", "",
            "From the published signature: " + ", ".join(f"{n} `{k}`" for k, n in sorted(f["hole_models"].items()))
            + (" samples; by length " + ", ".join(f"{n} of {k:g} mm" for k, n in sorted(f["lengths"].items()))
               if f["lengths"] else " samples")
            + f"; true coverage {cov['min']:.3f} to {cov['max']:.3f} (median {cov['median']:.3f}, mean "
            f"{cov['mean']:.3f}); {pts['median']} input points at the median ({pts['min']} to {pts['max']}).", "",
            "## Licence and attribution", ""] + _licence_rows(f)
    out += ["", "## How to cite", "", f"Cite the suite by its id and its signature's digest, as `colonbench suites` "
            f"prints it: **`{s.citation}`**, and colonbench (version {man['generator_version']} of its generator)."]
    if f["meshes"]:
        paper = next(x for x in f["attribution"]["lines"] if "et al." in x)
        out[-1] += f" Its real colons: {paper}"
    out += ["", "## Signature", "",
            f"`{_rel(f['signature_file'])}` (sha256 `{_sha256(f['signature_file'])}`), digest `{s.signature}` "
            f"(format {pub['version']}): per sample its id, hole model, length, truth, point counts and sketches "
            "of every point set. It also fixes the resolved manifest (sha256 "
            f"`{pub['manifest_sha256']}`), the generator configuration (`{pub['config_sha256']}`), the noise "
            f"({', '.join(f'{n:g}' for n in pub['noise_mm'])} mm, seed {pub['noise_seed']}) and the tolerances "
            "within which data made on another machine still verify:", "",
            "| tolerance | value |", "|---|---|"] + [f"| `{k}` | {v:g} |" for k, v in sorted(pub["tolerances"].items())]
    out += ["", f"Data bit-identical to the published ones have the content hash `{s.sha256}`; "
            "[docs/benchmark.md](../benchmark.md#verified-suites) says how a suite verifies."]
    return "\n".join(out) + "\n"


def _file_object(id_, path: Path, fmt: str, description: str, sha256: str | None = None) -> dict:
    return {"@type": "cr:FileObject", "@id": id_, "name": id_, "description": description, "contentUrl": _rel(path),
            "encodingFormat": fmt, "sha256": sha256 or _sha256(path)}


def croissant(suite) -> dict:
    """A suite's Croissant 1.0 metadata, a JSON-LD dict.

    Its record set ``samples`` lists every sample of the suite (shard and row, hole model, length, true coverage,
    input points, from the published signature) in the JSON-LD itself, so that Croissant tools
    (``mlcroissant.Dataset(jsonld).records("samples")``) yield one record per sample without the data; ``arrays``
    describes the fields of the HDF5 shards, which those tools do not read.

    Parameters
    ----------
    suite : str or Suite
        Id or name.
    """
    f = facts(suite)
    s, man = f["suite"], f["manifest"]
    dist = [_file_object("manifest", f["manifest_file"], "application/yaml",
                         "the manifest the suite's data are generated from (colonbench generate)"),
            _file_object("signature", f["signature_file"], "application/gzip",
                         f"the published signature ({s.signature}): per-sample truth and sketches, tolerances")]
    for name, m in f["meshes"].items():
        base = registry.manifest_dir()
        dist += [_file_object(f"mesh-{name}", base / m["mesh"], "application/x-ply",
                              f"the real colon {name}'s surface, mm (CC BY 4.0)", m["mesh_sha256"]),
                 _file_object(f"midline-{name}", base / m["centerline"], "application/x-npy",
                              f"the real colon {name}'s midline, (n, 3) float64 mm (CC BY 4.0)",
                              m["centerline_sha256"])]
    shards = {"@type": "cr:FileSet", "@id": "shards", "name": "shards", "encodingFormat": "application/x-hdf5",
              "includes": f"{s.split}/*.h5",
              "description": f"the suite's HDF5 shards ({'whole-colon, ' if s.task == 'colon' else ''}format "
                             f"{schema.COLON_FORMAT_VERSION if s.task == 'colon' else schema.FORMAT_VERSION}), made "
                             f"by `colonbench generate` into the suite's data folder ({s.id}/ under the suite cache); "
                             "they are checked against the signature, not by their bytes' sha256"}
    if s.archive_url:
        dist.append({"@type": "cr:FileObject", "@id": "archive", "name": "archive", "contentUrl": s.archive_url,
                     "encodingFormat": "application/x-tar", "sha256": s.archive_sha256,
                     "description": "a frozen archive of the suite's scored data (colonbench suites fetch)"})
        shards["containedIn"] = {"@id": "archive"}
    dist.append(shards)
    fields = [{"@type": "cr:Field", "@id": f"arrays/{x.name}", "name": x.name,
               "description": _field_text(x, f["noiseless"]),
               "dataType": "sc:Float" if x.dtype.startswith("float") else "sc:Integer",
               "source": {"fileSet": {"@id": "shards"}, "extract": {"column": x.path}}} for x in _fields(s)]
    what = ("one whole partial reconstruction of a colon, scored on exact per-face truth" if s.task == "colon"
            else "one partial colon segment and its exact truth")
    columns, rows = _sample_records(f)
    licenses = [LICENSES["MIT"]] + ([LICENSES[f["attribution"]["license"]]] if f["meshes"] else [])
    cite = f"{s.citation}; colonbench, generator {man['generator_version']}"
    if f["meshes"]:
        cite += "; " + next(x for x in f["attribution"]["lines"] if "et al." in x)
    return {
        "@context": CROISSANT_CONTEXT, "@type": "sc:Dataset", "conformsTo": CROISSANT_CONFORMS_TO,
        "name": s.id,
        "description": f"colonbench suite {s.id}: {s.tests}. {s.samples} "
                       f"{'whole-colon reconstructions' if s.task == 'colon' else 'segments'} of the {s.split} split "
                       f"of {_rel(f['manifest_file'])}, scored at input noise "
                       f"{', '.join(f'{n:g}' for n in s.noise_mm)} mm. Cite as {s.citation}. File paths are those "
                       "of the colonbench repository. The record set samples lists every sample; arrays describes "
                       "what its shards hold. Card: docs/suites/" + f"{s.id}.md.",
        "license": licenses if len(licenses) > 1 else licenses[0],
        "citeAs": cite, "version": f"{s.version}.0.0", "isLiveDataset": False,
        "keywords": ["colonoscopy", "coverage estimation", "point clouds", "3D reconstruction", "benchmark"],
        "distribution": dist,
        "recordSet": [
            {"@type": "cr:RecordSet", "@id": "samples", "name": "samples",
             "description": f"one record per sample of the suite ({what}), from its published signature: where it "
                            "lies in the suite's data and its truth", "field": columns, "data": rows},
            {"@type": "cr:RecordSet", "@id": "arrays", "name": "arrays",
             "description": f"what the HDF5 shards hold per sample ({what}), at row `index` of shard `shard` of its "
                            "record in samples; Croissant tools such as mlcroissant read no HDF5 (this record set "
                            f"yields nothing there): read them with {_reader(s)}", "field": fields}],
    }


def _reader(suite) -> str:
    return ("colonbench.shards.colonshard.ColonShard(path).sample(index)" if suite.task == "colon"
            else "colonbench.shards.reader.Shard(path).geometry(index)")


def _located(sample: str) -> tuple[str, int]:
    """The shard (its path in the suite's data folder) and row of a signature's sample id: the benchmark's id of
    it at noise 0, ``<split>_<shard stem>_<index>_noise0`` (:func:`colonbench.benchmark.exchange.sample_id`)."""
    m = re.fullmatch(r"([^_/]+)_(.+)_(\d+)_noise0", sample)
    if m is None:
        raise ValueError(f"the signature's sample id {sample!r} is not <split>_<shard stem>_<index>_noise0")
    return f"{m.group(1)}/{m.group(2)}.h5", int(m.group(3))


def _sample_records(f: dict) -> tuple[list, list]:
    """The Croissant record set ``samples``: its fields and its data, one record per sample of the published
    signature (the suite's samples, in its order), which Croissant tools read from the JSON-LD itself."""
    colon = f["suite"].task == "colon"
    spec = [("shard", "sc:Text", "the HDF5 shard holding the sample: a path in the suite's data folder (<suite id>/ "
             "under the suite cache)"),
            ("index", "sc:Integer", "the sample's row in that shard; the benchmark names it <split>_<shard stem>_"
             "<index, 3 digits>_noise<sigma> at each noise level"),
            ("hole_model", "sc:Text", "how its holes were made (the hole model's name)")]
    if not colon:
        spec.append(("length_mm", "sc:Float", "the segment's length along the colon's centerline, mm"))
    spec += [("coverage", "sc:Float", "true coverage: observed area / complete area of the "
              + ("whole colon" if colon else "segment") + ", a fraction in [0, 1]"),
             ("input_points", "sc:Integer", "points of its stored partial cloud, the method's input (before the "
              "noise the benchmark adds)")]
    fields = [{"@type": "cr:Field", "@id": f"samples/{name}", "name": name, "description": doc, "dataType": kind}
              for name, kind, doc in spec]
    rows = []
    for x in f["published"]["samples"]:
        shard, index = _located(x["sample"])
        value = {"shard": shard, "index": index, "hole_model": x["hole_model"], "length_mm": x["length_mm"],
                 "coverage": x["coverage"], "input_points": x["points"]["input@0"]["n"]}
        rows.append({f"samples/{name}": value[name] for name, _, _ in spec})
    return fields, rows


def write(suite, out) -> tuple[Path, Path]:
    """Write a suite's card and Croissant metadata: ``out/<id>.md`` and ``out/<id>.croissant.json``.

    Returns
    -------
    (Path, Path)
        The card and the JSON-LD file.
    """
    suite = registry.get(suite)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    md, js = out / f"{suite.id}.md", out / f"{suite.id}.croissant.json"
    md.write_text(card(suite))
    js.write_text(json.dumps(croissant(suite), indent=1, ensure_ascii=False) + "\n")
    return md, js
