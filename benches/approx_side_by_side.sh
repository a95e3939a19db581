#!/bin/bash
# Wall time of two `foldfree` binaries on approximation runs of the acceptance set, measured
# side by side: the binaries alternate on each run, REPS times, so a slower or faster spell of
# the machine falls on both. Prints each run's seconds per binary, their medians, and the median
# of the runs' ratios. The VM's timing noise is ±20 % between sweeps; a ratio is only worth
# quoting from here.
#
#   bash benches/approx_side_by_side.sh A_BIN B_BIN [REPS=3]
#   RUNS="sweep/closed/cgal_cow:60 cad/block:100" bash benches/approx_side_by_side.sh A B
#
# The default runs: the slowest (sword, hammer, fandisk_large K100) and eight near the sweep's
# median time/VSA (0.3–4 s), where the median the time criterion is judged by is decided and
# fixed costs weigh more than on the slowest runs. Nothing else may run meanwhile (no build, no
# sweep).
set -euo pipefail
a=$1
b=$2
reps=${3:-3}
here=$(cd "$(dirname "$0")/.." && pwd)
meshes=${MESHES:-$here/../shared/meshes}
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
median() { printf '%s\n' "$@" | sort -g | awk '{v[NR] = $1} END {print v[int((NR + 1) / 2)]}'; }
runs=${RUNS:-sweep/closed/cgal_cow:60 sweep/cad/oded_sword:100 sweep/cad/cgal_fandisk_large:100 \
    sweep/cad/oded_hammer:100 sweep/cad/cgal_blade:100 cad/block:100 closed/bunny_npm:100 \
    sweep/closed/cgal_homer:60 sweep/cad/cgal_handle:60 sweep/closed/oded_goathead:24 \
    cad/rocker_arm:100}
ratios=()
for run in $runs; do
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
    ma=$(median "${ta[@]}")
    mb=$(median "${tb[@]}")
    ratios+=("$(awk -v a="$ma" -v b="$mb" 'BEGIN {printf "%.3f", b / a}')")
    echo "${run%:*} K$k  A ${ta[*]} (median $ma)  B ${tb[*]} (median $mb)  B/A ${ratios[-1]}  outputs $same"
done
echo "median B/A over the runs: $(median "${ratios[@]}")"
