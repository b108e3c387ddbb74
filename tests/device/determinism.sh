#!/usr/bin/env bash
# Deterministic physics on the GPU machine (issue 2, "Exact"; configs/physics/deterministic.toml,
# shipped in ptx/deterministic/). Needs the build-step Python (source .device-py/small/activate.sh,
# see ../shared/tools/stage-device-python.sh) and the staged binaries (tests/device/stage.sh):
#   BIN=.device-bin tests/device/determinism.sh [capture] [reference] [test] [timing] [train]
#     capture    capture the variant's plans and PTX again ($WORK/det; what ptx/deterministic
#                should then hold is packed into $OUT/committed.tgz), and use them below
#     reference  MuJoCo Warp's reference states with the variant, and its run-to-run spread
#     test       gpu_physics: the Rust replay of ASSETS (default ptx/deterministic) against them
#     timing     steps/s at 4096 worlds: Warp's own graph replay and Rust, then the default plans
#     train      two training runs with the same seed on the variant; are their metrics identical?
# Default: reference test timing train. Logs in $OUT.
set -uo pipefail
BIN=${BIN:-.device-bin}
if [ -f "$BIN/bin.txz" ]; then
  mkdir -p /tmp/instantmimic-bin && tar xJf "$BIN/bin.txz" -C /tmp/instantmimic-bin && BIN=/tmp/instantmimic-bin
fi
BIN=$(cd "$BIN" && pwd)
export BIN WORK=${WORK:-/tmp/instantmimic-work} OUT=${OUT:-/tmp/instantmimic-out}
export INSTANTMIMIC_MOTIONS=${INSTANTMIMIC_MOTIONS:-$BIN/motions}
ASSETS=${ASSETS:-ptx/deterministic}
mkdir -p "$OUT"
S=kernels_py/gpu_session.sh
DET=configs/physics/deterministic.toml
steps=("$@")
[ $# -eq 0 ] && steps=(reference test timing train)
for step in "${steps[@]}"; do
  case $step in
    capture)
      bash $S capture det $DET "32 4096" 2>&1 | tee "$OUT/capture.log" | tail -3
      tar czf "$OUT/committed.tgz" -C "$WORK/det" committed
      # Later steps of this call test and time the new capture.
      ASSETS=$WORK/det/assets ;;
    reference)
      bash $S reference det $DET 2>&1 | tee "$OUT/reference.log" | grep "exact reference" ;;
    test)
      INSTANTMIMIC_ASSETS=$ASSETS INSTANTMIMIC_PHYSICS_REFERENCE="$WORK/det/reference" \
        "$BIN/gpu_physics" --nocapture --test-threads 1 2>&1 | tee "$OUT/test.log" | grep -e "contact:" -e "test result" ;;
    timing)
      python kernels_py/physics_reference.py timing --physics $DET --graph-conditional true --nworld 4096 \
        --steps 1000 --warmup 200 2>&1 | grep capture_launch | sed "s/^/[deterministic] /" | tee -a "$OUT/timing.log"
      for assets in "$ASSETS" ptx; do
        "$BIN/instantmimic" bench physics --envs 4096 --steps 1000 --warmup 200 --order dag --assets "$assets" \
          | grep physics: | sed "s|^|[$assets] rust dag |" | tee -a "$OUT/timing.log"
      done ;;
    train)
      for run in a b; do
        timeout 300 "$BIN/instantmimic" train --motion walk --config configs/train/walk.toml --seed 0 \
          --assets "$ASSETS" --out "$WORK/train_$run" --progress quiet > "$OUT/train_$run.log" 2>&1
        echo "train $run: $(tail -1 "$OUT/train_$run.log")"
      done
      cp "$WORK/train_a/metrics.jsonl" "$OUT/metrics_a.jsonl"; cp "$WORK/train_b/metrics.jsonl" "$OUT/metrics_b.jsonl"
      # Wall-clock fields differ by nature; everything else must match.
      python3 - "$WORK/train_a/metrics.jsonl" "$WORK/train_b/metrics.jsonl" <<'PY'
import json, sys
clock = ("time", "elapsed", "wall", "_s", "per_s", "fps")
def strip(v):
    if isinstance(v, dict):
        return {k: strip(x) for k, x in v.items() if not any(c in k for c in clock)}
    return v
def load(p):
    return [strip(json.loads(l)) for l in open(p)]
a, b = load(sys.argv[1]), load(sys.argv[2])
same = sum(x == y for x, y in zip(a, b))
first = next((i for i, (x, y) in enumerate(zip(a, b)) if x != y), None)
print(f"train reproducibility: {len(a)} and {len(b)} records, {same} identical (non-clock fields); first difference at record {first}")
if first is not None:
    x, y = a[first], b[first]
    print("  differing keys:", [k for k in x if x.get(k) != y.get(k)][:8])
PY
      ;;
    *) echo "unknown step $step" >&2; exit 2 ;;
  esac
done
