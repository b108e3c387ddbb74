#!/usr/bin/env bash
# Issue 40's measurement, in one device call on a machine with two GPUs: frames per second of
# the committed backflip config trained for ITERATIONS iterations (no stop at success, no
# evaluation) on one GPU, on `--gpus 0,1` (threads) and as two processes (`--rank R --world-size
# 2 --rendezvous`), each REPEATS times, the three modes alternating; then the backflip's time to
# success for each seed of SEEDS as threads and as processes. A table is printed last; the runs'
# summaries and logs come back packed in $OUT/world_scaling.tgz.
#   here:  tests/device/stage.sh --train-only (the release binary)
#   there: BIN=.device-bin tests/device/world_scaling.sh
# ITERATIONS (default 300), REPEATS (default 3), SEEDS (default "0 1 2"; empty: none), BUDGET
# (default 30).
set -uo pipefail
cd "$(dirname "$0")/../.."
rm -rf /tmp/instantmimic-bin
. tests/device/common.sh
LD_LIBRARY_PATH=$(nccl_libs); export LD_LIBRARY_PATH
LD_LIBRARY_PATH=$(toolkit_libs); export LD_LIBRARY_PATH
[ "$(gpu_count)" -ge 2 ] || { echo "world_scaling.sh needs two GPUs; this machine has $(gpu_count)" >&2; exit 2; }
exe=$BIN/instantmimic
runs=$OUT/runs
mkdir -p "$runs"
nvidia-smi -L > "$OUT/gpus.txt"
port=29611

one() { # name args...: one process on GPU 0
  local name=$1; shift
  CUDA_VISIBLE_DEVICES=0 timeout 200 "$exe" train "$@" --out "$runs/$name" --overwrite --progress lines \
    > "$runs/$name.log" 2>&1
}
threads() { # name args...
  local name=$1; shift
  timeout 200 "$exe" train "$@" --gpus 0,1 --out "$runs/$name" --overwrite --progress lines \
    > "$runs/$name.log" 2>&1
}
processes() { # name args...: ranks 0 and 1, each its own GPU
  local name=$1; shift
  port=$((port + 1))
  for r in 0 1; do
    timeout 200 "$exe" train "$@" --rank $r --world-size 2 --rendezvous "127.0.0.1:$port" \
      --world-timeout 60 --out "$runs/$name" --overwrite --progress lines > "$runs/${name}.rank$r.log" 2>&1 &
  done
  wait
}

# Throughput alone: no evaluation or replay page between the iterations (outside active time anyway).
fixed=(--motion backflip --max-iterations "${ITERATIONS:-300}" --set run.stop_on_success=false
  --set run.eval_interval=1000000 --set run.replay=false)
for i in $(seq 1 "${REPEATS:-3}"); do
  one "one_$i" "${fixed[@]}"
  threads "threads_$i" "${fixed[@]}"
  processes "processes_$i" "${fixed[@]}"
done
for s in ${SEEDS-0 1 2}; do
  success=(--motion backflip --seed "$s" --time-budget "${BUDGET:-30}")
  threads "success_threads_s$s" "${success[@]}"
  processes "success_processes_s$s" "${success[@]}"
done

python3 - "$runs" <<'PY'
import json, os, statistics, sys
runs = sys.argv[1]
def summary(name):
    p = f"{runs}/{name}/summary.json"
    return json.load(open(p)) if os.path.isfile(p) else None
print("| mode | runs | M frames/s (each) | median | / one GPU |")
base = None
for mode in ["one", "threads", "processes"]:
    names = sorted(n for n in os.listdir(runs) if n.startswith(mode + "_") and os.path.isdir(f"{runs}/{n}"))
    fps = [s["frames_per_s"] / 1e6 for s in map(summary, names) if s]
    med = statistics.median(fps) if fps else float("nan")
    base = med if mode == "one" else base
    print(f"| {mode} | {len(fps)} of {len(names)} | {' / '.join(f'{f:.4f}' for f in fps)} | {med:.4f} | {med / base:.3f}x |")
print("| mode | seed | time to success s | clip start s | frames M | wall to success s |")
for name in sorted(n for n in os.listdir(runs) if n.startswith("success_") and os.path.isdir(f"{runs}/{n}")):
    s = summary(name) or {}
    _, mode, seed = name.split("_")
    frames = s.get("frames_to_success")
    print(f"| {mode} | {seed[1:]} | {s.get('time_to_success_s')} | {s.get('time_to_clip_start_success_s')} "
          f"| {frames / 1e6 if frames else None} | {s.get('wall_time_to_success_s')} |")
PY
rm -rf "$runs"/*/checkpoints "$runs"/*/replay.html
tar czf /tmp/world_scaling.tgz -C "$OUT" . && rm -rf "${OUT:?}"/* && mv /tmp/world_scaling.tgz "$OUT/"
