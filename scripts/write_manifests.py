"""Write the shipped manifests (data_manifests/*.yaml) with every generator parameter spelled out.

Run after a change of the generator's defaults or version; the result is
committed. ``tests/test_manifests.py`` checks that the committed files are
complete and valid.
"""

from pathlib import Path

from colonbench._version import __version__
from colonbench.datagen.generate import GeneratorConfig
from colonbench.shards.manifest import dumps, resolve
from colonbench.shards.schema import sha256_file

OUT = Path(__file__).resolve().parents[1] / "data_manifests"


def split(first, count, per_length, permutations, noise, mix=None, meshes=None):
    out = {"colons": {"first": first, "count": count}, "segments_per_length": per_length,
           "permutations": permutations, "hole_models": dict(mix or {"camera": 0.5, "spheres": 0.5}),
           "noise_mm": dict(noise)}
    if meshes:
        out["meshes"] = list(meshes)
    return out


#: The real colons the project carries (data_manifests/meshes/, CC BY 4.0, see its README), by manifest name.
REAL = {name: {"id": 900000 + int(name[3:]), "mesh": f"meshes/{name}_large_intestine_mm.ply",
               "centerline": f"meshes/{name}_path_mm.npy"} for name in ("gca00090", "gca00080", "gca00060", "gca00020",
                                                                                  "gca00070")}


def meshes(*names):
    out = {}
    for n in names:
        m = REAL[n]
        out[n] = {"id": m["id"], "mesh": m["mesh"], "mesh_sha256": sha256_file(OUT / m["mesh"]),
                  "centerline": m["centerline"], "centerline_sha256": sha256_file(OUT / m["centerline"])}
    return out


def dump(name, description, seed, splits, overrides=None, axes="pca", mesh_names=(), task="segments"):
    grid = {"size": 64, "margin": 4, "min_extent_mm": 70.0}
    if axes != "pca":
        grid["axes"] = axes
    manifest = {"name": name, "description": description, "generator_version": __version__, "seed": seed,
                **({"task": task} if task != "segments" else {}), "grid": grid, "config": GeneratorConfig.from_dict(overrides or {}).to_dict(), "splits": splits}
    if mesh_names:
        manifest["meshes"] = meshes(*mesh_names)
    manifest["config"] = resolve(manifest, name)["config"]  # with the video section where a split uses it
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

# ------------------------------------------------------------------ 0.2: generalization (issue 11)
#: The widened generator: each range answers a failure seen on colons we did not make (docs/datagen.md).
WIDE = {
    "colon": {"length_mm": [1300.0, 2000.0], "radius_caecum_mm": [25.0, 40.0], "radius_transverse_mm": [18.0, 38.0],
              "radius_sigmoid_mm": [10.0, 25.0], "radius_rectum_mm": [15.0, 35.0], "fold_spacing_mm": [10.0, 50.0],
              "fold_depth": [0.0, 0.5], "fold_width_mm": [1.5, 6.0], "fold_free_share": 0.15,
              "ellipticity": [0.0, 0.3], "flattening": [0.0, 0.3], "roughness_mm": [0.0, 0.6], "max_attempts": 200,
              "diverticula": [0, 4], "pedunculated_polyps": [0, 2]},
    "segments": {"lengths_mm": [40.0, 55.0, 70.0], "point_density_scale": [0.25, 4.0], "density_falloff": [0.0, 2.0],
                 "outlier_share": [0.0, 0.03], "double_layer_share": [0.0, 0.3]},
}
WIDE_HOLES = {"camera": 0.3, "spheres": 0.3, "camera+spheres": 0.1, "camera+end": 0.15, "spheres+end": 0.15}
WIDE_NOISE = {0.0: 0.4, 0.25: 0.15, 0.5: 0.2, 0.75: 0.1, 1.0: 0.15}
dump("wide", "The widened generator (0.2): radii 10-40 mm, segments of 40-70 mm (as short as their diameter), folds "
     "from none to deep pockets, smooth colons, elliptic and flattened sections, clouds of 0.5-8 points/mm^2 thinning "
     "away from the camera, outliers, a misregistered second layer, noise up to 1 mm, an unseen end, diverticula and "
     "pedunculated polyps. Its test split "
     "is the widened suite of the benchmark.", 20261122,
     {"train": split(0, 200, 10, 3, WIDE_NOISE, WIDE_HOLES), "validation": split(200, 20, 4, 2, WIDE_NOISE, WIDE_HOLES),
      "test": split(220, 12, 4, 1, CLEAN, WIDE_HOLES)}, WIDE, axes="tube")
