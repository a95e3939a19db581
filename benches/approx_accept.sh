#!/bin/sh
# Acceptance runs of `foldfree approx` (issue 5): 4 meshes × K ∈ {24, 60, 100}, REPS runs each,
# median total seconds; prints a Markdown table built from the JSON reports.
# Usage: benches/approx_accept.sh [MESH_DIR] [REPS]   (release binary must be built)
set -eu
MESHES=${1:-../shared/meshes}
REPS=${2:-3}
BIN=${BIN:-target/release/foldfree}
OUT=target/approx-accept
mkdir -p "$OUT"
for m in cad/fandisk cad/block cad/rocker_arm closed/bunny_npm; do
  b=$(basename "$m")
  for k in 24 60 100; do
    r=1
    while [ "$r" -le "$REPS" ]; do
      "$BIN" approx "$MESHES/$m.obj" -k "$k" -q -o "$OUT/$b-$k.obj" \
        --polygons "$OUT/$b-$k-poly.obj" --report "$OUT/$b-$k-$r.json"
      r=$((r + 1))
    done
  done
done
python3 - "$OUT" "$REPS" <<'PY'
import json, statistics, sys
out, reps = sys.argv[1], int(sys.argv[2])
print("| mesh | faces | K | regions | runs (seed kept) | s, all runs (median of %d) | mean dist | rel. to diag | max dist | planarity (rel.) | flipped | degenerate | polygons | corners |" % reps)
print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
for b in ["fandisk", "block", "rocker_arm", "bunny_npm"]:
    for k in [24, 60, 100]:
        rs = [json.load(open("%s/%s-%d-%d.json" % (out, b, k, r))) for r in range(1, reps + 1)]
        r = rs[0]
        t = statistics.median(x["seconds_all_runs"] for x in rs)
        print("| %s.obj | %d | %d | %d | %d (%d) | %.2f | %.5f | %.5f | %.4f | %.1e | %d | %d | %d | %d |" % (
            b, r["faces"], k, r["k_obtained"], r["runs"], r["seed_used"], t, r["mean_input_distance"],
            r["mean_input_distance_rel"], r["max_input_distance"],
            r["max_planarity_deviation_rel"], r["flipped_faces"], r["degenerate_faces"],
            r["polygons"], r["corners"]))
PY
