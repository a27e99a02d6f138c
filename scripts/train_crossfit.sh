#!/usr/bin/env bash
# The two cross-fitted calibration models of decision 0152 on one GPU: each trained from the 0.1 model (the last
# trained on no real colon) on the widened colons and one real colon, so that it has never seen the other, whose
# calibration segments it then estimates (scripts/calibrate_intervals.py --crossfit).
#
#   scripts/train_crossfit.sh PARTS_DIR RUN_DIR MINUTES [DEVICE]
#
# PARTS_DIR holds the packs and the starting weights, as made here by
#   colonbench generate data_manifests/crossfit-wide.yaml --out data/crossfit-wide --workers 2   # and the two
#   colonbench generate data_manifests/crossfit-real-gca00090.yaml ...                            # real manifests
#   colonbench pack data/crossfit-wide --out PARTS_DIR/wide      # 25 MiB; real-gca00090, real-gca00080 the same
#   git show 880e995:completion/models/small-0.1.safetensors > PARTS_DIR/small-0.1.safetensors
# and, where monai or edt is missing, their wheels in PARTS_DIR/wheels (docs/training.md).
# Both folds train at once on the GPU, MINUTES each, with scripts/train_offline.sh's settings (the real colon 4 times
# per epoch, flips, transposes 0.3, erasure 0.3, every epoch kept); each fold's model is then the uniform mean of the
# second half of its epochs, batch norm recomputed (colonbench average), as the shipped model is a mean of
# checkpoints: RUN_DIR/crossfit-without-gca00080.safetensors and RUN_DIR/crossfit-without-gca00090.safetensors.
set -euo pipefail
shopt -s nullglob
parts=${1:?PARTS_DIR}; run=${2:?RUN_DIR}; minutes=${3:?MINUTES}; device=${4:-cuda}
source "$(dirname "$0")/offline_install.sh"

train() {  # train KEPT LEFT_OUT: on the widened colons and KEPT; the model has never seen LEFT_OUT
    python3 -m colonbench.cli train "$parts/wide" "$parts/real-$1" --out "$run/without-$2" --network small \
        --init "$parts/small-0.1.safetensors" --repeat 1,4 --lr 5e-4 --batch-size 32 --augment-prob 0 --flips \
        --transposes 0.3 --erase 0.3 --epochs 60 --max-minutes "$minutes" --checkpoint-minutes 2 --keep-epochs \
        --device "$device" --quiet
}
average() {  # average KEPT LEFT_OUT: the mean of the second half of the fold's epochs
    local epochs=("$run/without-$2"/epoch-*.safetensors)
    local n=${#epochs[@]}
    if [ "$n" -lt 2 ]; then echo "$run/without-$2: $n epochs, too few to average" >&2; return 1; fi
    python3 -m colonbench.cli average "${epochs[@]:$((n / 2))}" --out "$run/crossfit-without-$2.safetensors" \
        --bn-data "$parts/wide" "$parts/real-$1" --repeat 1,4 --seed 36
}
train gca00090 gca00080 > "$run/without-gca00080.log" 2>&1 &
a=$!
train gca00080 gca00090 > "$run/without-gca00090.log" 2>&1 &
b=$!
status=0
wait "$a" || status=1
wait "$b" || status=1
tail -n 1 "$run"/without-*.log
[ "$status" -eq 0 ] || exit 1
# the averages run on the CPU, one after the other: two at once on a 16-core GPU machine had not finished after
# 2.5 minutes; one takes about 2.3 minutes on a 2-core CPU
average gca00090 gca00080
average gca00080 gca00090