dump("real-test", "The real held-out suite: every usable segment of the real CT colon gca00060, which no shipped model "
     "is trained on, with camera and sphere holes at 2 points/mm^2 (the paper's protocol on a colon we did not make).",
     20261123, {"test": split(0, 0, None, 2, CLEAN, {"camera": 0.5, "spheres": 0.5}, meshes=["gca00060"])},
     {"segments": {"lengths_mm": [50.0, 60.0, 70.0], "end_margin_mm": 10.0}}, axes="tube", mesh_names=["gca00060"])
dump("train-wide", "Training data of the 0.2 model: 24 colons of the widened generator and the real colons gca00090 "
     "and gca00080, validated on 8 other widened colons. wide.yaml's and real-test.yaml's test "
     "colons are never seen. Sized for a fine-tune on a 2-core CPU; grow the colon count on a GPU.", 20261122,
     {"train": split(0, 24, 6, 2, WIDE_NOISE, WIDE_HOLES, meshes=["gca00090", "gca00080"]),
      "validation": split(200, 8, 4, 1, WIDE_NOISE, WIDE_HOLES)}, WIDE, axes="tube",
     mesh_names=["gca00090", "gca00080"])

dump("train-real", "Every segment of the real training colons gca00090 and gca00080 (40, 55 and 70 mm, two hole "
     "permutations each, the widened suite's hole models and noise), as the kink-free importer cuts them: trained "
     "together with train-wide.yaml (colonbench train data/train-wide data/train-real), it gives the real colons "
     "a sixth of the samples instead of a thirteenth. Validated on 4 widened colons that no other manifest "
     "trains on; real-test.yaml's colon gca00060 is never seen.", 20261125,
     {"train": split(0, 0, None, 2, WIDE_NOISE, WIDE_HOLES, meshes=["gca00090", "gca00080"]),
      "validation": split(212, 4, 2, 1, WIDE_NOISE, WIDE_HOLES)}, WIDE, axes="tube",
     mesh_names=["gca00090", "gca00080"])

#: Tortuous colons (after 0.3): real colons' 40-70 mm segments turn 2-3 times as much as the widened generator's
#: (end to end, median 52 against 24 degrees; docs/datagen.md, Tortuosity), and the network errs more on bent
#: segments. Narrower lumens (the real training colons' wall lies 11-14 mm from their line) and no diverticula
#: (whose reach widens every bend the curvature limit allows) let the random bending through.
BENDS = {"colon": {**WIDE["colon"], "radius_caecum_mm": [15.0, 35.0], "radius_transverse_mm": [10.0, 30.0],
                   "radius_sigmoid_mm": [8.0, 20.0], "radius_rectum_mm": [12.0, 30.0], "diverticula": [0, 0],
                   "tortuosity_mm": [10.0, 30.0], "tortuosity_scale_mm": [12.0, 25.0]},
         "segments": WIDE["segments"]}
dump("bends", "Tortuous colons for training: the widened generator with the centerline bent at random (tortuosity "
     "10-30 mm over 12-25 mm of arc), narrower lumens (8-35 mm) and no diverticula, so that its 40-70 mm segments "
     "turn as much as the real colons' do (end to end, median 45 degrees; real 52, wide.yaml 24). Train and "
     "validation splits only; trained together with wide.yaml and train-real.yaml.", 20261126,
     {"train": split(0, 100, 6, 2, WIDE_NOISE, WIDE_HOLES), "validation": split(100, 10, 4, 1, WIDE_NOISE, WIDE_HOLES)},
     BENDS, axes="tube")

