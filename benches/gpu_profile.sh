#!/usr/bin/env bash
# Where the ADMM iteration's time goes on whatever Vulkan device this machine has: per-kernel
# timestamps, bytes moved per kernel, achieved bandwidth against the device's streaming rate
# (saxpy), dispatch + submission overhead per iteration, and `foldfree param` end to end on the
# Vulkan and CPU backends. One Markdown table per mesh, ready to paste into BENCHMARKS.md.
#
#   bash benches/gpu_profile.sh --ci          # small: tests/data/camel_open.obj, 50 iterations
#   bash benches/gpu_profile.sh               # full: igea_open_249k + one corpus disk, 200 its
#   bash benches/gpu_profile.sh MESH.obj ...  # your meshes (disk topology), 200 iterations
#
# Pick the device with FOLDFREE_DEVICE=<name substring or index>. Nothing else may run on the
# machine while it measures.
set -euo pipefail
cd "$(dirname "$0")/.."
iters=200
if [[ "${1:-}" == "--ci" ]]; then
    shift
    iters=50
    meshes=(tests/data/camel_open.obj)
elif [[ $# -gt 0 ]]; then
    meshes=("$@")
else
    meshes=(../shared/meshes/disk/igea_open_249k.obj ../shared/meshes/sweep/disk/$(ls ../shared/meshes/sweep/disk | grep -m1 '\.obj$'))
fi
cargo build --release --locked --quiet
echo "# foldfree gpu profile — $(date -u +%Y-%m-%d), $(git rev-parse --short HEAD 2>/dev/null || echo unknown)"
echo
target/release/foldfree dev bench --profile --max-iters "$iters" --out-dir target/gpu-profile "${meshes[@]}"
