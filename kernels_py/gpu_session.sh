#!/usr/bin/env bash
# Physics plans on a GPU machine: capture, pack, compile, reference states, GPU tests and timing.
# Run from the repository root with warp-lang, mujoco and mujoco-warp importable (on the
# project's lent GPU machine: `source .device-py/small/activate.sh` after
# ../shared/tools/stage-device-python.sh) and the Rust binaries in $BIN:
#   $BIN/instantmimic          cargo build --release
#   $BIN/gpu_physics, ...      cargo test --release --features gpu --no-run (tests/gpu_*.rs)
#
# Each command works on a variant $WORK/<tag> (a physics config and its plans):
#   capture <tag> <physics.toml> "<nworlds>" ["<raw nworlds>"]
#       plans -> $WORK/<tag>/assets (laid out like ptx/; packed, or raw for the listed world
#       counts), PTX by compile.py, and $WORK/<tag>/committed (32 and 4096 worlds only: what
#       goes into ptx/ when <physics.toml> is the default)
#   reuse <tag> "<raw nworlds>"
#       the repository's committed plans and PTX, plus raw captures for other world counts
#   reference <tag> <physics.toml>   MuJoCo Warp reference states (kernels_py/physics_reference.py)
#   test <tag> <test binary>...      GPU tests against the variant's plans and reference
#   timing <tag> <physics.toml> <nworld> <rust orders...>
#       Warp's own replay (CUBIN), then the Rust replay in each order, same warm-up and steps
# Logs go to $OUT (default $WORK/out).
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
quiet() { grep -v -e '^Module ' -e '^Warp 1\.' -e '^   ' || true; }

capture() {
  local tag=$1 physics=$2 nworlds=$3 raw=${4:-} dir="$WORK/$1"
  nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv,noheader > "$OUT/gpu.txt"
  # shellcheck disable=SC2086
  python kernels_py/capture.py --physics "$physics" --nworld $nworlds --out "$dir/capture" 2>&1 | quiet
  # shellcheck disable=SC2086
  python kernels_py/pack_plans.py --capture "$dir/capture" --out "$dir/assets" --packer "$BIN/instantmimic" --raw $raw
  python kernels_py/compile.py --only mjwarp --manifest "$dir/assets/plans/manifest.json" --out "$dir/assets" 2>&1 | quiet | tail -2
  if [[ " $nworlds " == *" 4096 "* ]]; then
    python kernels_py/pack_plans.py --capture "$dir/capture" --out "$dir/committed" --packer "$BIN/instantmimic" --only 32 4096 >/dev/null
    cp -r "$dir/assets/mjwarp" "$dir/committed/"
  fi
}

reuse() {
  local tag=$1 raw=$2 dir="$WORK/$1"
  mkdir -p "$dir/assets"
  cp -r ptx/plans ptx/mjwarp "$dir/assets/"
  # shellcheck disable=SC2086
  python kernels_py/capture.py --nworld $raw --out "$dir/capture" 2>&1 | quiet
  python - "$dir" <<'PY'
import json, pathlib, shutil, sys
d = pathlib.Path(sys.argv[1])
committed = json.loads((d / "assets/plans/manifest.json").read_text())
new = json.loads((d / "capture/manifest.json").read_text())
for plan in new["plans"]:
    raw = d / "capture" / plan.pop("raw")
    shutil.copyfile(raw, d / "assets/plans" / raw.name)
    plan["file"] = raw.name
    committed["plans"].append(plan)
(d / "assets/plans/manifest.json").write_text(json.dumps(committed, indent=1))
print("reused the committed plans and added", [(p["name"], p["nworld"]) for p in new["plans"]])
PY
}

reference() {
  python kernels_py/physics_reference.py exact --physics "$2" --nworld 4096 --out "$WORK/$1/reference" 2>&1 | quiet
}

test_variant() {
  local tag=$1; shift
  for t in "$@"; do
    INSTANTMIMIC_ASSETS="$WORK/$tag/assets" INSTANTMIMIC_PHYSICS_REFERENCE="$WORK/$tag/reference" \
      "$BIN/$t" --nocapture --test-threads 1 2>&1 | grep -v -e '^running' -e '^$' || echo "FAILED: $t ($tag)"
  done
}

timing() {
  local tag=$1 physics=$2 n=$3; shift 3
  python kernels_py/physics_reference.py timing --physics "$physics" --graph-conditional true --nworld "$n" \
    --steps "$STEPS" --warmup "$WARMUP" --json "$OUT/warp_${tag}_${n}_$(date +%s%N).json" 2>&1 | grep capture_launch | sed "s/^/[$tag] /"
  for order in "$@"; do
    "$BIN/instantmimic" bench physics --envs "$n" --steps "$STEPS" --warmup "$WARMUP" --order "$order" \
      --assets "$WORK/$tag/assets" | grep physics: | sed "s/^/[$tag] rust $order /"
  done
}

cmd=${1:-}; shift || true
case "$cmd" in
  capture) capture "$@" ;;
  reuse) reuse "$@" ;;
  reference) reference "$@" ;;
  test) test_variant "$@" ;;
  timing) timing "$@" ;;
  *) echo "usage: $0 capture|reuse|reference|test|timing ... (see the header)" >&2; exit 2 ;;
esac