# ------------------------------------------------------------------ 0.3: reconstruction-like partials (issue 13)
#: The same segments of paper.yaml's test colons, as ideal visibility (camera) and as a fused, degraded video.
for name, mix, what in (("video", {"video": 1.0}, "reconstruction-like partials: a rendered withdrawal per segment, "
                         "its depth degraded (noise, edge smoothing, scale drift), its poses drifting, frames lost, "
                         "fused by TSDF (the video hole model, docs/video.md)"),
                        ("video-camera", {"camera": 1.0}, "ideal per-face visibility from camera poses, the paper's "
                         "camera holes, for the side-by-side comparison with video.yaml")):
    dump(name, f"The video suite: the segments of 6 of paper.yaml's test colons (2 per length per colon), with {what}.",
         20210901, {"test": split(440, 6, 2, 1, CLEAN, mix)})
dump("train-video", "Video partials for training (the video hole model on the widened generator and the real training "
     "colons): 16 widened colons that train-wide.yaml does not use, gca00090 and gca00080, validated on 4 other "
     "widened colons. Trained together with train-wide.yaml (colonbench train data/train-wide data/train-video); "
     "wide.yaml's, real-test.yaml's and video.yaml's test colons are never seen.", 20261124,
     {"train": split(24, 16, 3, 1, WIDE_NOISE, {"video": 1.0}, meshes=["gca00090", "gca00080"]),
      "validation": split(208, 4, 2, 1, WIDE_NOISE, {"video": 1.0})}, WIDE, axes="tube",
     mesh_names=["gca00090", "gca00080"])

# ------------------------------------------------------------------ interval calibration (issue 52)
#: Where the completion method's coverage intervals are calibrated (scripts/calibrate_intervals.py): widened colons
#: under a seed of their own (no manifest trains on them), with a tenth video partials, and the real training colons
#: (seen in training: their errors are optimistic). No suite's colons are used.
dump("calibration", "Calibration of the completion method's coverage intervals (scripts/calibrate_intervals.py): "
     "24 widened colons under this manifest's own seed, which no manifest trains on, with the widened hole models "
     "and a tenth video partials, and the real training colons gca00090 and gca00080. Validation split only; no "
     "suite's colons.", 20261128,
     {"validation": split(0, 24, 3, 2, WIDE_NOISE, {**{k: round(0.9 * v, 4) for k, v in WIDE_HOLES.items()}, "video": 0.1},
                          meshes=["gca00090", "gca00080"])}, WIDE, axes="tube", mesh_names=["gca00090", "gca00080"])
#: The real colons' share of the calibration raised to about 43 % of its segments (decision 0147): the intervals are
#: for users' own colons, and the method under-estimates real colons more often than generated ones.
dump("calibration-real", "Real segments of the interval calibration (scripts/calibrate_intervals.py, with "
     "calibration.yaml): the real training colons gca00090 and gca00080 under this manifest's own seed, 24 segments "
     "per length and colon (as many as it has) with 3 hole draws, calibration.yaml's hole models and noise. Validation split only; the "
     "windows are those train-real.yaml trains on (other holes and noise), never a suite's colon.", 20261129,
     {"validation": split(0, 0, 24, 3, WIDE_NOISE, {**{k: round(0.9 * v, 4) for k, v in WIDE_HOLES.items()},
                                                    "video": 0.1}, meshes=["gca00090", "gca00080"])},
     WIDE, axes="tube", mesh_names=["gca00090", "gca00080"])

#: Colons like the paper's in the interval calibration (issue 70, decision 0325): unseen colons the network's own
#: generator makes, so that the intervals are as sure as they should be where the method is at home.
dump("calibration-paper", "Paper-like colons of the interval calibration (scripts/calibrate_intervals.py): 24 of "
     "paper.yaml's validation colons (no manifest trains on them; not train-cpu.yaml's), one segment per length, two "
     "hole draws, the paper's camera and sphere holes and a fifth video partials. Validation split only.", 20210901,
     {"validation": split(400, 24, 1, 2, CLEAN, {"camera": 0.4, "spheres": 0.4, "video": 0.2})})
#: More of them, made as paper-v1 is (decision 0170, after 0169's probe): the calibration's paper-like colons
#: without video partials, so that it sees how sure the method is on the paper's own protocol.
dump("calibration-paper-more", "More paper-like colons of the interval calibration (scripts/calibrate_intervals.py, "
     "with calibration-paper.yaml): paper.yaml's validation colons 424-439 (no manifest trains on them), three "
     "segments per length, two hole draws, the paper's camera and sphere holes half each, as paper-v1. Validation "
     "split only.", 20210901, {"validation": split(424, 16, 3, 2, CLEAN)})

