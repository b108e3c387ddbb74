#!/usr/bin/env bash
# Issue 19's measurements in one device call on a machine with 4 GPUs, each GPU one lane:
#   GPU 0: the GPU tests of the library, latent and goal code (TESTS), then
#          library_of_one.sh (when BEFORE names the older build), then the goal task (GOAL_S),
#          then, while time is left, the backflip with TF32 GEMMs for issue 20 (seeds TF32_SEEDS)
#   GPU 1: a library tracker as the teacher (configs/train/library_shipped.toml, TEACHER_S of
#          active time), then the latent controller distilled from its last checkpoint (LATENT_S)
#   GPU 2: the library tracker on configs/train/library_shipped.toml (SHIPPED_S)
#   GPU 3: the library tracker on configs/train/library_all.toml (ALL_S; needs long/ in the
#          staged motions)
# FIRST: a command run before the lanes start, with every GPU free (e.g. a multi-GPU run).
# Every run writes its directory under $OUT/runs (checkpoints but the newest left out) and a
# line to $OUT/summary.txt, printed last.
#   tests/device/stage.sh; then there: BIN=.device-bin [BEFORE=.device-before] tests/device/library_session.sh
set -uo pipefail
cd "$(dirname "$0")/../.."
. tests/device/common.sh
export BIN NCCL_NVLS_ENABLE=${NCCL_NVLS_ENABLE:-0}
LD_LIBRARY_PATH=$(toolkit_libs)
export LD_LIBRARY_PATH
start=$(date +%s)
summary="$OUT/summary.txt"
: > "$summary"
mkdir -p "$OUT/runs"
note() { echo "$*" | tee -a "$summary"; }

# FIRST runs in its own shell: give it the library paths (nccl_libs) and OUT.
export -f nccl_libs toolkit_libs
export OUT
if [ -n "${FIRST:-}" ]; then
  bash -c "$FIRST" > "$OUT/first.log" 2>&1
  note "first (rc $?, $(( $(date +%s) - start )) s): $(tail -3 "$OUT/first.log" | tr '\n' ' ')"
fi

# No run starts later than SESSION_S (default 540) seconds after the start, and none runs past it.
deadline=$(( start + ${SESSION_S:-540} ))
# train GPU NAME WALL_S ARGS...: one run, its last line in the summary.
train() {
  local gpu=$1 name=$2 wall=$3; shift 3
  local t0 left; t0=$(date +%s); left=$(( deadline - t0 ))
  if [ "$left" -lt 30 ]; then note "$name: skipped (session time)"; return; fi
  [ "$wall" -gt "$left" ] && wall=$left
  CUDA_VISIBLE_DEVICES=$gpu timeout "$wall" "$BIN/instantmimic" train --out "$OUT/runs/$name" --overwrite \
    --progress lines "$@" > "$OUT/runs/$name.log" 2>&1
  local rc=$?
  note "$name (GPU $gpu, rc $rc, wall $(( $(date +%s) - t0 )) s): $(grep -E 'stopped after|error' "$OUT/runs/$name.log" | tail -1)"
  note "    last: $(grep '^iteration' "$OUT/runs/$name.log" | tail -1)"
}
newest_checkpoint() { ls "$OUT/runs/$1"/checkpoints/*.safetensors 2>/dev/null | sort | tail -1; }

lane0() {
  local t
  for t in ${TESTS:-gpu_latent gpu_library_eval gpu_goal gpu_env_kernels gpu_rollout gpu_train}; do
    [ -x "$BIN/$t" ] || { note "test $t: not staged"; continue; }
    local t0; t0=$(date +%s)
    if CUDA_VISIBLE_DEVICES=0 INSTANTMIMIC_NO_SKIP=1 INSTANTMIMIC_BIN=$BIN/instantmimic timeout "${TEST_TIMEOUT:-240}" \
        "$BIN/$t" --nocapture --test-threads 1 > "$OUT/test_$t.log" 2>&1; then s=PASS; else s=FAIL; fi
    note "test  $t  $s  $(( $(date +%s) - t0 )) s  $(grep -o 'test result: .*; [0-9]* ignored' "$OUT/test_$t.log" | tail -1)"
    [ "$s" = FAIL ] && grep -E "panicked|FAILED" "$OUT/test_$t.log" | head -4 | tee -a "$summary"
  done
  if [ -n "${BEFORE:-}" ]; then
    CUDA_VISIBLE_DEVICES=0 OUT="$OUT/library_of_one" timeout 200 tests/device/library_of_one.sh > "$OUT/library_of_one.txt" 2>&1
    note "library_of_one: $(tail -2 "$OUT/library_of_one.txt" | tr '\n' ' ')"
  fi
  train 0 goal_reach $(( ${GOAL_S:-60} * 3 + 60 )) --config configs/goal/reach.toml --time-budget "${GOAL_S:-60}"
  local seed
  for seed in ${TF32_SEEDS:-0 1 2}; do
    train 0 backflip_tf32_$seed 120 --motion backflip --seed "$seed" --time-budget 40 --no-replay --set policy.gemm=cublas_tf32
  done
}
lane1() {
  train 1 teacher $(( ${TEACHER_S:-150} * 3 / 2 + 40 )) --config configs/train/library_shipped.toml --time-budget "${TEACHER_S:-150}" --set run.stop_on_success=false
  local teacher; teacher=$(newest_checkpoint teacher)
  if [ -z "$teacher" ]; then note "latent: no teacher checkpoint"; return; fi
  train 1 latent $(( ${LATENT_S:-150} * 3 / 2 + 40 )) --config configs/latent/library.toml --teacher "$teacher" --time-budget "${LATENT_S:-150}"
}

lane0 & lane1 &
train 2 library_shipped $(( ${SHIPPED_S:-400} * 5 / 4 + 30 )) --config configs/train/library_shipped.toml --time-budget "${SHIPPED_S:-400}" &
train 3 library_all $(( ${ALL_S:-320} * 8 / 5 + 30 )) --config configs/train/library_all.toml --time-budget "${ALL_S:-320}" &
wait
# Keep the newest checkpoint of each run (to resume or to teach), and its tables.
for d in "$OUT"/runs/*/checkpoints; do
  ls "$d"/*.safetensors 2>/dev/null | sort | head -n -1 | xargs -r rm -f
done
note "all done in $(( $(date +%s) - start )) s"
echo "==== summary"; cat "$summary"
