#!/usr/bin/env bash
# A restructuring's check that nothing changed, in one device call, both builds on the same GPUs:
# `bench full` (the committed backflip config) on GPU 0, the backflip's time to success for
# each seed of SEEDS (the builds alternating) on GPU 1 (GPU 0 on a one-GPU machine), then
# `eval --json` of the older build's seed-0 checkpoint on the deterministic physics
# (ptx/deterministic), each build twice: the four outputs must be byte-identical. A table is
# printed last; everything else comes back packed in $OUT/no_change.tgz.
#   here:  tests/device/stage.sh (the newer build); xz the older binary into DIR/instantmimic.xz
#   there: BEFORE=DIR BIN=.device-bin tests/device/no_change.sh
# SEEDS (default "0 1 2"); BUDGET (train --time-budget, default 30). GPU tests of the staged
# BIN can run first on the training GPU: GPU_TESTS=1.
set -uo pipefail
cd "$(dirname "$0")/../.."
rm -rf /tmp/instantmimic-bin
. tests/device/common.sh
unpack_before
LD_LIBRARY_PATH=$(toolkit_libs); export LD_LIBRARY_PATH
staged=$BIN
pick() { binary "$1"; }
mkdir -p "$OUT/runs"
nvidia-smi -L > "$OUT/gpus.txt"
G2=$(( $(gpu_count) > 1 ? 1 : 0 ))
(
  if [ "${GPU_TESTS:-0}" = 1 ]; then
    mkdir -p /tmp/no_change_tests
    OUT=/tmp/no_change_tests BIN=$staged GPUS=$G2 tests/device/parallel_tests.sh > /tmp/no_change_tests/run.txt 2>&1
    grep '^test ' /tmp/no_change_tests/run.txt > "$OUT/gpu_tests.txt"
    tar czf "$OUT/gpu_tests.tgz" -C /tmp/no_change_tests .
  fi
  for s in ${SEEDS:-0 1 2}; do for b in before after; do
    CUDA_VISIBLE_DEVICES=$G2 timeout 150 "$(pick $b)" train --motion backflip --seed "$s" \
      --time-budget "${BUDGET:-30}" --out "$OUT/runs/${b}_s$s" --overwrite --progress lines \
      > "$OUT/runs/${b}_s$s.log" 2>&1
  done; done
) &
train_pid=$!
for b in before after; do
  CUDA_VISIBLE_DEVICES=0 timeout 240 "$(pick $b)" bench full --json > "$OUT/full_$b.json" 2> "$OUT/full_$b.err"
done
wait $train_pid
ck=$(ls "$OUT"/runs/before_s0/checkpoints/*.safetensors 2>/dev/null | sort | tail -1)
for b in before after; do for i in 1 2; do
  CUDA_VISIBLE_DEVICES=0 timeout 120 "$(pick $b)" eval --checkpoint "$ck" --assets ptx/deterministic \
    --episodes 2 --json > "$OUT/eval_${b}_$i.json" 2> "$OUT/eval_${b}_$i.err"
done; done
[ -f "$OUT/gpu_tests.txt" ] && cat "$OUT/gpu_tests.txt"
python3 - "$OUT" <<'PY'
import hashlib, json, os, sys
out = sys.argv[1]
def js(path):
    text = open(path).read()
    return json.loads(text[text.find("{"):])
print("| build | bench full: one after the other / concurrent M frames/s | / floor (concurrent) | floor M frames/s |")
for b in ["before", "after"]:
    try:
        r = js(f"{out}/full_{b}.json")
        print(f"| {b} | {r['sequential']['frames_per_s']/1e6:.4f} / {r['concurrent']['frames_per_s']/1e6:.4f} "
              f"| {r['concurrent']['ratio_to_floor']:.4f} | {r['floor_frames_per_s']/1e6:.4f} |")
    except Exception as e:
        print(f"| {b} | error: {e} |")
print("| build | seed | time to success s | frames M |")
for name in sorted(os.listdir(f"{out}/runs")):
    path = f"{out}/runs/{name}/summary.json"
    if os.path.isfile(path):
        r = json.load(open(path))
        frames = r.get("frames_to_success")
        b, s = name.rsplit("_s", 1)
        print(f"| {b} | {s} | {r.get('time_to_success_s')} | {frames / 1e6 if frames else None} |")
digests = set()
for b in ["before", "after"]:
    for i in [1, 2]:
        p = f"{out}/eval_{b}_{i}.json"
        data = open(p, "rb").read() if os.path.exists(p) else b""
        digests.add(hashlib.md5(data).hexdigest())
        print(f"eval --json {b} {i}: {len(data)} bytes, md5 {hashlib.md5(data).hexdigest()}")
print("eval --json byte-identical" if len(digests) == 1 else "eval --json DIFFERS")
PY
rm -rf "$OUT"/runs/*/checkpoints "$OUT"/runs/*/replay.html
tar czf /tmp/no_change.tgz -C "$OUT" . && rm -rf "${OUT:?}"/* && mv /tmp/no_change.tgz "$OUT/"
