#!/usr/bin/env bash
# Issue 11's training run on a machine that has PyTorch but no package registry (a GPU box reached by
# copying files): install colonbench from this clone, put split packs back together, train, and keep what
# a later `colonbench average` and the validation rule need.
#
#   scripts/train_offline.sh PARTS_DIR RUN_DIR MINUTES [DEVICE]
#
# PARTS_DIR holds the packs to train on (wide, train-real and bends: the tortuous colons of data_manifests/bends.yaml,
# docs/datagen.md, Tortuosity), as made here by
#   colonbench pack data/wide --out packs/wide; colonbench pack data/train-real --out packs/train-real
#   colonbench pack data/bends --out packs/bends
#   mkdir -p PARTS_DIR/wide PARTS_DIR/train-real PARTS_DIR/bends; cp packs/wide/{pack.json,validation.h5} PARTS_DIR/wide/
#   split -b 30M packs/wide/train.h5 PARTS_DIR/wide/train.h5.part-; cp packs/train-real/* PARTS_DIR/train-real/
#   cp packs/bends/* PARTS_DIR/bends/
# and, when monai or edt is missing there, their wheels in PARTS_DIR/wheels (docs/training.md).
# A folder of format-2 shards (colonbench generate) trains the same as its pack, but weighs about 25 times
# more (130 against 5.2 KiB per sample): at 64 MiB per upload, about 500 samples of shards travel against
# about 12 000 packed ones, so the wide + real + bends data (about 22 000 samples) travels as packs.
# Each pack's train.h5.part-* pieces are joined into train.h5; pack.json's sha256 refuses a wrong join.
# Rerun with the same RUN_DIR to resume (colonbench train resumes from RUN_DIR/last.pt); it stops cleanly
# after MINUTES. The run's settings are those of docs/training.md: the shipped small network's
# weights as the start, the real colons 4 times per epoch, flips, transposes (a third of the samples with their
# grid axes exchanged: docs/training.md and docs/decisions/0135-transposes.md) and erasure, every epoch kept.
# A PARTS_DIR without bends/ trains on wide and train-real alone, as planned before bends.yaml.
set -euo pipefail
parts=${1:?PARTS_DIR}; run=${2:?RUN_DIR}; minutes=${3:?MINUTES}; device=${4:-cuda}
# Install when colonbench does not import (with the wheels in PARTS_DIR/wheels built for this Python), and work
# from an empty temporary folder: in the clone's root, python3 -m colonbench.cli would import the clone's
# colonbench/ folder, not the installed package (No module named colonbench.benchmark). PARTS_DIR and RUN_DIR are
# made absolute first.
site=${SITE:-/tmp/colonbench-site}
here=$(cd "$(dirname "$0")/.." && pwd)
parts=$(cd "$parts" && pwd)
mkdir -p "$run"; run=$(cd "$run" && pwd)
cd "$(mktemp -d)"

if ! python3 -c "import colonbench.benchmark" 2>/dev/null; then
    py=$(python3 -c "import sys; print(f'cp{sys.version_info[0]}{sys.version_info[1]}')")
    wheels=()
    for w in "$parts"/wheels/*.whl; do
        [ -e "$w" ] || continue
        n=${w##*/}
        if [[ "$n" == *-cp3*-cp3* && "$n" != *"-$py-"* ]]; then echo "skipping $n (not $py)" >&2; continue; fi
        wheels+=("$w")
    done
    python3 -m pip install -q --no-index --no-deps --no-build-isolation --no-compile --target "$site" \
        "$here" "${wheels[@]}"
    export PYTHONPATH="$site${PYTHONPATH:+:$PYTHONPATH}"
fi

for pack in "$parts"/*/; do
    if [ ! -f "$pack/train.h5" ] && compgen -G "$pack/train.h5.part-*" > /dev/null; then
        cat "$pack"/train.h5.part-* > "$pack/train.h5.tmp" && mv "$pack/train.h5.tmp" "$pack/train.h5"
    fi
done

packs=("$parts/wide" "$parts/train-real"); repeat=1,4
if [ -d "$parts/bends" ]; then packs+=("$parts/bends"); repeat=1,4,1; fi
python3 -m colonbench.cli train "${packs[@]}" --out "$run" --network small --init small \
    --repeat "$repeat" --lr 5e-4 --batch-size 32 --augment-prob 0 --flips --transposes 0.3 --erase 0.3 --epochs 60 \
    --max-minutes "$minutes" --checkpoint-minutes 2 --keep-epochs --device "$device" --quiet