#: The real validation and calibration colons (issues 63 and 70): gca00020 and gca00070, which no manifest trains on
#: and no suite is made of. Every choice of model, step or calibration is judged on data that includes them.
dump("validation-real", "The real validation and calibration colons gca00020 (CT with the colon inflated) and gca00070 "
     "(Visible Human male, a coarse mesh): every usable "
     "segment of 40, 50, 55, 60 and 70 mm (the suites' lengths), two hole draws each, with the suites' hole models "
     "(camera, spheres, both, an unseen end, video partials) at 2 points/mm^2 as real-test.yaml's; evaluated at 0 and "
     "0.5 mm noise as the suites are. Validation split only: choose and calibrate on them, never train or test on them.",
     20261130, {"validation": split(0, 0, None, 2, CLEAN, {"camera": 0.25, "spheres": 0.25, "camera+spheres": 0.1,
                                                          "camera+end": 0.125, "spheres+end": 0.125, "video": 0.15},
                                    meshes=["gca00020", "gca00070"])},
     {"segments": {"lengths_mm": [40.0, 50.0, 55.0, 60.0, 70.0], "end_margin_mm": 10.0}}, axes="tube",
     mesh_names=["gca00020", "gca00070"])

# ------------------------------------------------------------------ screening set-up (issue 71, decision 0326)
#: Small training sets for screening recipes at 32^3 (colonbench train --pool 2), beside train-wide.yaml (the base):
#: paper-like colons (the recipe of the 0.1 model's data), and two changes aimed at the colons the network misses.
dump("screen-paper", "Screening: the paper's generator alone (the recipe of the 0.1 model's data), sized as "
     "train-wide.yaml: 24 of paper.yaml's train colons, 6 segments per length, 2 hole draws; validated on 8 of its "
     "validation colons (not calibration-paper.yaml's).", 20210901,
     {"train": split(0, 24, 6, 2, NOISY), "validation": split(340, 8, 4, 1, NOISY)}, axes="tube")
HAUSTRA = {**WIDE, "colon": {**WIDE["colon"], "radius_caecum_mm": [35.0, 50.0], "radius_transverse_mm": [30.0, 45.0],
                             "radius_sigmoid_mm": [20.0, 32.0], "radius_rectum_mm": [28.0, 40.0],
                             "fold_spacing_mm": [15.0, 40.0], "fold_depth": [0.35, 0.6], "fold_free_share": 0.0,
                             "taenia_depth": [0.1, 0.25], "taenia_depth_transverse": [0.2, 0.35]}}
dump("screen-haustra", "Screening candidate: wide lumens (radii 20-50 mm) with deep haustral pockets between the "
     "taeniae (folds 0.35-0.6 of the radius deep, taeniae 0.1-0.35), the widened generator otherwise: 12 colons, 6 segments per "
     "length, 2 hole draws, trained beside train-wide.yaml; validated on 4 others.", 20261201,
     {"train": split(0, 12, 6, 2, WIDE_NOISE, WIDE_HOLES), "validation": split(100, 4, 2, 1, WIDE_NOISE, WIDE_HOLES)},
     HAUSTRA, axes="tube")
LOWCOV = {**WIDE, "camera": {"poses": [2, 6]}, "spheres": {"spheres": [3, 8], "radius_mm": [8.0, 22.0]}}
dump("screen-lowcov", "Screening candidate: low coverage, where the estimate's bias is largest (camera holes of 2-6 "
     "poses, 3-8 sphere holes of 8-22 mm), the widened generator otherwise: 12 colons, 6 segments per length, 2 hole "
     "draws, trained beside train-wide.yaml; validated on 4 others.", 20261202,
     {"train": split(0, 12, 6, 2, WIDE_NOISE, WIDE_HOLES), "validation": split(100, 4, 2, 1, WIDE_NOISE, WIDE_HOLES)},
     LOWCOV, axes="tube")

# ------------------------------------------------------------------ whole-colon benchmark (issue 12)
def whole_colons(first, count, permutations, meshes):
    """A split of whole-colon reconstructions (task: colon): no segments, camera and sphere holes half and half."""
    out = split(first, count, None, permutations, CLEAN, {"camera": 0.5, "spheres": 0.5}, meshes=meshes)
    del out["segments_per_length"]
    return out


