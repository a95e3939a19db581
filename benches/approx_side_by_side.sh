#!/bin/bash
# Wall time of two `foldfree` binaries on the slowest approximation runs of the acceptance set,
# measured side by side: the binaries alternate on each run, REPS times, so a slower or faster
# spell of the machine falls on both. Prints each run's seconds per binary and their medians.
# The VM's timing noise is ±20 % between sweeps; a ratio is only worth quoting from here.
#
#   bash benches/approx_side_by_side.sh A_BIN B_BIN [REPS=3]
#
# Nothing else may run meanwhile (no build, no sweep).
set -euo pipefail
a=$1
b=$2
reps=${3:-3}
here=$(cd "$(dirname "$0")/.." && pwd)
meshes=${MESHES:-$here/../shared/meshes}
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
median() { printf '%s\n' "$@" | sort -g | awk '{v[NR] = $1} END {print v[int((NR + 1) / 2)]}'; }
for run in sweep/closed/cgal_cow:60 sweep/cad/oded_sword:100 sweep/cad/cgal_fandisk_large:100 \
    sweep/cad/oded_hammer:100 sweep/cad/cgal_blade:100 cad/block:100; do
    mesh=$meshes/${run%:*}.obj
    k=${run#*:}
    ta=()
    tb=()
    for _ in $(seq "$reps"); do
        for side in a b; do
            bin=$a
            [ "$side" = b ] && bin=$b
            /usr/bin/time -o "$out/t" -f %e "$bin" approx "$mesh" -o "$out/$side.obj" -k "$k" -q \
                >/dev/null 2>&1 || true
            if [ "$side" = a ]; then ta+=("$(cat "$out/t")"); else tb+=("$(cat "$out/t")"); fi
        done
    done
    same=identical
    cmp -s "$out/a.obj" "$out/b.obj" || same=different
    echo "${run%:*} K$k  A ${ta[*]} (median $(median "${ta[@]}"))  B ${tb[*]} (median $(median "${tb[@]}"))  outputs $same"
done
