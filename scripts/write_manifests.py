"""Write the shipped manifests (data_manifests/*.yaml) with every generator parameter spelled out.

Run after a change of the generator's defaults or version; the result is
committed. ``tests/test_manifests.py`` checks that the committed files are
complete and valid.
"""

from pathlib import Path

from colonbench._version import __version__
from colonbench.datagen.generate import GeneratorConfig
from colonbench.shards.manifest import dumps

OUT = Path(__file__).resolve().parents[1] / "data_manifests"


def split(first, count, per_length, permutations, noise, mix=None):
    return {"colons": {"first": first, "count": count}, "segments_per_length": per_length,
            "permutations": permutations, "hole_models": dict(mix or {"camera": 0.5, "spheres": 0.5}),
            "noise_mm": dict(noise)}


def dump(name, description, seed, splits, overrides=None):
    manifest = {"name": name, "description": description, "generator_version": __version__, "seed": seed,
                "grid": {"size": 64, "margin": 4, "min_extent_mm": 70.0}, "config": GeneratorConfig.from_dict(overrides or {}).to_dict(),
                "splits": splits}
    head = (f"# colonbench dataset manifest: {name}\n"
            f"# Generate with: colonbench generate data_manifests/{name}.yaml --out data/{name} --workers N\n"
            "# Written by scripts/write_manifests.py; every generator parameter is spelled out\n"
            "# (docs/datagen.md, docs/shards.md).\n")
    (OUT / f"{name}.yaml").write_text(head + dumps(manifest))


NOISY = {0.0: 0.5, 0.5: 0.5}
CLEAN = {0.0: 1.0}

dump("paper", "The paper's Table 1 protocol: 10200 / 3000 / 1200 segments of 5, 6 and 7 cm cut from disjoint "
     "colons, 15 hole permutations per train and validation segment, camera and sphere holes half and half.",
     20210901, {"train": split(0, 340, 10, 15, NOISY), "validation": split(340, 100, 10, 15, NOISY),
                "test": split(440, 40, 10, 1, CLEAN)})
dump("demo", "A small dataset for the demo, a few minutes on a laptop: 2 train, 1 validation and 2 test colons, "
     "4 segments per length.", 11,
     {"train": split(0, 2, 4, 3, NOISY), "validation": split(2, 1, 4, 3, NOISY), "test": split(3, 2, 4, 1, CLEAN)})
dump("train-cpu", "Training data of the shipped small model, sized for CPU training: 40 train colons (a subset of "
     "paper.yaml's train colons) and 5 validation colons (a subset of its validation colons), so paper.yaml's test "
     "colons stay unseen.", 20210901,
     {"train": split(0, 40, 10, 3, NOISY), "validation": split(340, 5, 4, 2, NOISY)})
dump("train-gpu", "Training data of the shipped model when a GPU trains it: 100 train colons (a subset of paper.yaml's "
     "train colons, holding train-cpu.yaml's) and 10 validation colons (a subset of its validation colons), so "
     "paper.yaml's test colons stay unseen. Sized so that its packed occupancies (colonbench pack) fit one upload "
     "to a GPU machine of about 50 MiB.", 20210901,
     {"train": split(0, 100, 10, 3, NOISY), "validation": split(340, 10, 4, 2, NOISY)})
dump("smoke", "Seconds of data for tests: short coarse colons, one 6 cm segment length, 1-2 segments per colon.", 7,
     {"train": split(0, 1, 2, 2, NOISY), "validation": split(1, 1, 1, 2, CLEAN), "test": split(2, 1, 2, 1, CLEAN)},
     {"colon": {"length_mm": [450, 550], "ring_spacing_mm": 1.0, "edge_mm": 1.5}, "segments": {"lengths_mm": [60.0]}})
