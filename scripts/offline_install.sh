# Sourced by scripts/train_offline.sh and scripts/train_crossfit.sh on a machine that has PyTorch but no package
# registry: installs colonbench from this clone (and the wheels in $parts/wheels, e.g. monai and edt, those for
# this Python) into $SITE unless it imports already, and joins each pack's split train.h5.part-* pieces.
# It then works from the temporary folder: in the clone's root `python3 -m colonbench.cli` would import the
# clone's colonbench/ folder, not the installed package ($parts and $run are made absolute first).
site=${SITE:-/tmp/colonbench-site}
here=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
parts=$(cd "$parts" && pwd)
mkdir -p "$run"; run=$(cd "$run" && pwd)
cd "${TMPDIR:-/tmp}"
if ! python3 -c "import colonbench.benchmark" 2>/dev/null; then
    py=$(python3 -c "import sys; print(f'cp{sys.version_info[0]}{sys.version_info[1]}')")
    wheels=()
    for w in "$parts"/wheels/*.whl; do
        [ -e "$w" ] || continue
        case "$w" in *-cp3*-cp3*) [[ "$w" == *"-$py-"* ]] || continue ;; esac
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
