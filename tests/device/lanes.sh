#!/usr/bin/env bash
# One device call, one lane per GPU: LANE0, LANE1, ... are shell snippets, each run in the
# background on its GPU ($GPU inside the snippet), with these helpers:
#   train NAME WALL_S ARGS...      instantmimic train --out $OUT/runs/NAME --overwrite ARGS
#   train_before NAME WALL_S ARGS...  the same with the older build in $BEFORE/instantmimic.xz
#   resume NAME FROM WALL_S ARGS...  copies the run directory FROM (carried from an earlier
#                                  call) to $OUT/runs/NAME and continues it (train --resume)
#   gpu_test NAME...               the staged GPU test binaries, one after another
#   bench NAME WALL_S ARGS...      instantmimic bench ARGS > $OUT/runs/NAME.log (its last lines
#                                  go to the summary)
#   bench_before NAME WALL_S ARGS...  the same with the older build in $BEFORE/instantmimic.xz
#   library_eval NAME CHECKPOINT LIBRARY   eval --library LIBRARY --out $OUT/runs/NAME.tsv
#   newest_checkpoint NAME         the newest checkpoint of $OUT/runs/NAME
#   wait_for FILE_GLOB SECONDS     waits until another lane has written it
# FIRST: a command run before the lanes, with every GPU free (e.g. gpu_multi_gpu).
# Nothing starts later than SESSION_S (default 530) seconds after the start and no run is
# allowed past it: `train` gets `timeout` at the deadline, whose SIGTERM makes it stop after
# the current iteration with a checkpoint (exit 143), so the run can be resumed in the next
# call. Each line of $OUT/summary.txt is one finished step; the summary is printed last.
# REPLAY=1: the runs write their replay pages (default: --no-replay).
# KEEP: the runs whose directories (with their newest checkpoint), xz-packed, come back as
# run_NAME.txz (a file must stay under 16 MiB: a library run's metrics.jsonl alone passes 10 MB
# in 15 minutes). A plan file given as the argument is sourced first; it may set all of the above.
#   tests/device/stage.sh; then there:
#   BIN=.device-bin LANE1='train tracker 520 --config configs/train/library_all.toml' tests/device/lanes.sh
#   BIN=.device-bin tests/device/lanes.sh experiments/plans/NAME.sh
set -uo pipefail
if [ -n "${1:-}" ]; then
  [ -f "$1" ] || { echo "lanes.sh: no plan file $1" >&2; exit 2; }
  # shellcheck disable=SC1090
  . "$1"
fi
cd "$(dirname "$0")/../.."
. tests/device/common.sh
export BIN NCCL_NVLS_ENABLE=${NCCL_NVLS_ENABLE:-0}
LD_LIBRARY_PATH=$(toolkit_libs)
export LD_LIBRARY_PATH
# Runs write no replay pages unless REPLAY=1: a library's are 20-30 MB, over what a kept run
# may bring back.
replay_flag=--no-replay
[ "${REPLAY:-0}" = 1 ] && replay_flag=
start=$(date +%s)
deadline=$(( start + ${SESSION_S:-530} ))
summary="$OUT/summary.txt"
: > "$summary"
mkdir -p "$OUT/runs"
nvidia-smi --query-gpu=index,name,driver_version --format=csv,noheader > "$OUT/gpu.txt"
note() { echo "[$(( $(date +%s) - start ))s GPU ${GPU:-all}] $*" | tee -a "$summary"; }
left() { echo $(( deadline - $(date +%s) )); }

