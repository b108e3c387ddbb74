#!/usr/bin/env bash
# A change's effect on speed and learning, before and after, in one device call (issue 17's
# acceptance): `bench rollout` (backflip, 4096 envs, horizon 8) twice per build, then the five
# committed clips' time to success (seed 0, the committed configs built into each binary), the
# two builds alternating so that neither gets the warmer GPU. A table is printed last; logs and
# run directories (checkpoints left out) go under $OUT.
#   here:  tests/device/stage.sh; build the older binary and xz it into DIR/instantmimic.xz
#   there: BEFORE=DIR BIN=.device-bin tests/device/before_after.sh
# SESSION_S (default 540): no new run starts after that many seconds.
set -uo pipefail
cd "$(dirname "$0")/../.."
. tests/device/common.sh
unpack_before
# cuBLAS for the policy's GEMMs (`policy.gemm = "auto"`), as the committed configs measure.
LD_LIBRARY_PATH=$(toolkit_libs)
export LD_LIBRARY_PATH
deadline=$(( $(date +%s) + ${SESSION_S:-540} ))
mkdir -p "$OUT/runs"
rows="$OUT/before_after.tsv"
printf 'what\tbuild\tvalue\tframes_M\n' > "$rows"
time_left() { [ $(( deadline - $(date +%s) )) -gt "$1" ]; }

for round in 1 2; do
  for build in before after; do
    time_left 30 || continue
    json="$OUT/bench_${build}_$round.json"
    if timeout 120 "$(binary "$build")" bench rollout --motion backflip --envs 4096 --substeps 4 --horizon 8 --json \
        > "$json" 2> "$OUT/bench_${build}_$round.err"; then
      python3 - "$json" "$build" >> "$rows" <<'PY'
import json, sys
# MuJoCo Warp's kernels printf their overflow warnings to stdout, before the JSON.
text = open(sys.argv[1]).read()
r = json.loads(text[text.index("\n{") + 1 if not text.startswith("{") else 0:])
print(f"bench rollout M frames/s\t{sys.argv[2]}\t{r['frames_per_s'] / 1e6:.4f}\t")
PY
    else
      echo "bench $build round $round failed: $(tail -2 "$OUT/bench_${build}_$round.err")"
    fi
  done
done

for motion in walk run spinkick cartwheel backflip; do
  for build in before after; do
    time_left 60 || { echo "skipped $motion $build (session time)"; continue; }
    dir="$OUT/runs/${build}_$motion"
    timeout 240 "$(binary "$build")" train --motion "$motion" --seed 0 --time-budget 60 --out "$dir" \
      --overwrite --progress lines > "$OUT/runs/${build}_$motion.log" 2>&1
    python3 - "$dir/summary.json" "$motion" "$build" >> "$rows" <<'PY'
import json, sys
path, motion, build = sys.argv[1:]
try:
    s = json.load(open(path))
except Exception as e:
    print(f"{motion} time to success s\t{build}\terror\t")
    sys.exit()
t, f = s["time_to_success_s"], s.get("frames_to_success")
print(f"{motion} time to success s\t{build}\t{'' if t is None else f'{t:.3f}'}\t{'' if not f else f'{f / 1e6:.2f}'}")
PY
    rm -f "$dir"/checkpoints/*.safetensors
  done
done

python3 - "$rows" <<'PY' | tee "$OUT/before_after.txt"
import csv, statistics, sys
rows = list(csv.DictReader(open(sys.argv[1]), delimiter="\t"))
order = list(dict.fromkeys(r["what"] for r in rows))
print(f"{'':30} {'before':>16} {'after':>16}")
for what in order:
    cell = {}
    for build in ("before", "after"):
        vals = [r for r in rows if r["what"] == what and r["build"] == build]
        nums = [float(r["value"]) for r in vals if r["value"] not in ("", "error")]
        text = " / ".join(f"{v:.3f}" for v in nums) or "no success"
        frames = [r["frames_M"] for r in vals if r["frames_M"]]
        cell[build] = text + (f" ({frames[0]} M)" if frames else "")
    print(f"{what:30} {cell['before']:>16} {cell['after']:>16}")
PY