dump("colon-test", "The whole-colon benchmark (colonbench evaluate --task colon): two whole partial reconstructions "
     "(withdrawal-camera or sphere holes, 2 points/mm^2, each with its withdrawal trajectory) of each of 4 of "
     "paper.yaml's test colons and of the real held-out colon gca00060, with their exact per-face truth.",
     20210901, {"test": whole_colons(440, 4, 2, ["gca00060"])}, mesh_names=["gca00060"], task="colon")

#: Whole-colon validation: where the map's own settings (its context margin) are chosen, never on colon-test.yaml.
dump("colon-val", "Whole-colon validation, where the map's settings are chosen (colonbench evaluate --task colon "
     "--split validation): two whole partial reconstructions (withdrawal-camera or sphere holes, 2 points/mm^2) of "
     "each of 4 of paper.yaml's validation colons and of the real training colons gca00090 and gca00080 (their "
     "segments are in train-real.yaml, so the network's figures on them are optimistic; colon-test.yaml's colons "
     "are never used).",
     20261123, {"validation": whole_colons(340, 4, 2, ["gca00090", "gca00080"])},
     mesh_names=["gca00090", "gca00080"], task="colon")

#: The real validation colon mapped whole (issue 63): where the map's figures on a real colon are judged and its
#: segments' intervals calibrated, never colon-test.yaml's gca00060.
dump("colon-val-real", "Whole-colon validation on the real validation colons gca00020 and gca00070 (colonbench evaluate "
     "--task colon --split validation): two whole partial reconstructions of each (withdrawal-camera or sphere holes, "
     "2 points/mm^2, each with its withdrawal trajectory), with their exact per-face truth. No manifest trains on them.",
     20261130, {"validation": whole_colons(0, 0, 2, ["gca00020", "gca00070"])}, mesh_names=["gca00020", "gca00070"],
     task="colon")

#: More maps of the real validation colons (decision record 0224): colon-val-real.yaml's two maps of each hold too few
#: far-off segments to choose the map's review on.
dump("colon-val-real-more", "More whole-colon validation on the real validation colons gca00020 and gca00070, beside "
     "colon-val-real.yaml (its seed differs): four whole partial reconstructions of each (withdrawal-camera or sphere "
     "holes, 2 points/mm^2, each with its withdrawal trajectory), with their exact per-face truth. No manifest trains "
     "on them.",
     20261201, {"validation": whole_colons(0, 0, 4, ["gca00020", "gca00070"])}, mesh_names=["gca00020", "gca00070"],
     task="colon")

#: Whole-colon training data of the context model (issue 12): its context samples are cut from these
#: reconstructions (colonbench pack --context): paper.yaml's train colons and the real colon gca00090, and
#: colons of the widened generator; gca00080 stays out for colon-val.yaml to judge on.
dump("colon-train", "Whole-colon training data for the in-context model (colonbench pack DATA --context, then "
     "colonbench train, with colon-train-wide.yaml): three whole partial reconstructions (withdrawal-camera or "
     "sphere holes, 2 points/mm^2) of each of 20 of paper.yaml's train colons and of the real training colon "
     "gca00090, validated on 2 of paper.yaml's validation colons that colon-val.yaml does not use. The real colon "
     "gca00080 is left out so that colon-val.yaml can judge the in-context model on a real colon it did not learn "
     "from; colon-val.yaml's and colon-test.yaml's colons are never trained on.",
     20261126, {"train": whole_colons(0, 20, 3, ["gca00090"]),
                "validation": whole_colons(346, 2, 1, None)},
     mesh_names=["gca00090"], task="colon")
dump("colon-train-wide", "Whole-colon training data for the in-context model from the widened generator (trained "
     "together with colon-train.yaml): two whole partial reconstructions (withdrawal-camera or sphere holes, "
     "2 points/mm^2) of each of 24 widened colons (wide.yaml's ranges under this manifest's own seed), validated on "
     "2 others.",
     20261127, {"train": whole_colons(0, 24, 2, None), "validation": whole_colons(24, 2, 1, None)},
     WIDE, task="colon")
