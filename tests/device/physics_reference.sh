#!/usr/bin/env bash
# MuJoCo Warp's own reference states for tests/gpu_physics.rs, made on the GPU machine so they can
# be committed as fixtures (then gpu_physics always checks; issue 17). Stage the Python first
# (here: ../shared/tools/stage-device-python.sh .device-py; there: three calls carrying
# .device-py/p0, p1, p2 with `bash .device-py/pN/recv.sh`), then, carrying .device-py/small:
#   source .device-py/small/activate.sh && tests/device/physics_reference.sh
# Writes $OUT/reference/{default,deterministic}_32 (seeded initial states and MuJoCo Warp's
# qpos/qvel after a few step counts, 32 worlds: the committed 32-world plans replay them).
set -euo pipefail
cd "$(dirname "$0")/../.."
OUT=${OUT:-/tmp/instantmimic-out}
export PYTHONUNBUFFERED=1
nvidia-smi --query-gpu=name,driver_version --format=csv,noheader | tee "$OUT/gpu.txt"
for variant in default deterministic; do
  python3 kernels_py/physics_reference.py exact --physics "configs/physics/$variant.toml" \
    --nworld 32 --out "$OUT/reference/${variant}_32" 2>&1 | grep -v -e '^Module ' -e '^   ' | tail -5
done
du -sh "$OUT/reference"/*
