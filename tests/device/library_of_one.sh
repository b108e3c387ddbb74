#!/usr/bin/env bash
# A single clip through the motion library's code path (issue 19) against the build before it,
# bit for bit, in one device call: one short training run of walk (the older build: a newer checkpoint stores config keys the older build does not know), then its
# checkpoint's evaluation replayed by both builds on the deterministic physics
# (ptx/deterministic, whose replays are exact), twice each. The recordings (every env's qpos and
# body poses every control step, and the reference rows the kernels looked up) and `eval --json`
# are compared byte for byte: before vs before and after vs after show the replays are
# repeatable, before vs after that the library of one rolls out what the single clip did.
#   here:  tests/device/stage.sh; build the older binary and xz it into DIR/instantmimic.xz
#   there: BEFORE=DIR BIN=.device-bin tests/device/library_of_one.sh
# The speed side (frames/s, time to success) is tests/device/before_after.sh.
set -uo pipefail
cd "$(dirname "$0")/../.."
. tests/device/common.sh
unpack_before
LD_LIBRARY_PATH=$(toolkit_libs)
export LD_LIBRARY_PATH
ASSETS=ptx/deterministic
dir="$OUT/library_of_one"
mkdir -p "$dir"

"$(binary before)" train --motion walk --seed 0 --max-iterations 10 --eval-interval 5 --no-replay \
  --assets "$ASSETS" --out "$dir/run" --overwrite --progress lines > "$dir/train.log" 2>&1 \
  || { echo "training failed: $(tail -3 "$dir/train.log")"; exit 1; }
checkpoint=$(ls "$dir"/run/checkpoints/*.safetensors | tail -1)
for build in before after; do
  for round in 1 2; do
    tag="${build}_$round"
    "$(binary "$build")" replay --checkpoint "$checkpoint" --assets "$ASSETS" --episodes 8 \
      --out "$dir/$tag.html" --save-recording "$dir/$tag.safetensors" > "$dir/$tag.replay.log" 2>&1 \
      || echo "replay $tag failed: $(tail -2 "$dir/$tag.replay.log")"
    "$(binary "$build")" eval --checkpoint "$checkpoint" --assets "$ASSETS" --episodes 2 --json \
      > "$dir/$tag.eval.json" 2> "$dir/$tag.eval.log" || echo "eval $tag failed: $(tail -2 "$dir/$tag.eval.log")"
  done
done
same() { if cmp -s "$1" "$2"; then echo identical; else echo DIFFER; fi; }
{
  for what in safetensors eval.json; do
    echo "$what: before vs before $(same "$dir/before_1.$what" "$dir/before_2.$what"), after vs after $(same "$dir/after_1.$what" "$dir/after_2.$what"), before vs after $(same "$dir/before_1.$what" "$dir/after_1.$what")"
  done
} | tee "$dir/library_of_one.txt"
