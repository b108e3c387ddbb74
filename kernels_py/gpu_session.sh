#!/usr/bin/env bash
# Physics plans on a GPU machine: capture, pack, compile and check, then verify and time the Rust
# replay against MuJoCo Warp. Run from the repository root, with warp-lang, mujoco and
# mujoco-warp importable (on the project's lent GPU machine: `source .device-py/small/activate.sh`
# after ../shared/tools/stage-device-python.sh) and the Rust binaries in $BIN:
#   $BIN/instantmimic   cargo build --release
#   $BIN/gpu_physics    cargo test --release --features gpu --no-run (tests/gpu_physics.rs)
#   $BIN/gpu_cuda       (tests/gpu_cuda.rs)
#
#   kernels_py/gpu_session.sh capture   plans for 32, 4096, 16384 worlds -> $WORK/assets (a ptx/
#                                       layout), PTX by compile.py, MuJoCo Warp reference states
#   kernels_py/gpu_session.sh verify    GPU tests against the reference, Warp's own replay timing,
#                                       the Rust replay timing (same warm-up and step counts)
# Logs and a summary go to $OUT (default $WORK/out). The committed plans are the 32- and
# 4096-world ones: copy $WORK/assets/plans/{manifest.json,*_32.*,*_4096.*} and
# $WORK/assets/mjwarp into ptx/ (pack_plans.py --only 32 4096 writes that manifest).
set -euo pipefail
WORK=${WORK:-/tmp/instantmimic-work}
BIN=${BIN:-.device-bin}
OUT=${OUT:-$WORK/out}
STEPS=${STEPS:-1000}
WARMUP=${WARMUP:-200}
mkdir -p "$WORK" "$OUT"
export PYTHONUNBUFFERED=1
# capture, reference and timing share compiled modules; compile.py always starts from nothing.
export INSTANTMIMIC_WARP_CACHE="$WORK/warp-cache"

capture() {
  nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv,noheader | tee "$OUT/gpu.txt"
  local t0=$SECONDS
  python kernels_py/capture.py --nworld 32 4096 16384 --out "$WORK/capture" 2>&1 | grep -v '^Module ' | tee "$OUT/capture.log"
  echo "capture: $((SECONDS - t0)) s"
  t0=$SECONDS
  python kernels_py/pack_plans.py --capture "$WORK/capture" --out "$WORK/assets" --packer "$BIN/instantmimic" --raw 16384 2>&1 | tee "$OUT/pack.log"
  python kernels_py/pack_plans.py --capture "$WORK/capture" --out "$WORK/committed" --packer "$BIN/instantmimic" --only 32 4096 >/dev/null
  echo "pack: $((SECONDS - t0)) s"; ls -la "$WORK/assets/plans" | tee -a "$OUT/pack.log"
  t0=$SECONDS
  python kernels_py/compile.py --manifest "$WORK/assets/plans/manifest.json" --out "$WORK/assets" 2>&1 | grep -v '^Module ' | tail -3 | tee "$OUT/compile.log"
  echo "compile: $((SECONDS - t0)) s"
  cp -r "$WORK/assets/mjwarp" "$WORK/committed/"
  for p in "$WORK"/committed/plans/*.wrp.zst; do "$BIN/instantmimic" plan inspect "$p" > "$OUT/inspect_$(basename "$p" .wrp.zst).txt"; done
  t0=$SECONDS
  python kernels_py/physics_reference.py exact --nworld 4096 --out "$WORK/reference" 2>&1 | grep -v '^Module ' | tee "$OUT/reference.log"
  echo "reference: $((SECONDS - t0)) s"
  tar -C "$WORK/committed" -cf - . | zstd -q -3 -o "$OUT/committed.tar.zst" 2>/dev/null || tar -C "$WORK/committed" -czf "$OUT/committed.tar.gz" .
  ls -la "$OUT"
}

verify() {
  export INSTANTMIMIC_ASSETS="$WORK/assets" INSTANTMIMIC_PHYSICS_REFERENCE="$WORK/reference"
  "$BIN/gpu_physics" --nocapture --test-threads 1 2>&1 | tee "$OUT/gpu_physics.log"
  python kernels_py/physics_reference.py timing --nworld 4096 16384 --steps "$STEPS" --warmup "$WARMUP" --json "$OUT/warp_timing.json" 2>&1 | grep -v '^Module ' | tee "$OUT/warp_timing.log"
  python kernels_py/physics_reference.py timing --shipped-ptx --nworld 4096 16384 --steps "$STEPS" --warmup "$WARMUP" --json "$OUT/warp_timing_shipped.json" 2>&1 | grep -v '^Module ' | tee -a "$OUT/warp_timing.log"
  for run in 1 2; do
    for n in 4096 16384; do
      "$BIN/instantmimic" bench physics --envs "$n" --steps "$STEPS" --warmup "$WARMUP" --assets "$WORK/assets" --json > "$OUT/rust_bench_${n}_$run.json"
      python - "$OUT/rust_bench_${n}_$run.json" <<'PY'
import json, sys
r = json.load(open(sys.argv[1]))
print(f"rust replay: {r['nworld']:6d} worlds: {r['steps_per_s'] / 1e6:.3f} M steps/s "
      f"({r['seconds'] * 1e3 / r['steps']:.3f} ms/step), load {r['load_seconds']:.2f} s, nodes {r['graph_nodes']}")
PY
    done
  done | tee "$OUT/rust_bench.log"
}

case "${1:-}" in
  capture) capture ;;
  verify) verify ;;
  *) echo "usage: $0 capture|verify" >&2; exit 2 ;;
esac
