#!/usr/bin/env bash
# Setup time on a fresh machine (issue 37): `train` runs the backflip for one active second
# with an empty driver JIT cache of its own (CUDA_CACHE_PATH: a new machine, whose first run
# compiles every PTX module) and then again with the cache that run filled (every later run),
# for each binary of BINARIES, the binaries alternating, REPEATS times. Setup is `wall_setup_s`
# of summary.json (the command's start to the first iteration). A table is printed last; logs
# in $OUT/setup_time/.
#   here:  tests/device/stage.sh --train-only (the release binary; an older one beside it)
#   there: BINARIES="before=/tmp/a/instantmimic after=/tmp/b/instantmimic" tests/device/setup_time.sh
# BINARIES: name=path pairs (default: after=$BIN/instantmimic); REPEATS (default 2); MOTION
# (default backflip).
set -uo pipefail
cd "$(dirname "$0")/../.."
. tests/device/common.sh
LD_LIBRARY_PATH=$(toolkit_libs); export LD_LIBRARY_PATH
BINARIES=${BINARIES:-after=$BIN/instantmimic}
REPEATS=${REPEATS:-2}
MOTION=${MOTION:-backflip}
dir=$OUT/setup_time
mkdir -p "$dir"
tsv=$dir/setup.tsv
printf 'binary\tjit_cache\trepeat\tsetup_s\twall_s\n' > "$tsv"
nvidia-smi --query-gpu=name,driver_version --format=csv,noheader > "$dir/gpu.txt"
echo "CPU cores: $(nproc)" >> "$dir/gpu.txt"

one() { # name exe cache(empty|filled) repeat
  local name=$1 exe=$2 cache=$3 repeat=$4 run=$dir/$1_$3_$4 start end setup
  local cache_dir=$dir/cache_${name}_$repeat
  [ "$cache" = empty ] && rm -rf "$cache_dir"
  start=$(date +%s.%N)
  CUDA_CACHE_PATH=$cache_dir timeout 300 "$exe" train --motion "$MOTION" --seed 0 \
    --time-budget 1 --no-replay --out "$run" --overwrite --progress lines > "$run.log" 2>&1
  end=$(date +%s.%N)
  setup=$(python3 -c 'import json,sys; print(round(json.load(open(sys.argv[1]))["wall_setup_s"], 2))' \
    "$run/summary.json" 2>/dev/null || echo NA)
  printf '%s\t%s\t%s\t%s\t%s\n' "$name" "$cache" "$repeat" "$setup" \
    "$(awk -v a="$start" -v b="$end" 'BEGIN { printf "%.2f", b - a }')" >> "$tsv"
}

for repeat in $(seq "$REPEATS"); do
  for cache in empty filled; do
    for pair in $BINARIES; do
      one "${pair%%=*}" "${pair#*=}" "$cache" "$repeat"
    done
  done
done
cat "$dir/gpu.txt"
cat "$tsv"
