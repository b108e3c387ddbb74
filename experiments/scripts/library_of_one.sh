#!/usr/bin/env bash
# A single clip through the motion library's code path (issue 19) against the build before it,
# bit for bit, in one device call: one short training run of walk (the older build: a newer checkpoint stores config keys the older build does not know), then its
# checkpoint's evaluation replayed by both builds on the deterministic physics
# (ptx/deterministic, whose replays are exact), twice each. The recordings (every env's qpos and
# body poses every control step, and the reference rows the kernels looked up) and `eval --json`
# are compared byte for byte: before vs before and after vs after show the replays are
# repeatable, before vs after that the library of one rolls out what the single clip did.
#   here:  tests/device/stage.sh; build the older binary and xz it into DIR/instantmimic.xz
#   there: BEFORE=DIR BIN=.device-bin experiments/scripts/library_of_one.sh
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
# Recordings are compared by content: their JSON header (tensor names, shapes, offsets and the
# metadata) parsed, and the tensor bytes after it. The header's metadata keys come out in a
# process-dependent order (safetensors serializes a hash map), so the files' bytes may differ
# where nothing recorded does (first device run, 2026-11-26: after vs after "DIFFER" by bytes).
same() {
  if python3 - "$1" "$2" <<'PY'; then echo identical; else echo DIFFER; fi
import json, struct, sys
def parts(path):
    data = open(path, "rb").read()
    if not path.endswith(".safetensors"):
        return data
    n = struct.unpack("<Q", data[:8])[0]
    return json.loads(data[8:8 + n]), data[8 + n:]
sys.exit(0 if parts(sys.argv[1]) == parts(sys.argv[2]) else 1)
PY
}
{
  for what in safetensors eval.json; do
    echo "$what: before vs before $(same "$dir/before_1.$what" "$dir/before_2.$what"), after vs after $(same "$dir/after_1.$what" "$dir/after_2.$what"), before vs after $(same "$dir/before_1.$what" "$dir/after_1.$what")"
  done
} | tee "$dir/library_of_one.txt"