# run_bounded WALL_S LOG CMD...: CMD on this lane's GPU, stopped by SIGTERM at WALL_S or at the
# deadline (with 15 s to write its checkpoint), whichever comes first.
run_bounded() {
  local wall=$1 log=$2; shift 2
  local l; l=$(left)
  [ "$wall" -gt "$l" ] && wall=$l
  CUDA_VISIBLE_DEVICES=$GPU timeout -k 15 "$wall" "$@" > "$log" 2>&1
}
report_run() {
  local name=$1 rc=$2 t0=$3 log="$OUT/runs/$1.log"
  note "$name (rc $rc, wall $(( $(date +%s) - t0 )) s): $(grep -E 'stopped after|^error|received' "$log" | tail -1)"
  note "    last: $(grep -E '^iteration|^eval' "$log" | tail -1)"
}
# The older build of $BEFORE, unpacked once (common.sh's unpack_before), for before/after
# comparisons on the same GPU.
unpack_before_once() { [ -x "$(binary before)" ] || unpack_before; }
# train_with BINARY NAME WALL_S ARGS...: `train` with that build.
train_with() {
  local exe=$1 name=$2 wall=$3; shift 3
  if [ "$(left)" -lt 40 ]; then note "$name: skipped (session time)"; return; fi
  local t0; t0=$(date +%s)
  run_bounded "$wall" "$OUT/runs/$name.log" "$exe" train --out "$OUT/runs/$name" --overwrite \
    --progress lines $replay_flag "$@"
  report_run "$name" $? "$t0"
}
train() { train_with "$BIN/instantmimic" "$@"; }
# train_before NAME WALL_S ARGS...: `train` with the older build of $BEFORE, for time to
# success before and after on the same GPU.
train_before() { unpack_before_once; train_with "$(binary before)" "$@"; }
resume() {
  local name=$1 from=$2 wall=$3; shift 3
  if [ ! -d "$from" ]; then note "$name: no run directory $from to resume"; return; fi
  if [ "$(left)" -lt 40 ]; then note "$name: skipped (session time)"; return; fi
  rm -rf "$OUT/runs/$name"; cp -r "$from" "$OUT/runs/$name"; chmod -R u+w "$OUT/runs/$name"
  local t0; t0=$(date +%s)
  run_bounded "$wall" "$OUT/runs/$name.log" "$BIN/instantmimic" train --resume "$OUT/runs/$name" \
    --progress lines $replay_flag "$@"
  report_run "$name" $? "$t0"
}
gpu_test() {
  local t
  for t in "$@"; do
    [ -x "$BIN/$t" ] || { note "test $t: not staged"; continue; }
    if [ "$(left)" -lt 40 ]; then note "test $t: skipped (session time)"; continue; fi
    local t0 s; t0=$(date +%s)
    if INSTANTMIMIC_NO_SKIP=1 INSTANTMIMIC_BIN=$BIN/instantmimic run_bounded "${TEST_TIMEOUT:-300}" \
        "$OUT/test_$t.log" "$BIN/$t" --nocapture --test-threads 1; then s=PASS; else s=FAIL; fi
    note "test $t $s $(( $(date +%s) - t0 )) s $(grep -o 'test result: .*; [0-9]* ignored' "$OUT/test_$t.log" | tail -1)"
    [ "$s" = FAIL ] && grep -E "panicked|FAILED|^error" "$OUT/test_$t.log" | head -4 | tee -a "$summary"
  done
}
bench_with() {
  local binary=$1 name=$2 wall=$3; shift 3
  if [ "$(left)" -lt 40 ]; then note "$name: skipped (session time)"; return; fi
  local t0; t0=$(date +%s)
  run_bounded "$wall" "$OUT/runs/$name.log" "$binary" bench "$@"
  note "$name (rc $?, $(( $(date +%s) - t0 )) s): bench $*"
  tail -n 22 "$OUT/runs/$name.log" | sed 's/^/    /' | tee -a "$summary" > /dev/null
}
bench() { bench_with "$BIN/instantmimic" "$@"; }
# bench_before NAME WALL_S ARGS...: `bench` with the older build of $BEFORE (common.sh's
# unpack_before), for a before/after comparison on the same warm GPU.
bench_before() { unpack_before_once; bench_with "$(binary before)" "$@"; }
newest_checkpoint() { ls "$OUT/runs/$1"/checkpoints/*.safetensors 2>/dev/null | sort | tail -1; }
library_eval() {
  local name=$1 checkpoint=$2 library=$3
  if [ -z "$checkpoint" ]; then note "$name: no checkpoint"; return; fi
  if [ "$(left)" -lt 20 ]; then note "$name: skipped (session time)"; return; fi
  local t0; t0=$(date +%s)
  run_bounded 200 "$OUT/runs/$name.log" "$BIN/instantmimic" eval --checkpoint "$checkpoint" \
    --library "$library" --out "$OUT/runs/$name.tsv"
  note "$name (rc $?, $(( $(date +%s) - t0 )) s): $(tail -2 "$OUT/runs/$name.log" | tr '\n' ' ')"
}
wait_for() {
  local until=$(( $(date +%s) + $2 ))
  while [ "$(date +%s)" -lt "$until" ] && [ "$(left)" -gt 40 ]; do
    compgen -G "$1" > /dev/null && return 0
    sleep 5
  done
  compgen -G "$1" > /dev/null
}
export -f nccl_libs toolkit_libs
export OUT

if [ -n "${FIRST:-}" ]; then
  GPU=all bash -c "$FIRST" > "$OUT/first.log" 2>&1
  note "first (rc $?): $(tail -3 "$OUT/first.log" | tr '\n' ' ')"
fi
for i in 0 1 2 3 4 5 6 7; do
  var=LANE$i
  [ -n "${!var:-}" ] || continue
  ( GPU=$i; eval "${!var}" ) &
done
wait
# Keep the newest checkpoint of each run (to resume or to teach).
for d in "$OUT"/runs/*/checkpoints; do
  ls "$d"/*.safetensors 2>/dev/null | sort | head -n -1 | xargs -r rm -f
done
note "all done in $(( $(date +%s) - start )) s"
# What comes back is at most 8 files, 2 folders down: summary.txt, logs.txz (every log and run
# directory without its checkpoints) and run_NAME.txz for each run named in KEEP (the run
# directory with its newest checkpoint, xz-packed, to resume or to teach in the next call; at
# most 6).
# xz on every core: the device machine has 16-128, and packing four library runs on one took
# about 40 s of the call's 600.
export XZ_OPT=${XZ_OPT:--T0}
tar cJf "$OUT/logs.txz" -C "$OUT" --exclude='*.safetensors' --exclude=logs.txz \
  $(cd "$OUT" && ls | grep -v -e '^summary.txt$' -e '^logs.txz$')
kept=0
for name in ${KEEP:-}; do
  if [ ! -d "$OUT/runs/$name" ]; then note "keep $name: no such run"; continue; fi
  if [ "$kept" -ge 6 ]; then note "keep $name: more than 6 runs to keep, left out"; continue; fi
  tar cJf "$OUT/run_$name.txz" -C "$OUT/runs" "$name" && kept=$((kept + 1))
  size=$(stat -c %s "$OUT/run_$name.txz")
  [ "$size" -lt $((16 << 20)) ] || note "keep $name: run_$name.txz is $size bytes, over the 16 MiB a file may bring back"
done
find "$OUT" -mindepth 1 -maxdepth 1 ! -name summary.txt ! -name logs.txz ! -name 'run_*.txz' -exec rm -rf {} +
ls -la "$OUT"
echo "==== summary"; cat "$summary"
