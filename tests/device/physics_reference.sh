#!/usr/bin/env bash
# MuJoCo Warp's own reference states for tests/gpu_physics.rs, made on the GPU machine and
# committed as tests/fixtures/physics_reference/ (so gpu_physics always checks; issue 17). Stage
# the Python first: the warp-lang wheel (150 MB) goes in parts small enough to ride beside the
# working tree under the 64 MiB a call carries (.device-py/qN: four calls, each carrying one part
# and running `bash .device-py/qN/recv.sh`; ../shared/tools/stage-device-python.sh makes 48 MB
# parts, too large beside the tree: re-split so that a part and the tree (33 MB) stay under 64 MiB, e.g. `split -b 30000000`, five parts), then, carrying
# .device-py/small:
#   source .device-py/small/activate.sh && tests/device/physics_reference.sh
# Writes $OUT/reference.tgz: reference/{default,deterministic,g1}_32 (seeded initial states and
# MuJoCo Warp's qpos/qvel after a few step counts, 32 worlds: the committed 32-world plans replay
# them), one archive because a call brings back only so many files.
set -euo pipefail
cd "$(dirname "$0")/../.."
OUT=${OUT:-/tmp/instantmimic-out}
work=$(mktemp -d)
export PYTHONUNBUFFERED=1
nvidia-smi --query-gpu=name,driver_version --format=csv,noheader | tee "$OUT/gpu.txt"
for variant in default deterministic g1; do
  python3 kernels_py/physics_reference.py exact --physics "configs/physics/$variant.toml" \
    --nworld 32 --out "$work/reference/${variant}_32" 2>&1 | grep -v -e '^Module ' -e '^   ' | tail -5
done
du -sh "$work/reference"/*
tar czf "$OUT/reference.tgz" -C "$work" reference
