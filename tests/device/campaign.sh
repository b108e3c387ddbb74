#!/usr/bin/env bash
# A training campaign on the GPU machine: every trial of a plan file, one `instantmimic train`
# each, a table of medians printed last and the per-trial rows in $OUT/campaign.tsv.
#   tests/device/stage.sh --train-only      (here; or stage.sh for the GPU tests too)
#   BIN=.device-bin tests/device/campaign.sh PLAN [PLAN...]      (there)
# A plan line is `name|motion|seeds|budget_s|flags`: flags are passed to `train` as they are
# (e.g. `--set ppo.value_normalization=true --set env.substeps=2`); seeds are space-separated.
# Lines starting with # are skipped. One worker per GPU (GPUS="0 1 2 3" picks them; default
# every GPU nvidia-smi lists) takes the trials in file order, seed by seed, each worker training
# one trial at a time on its own GPU (CUDA_VISIBLE_DEVICES), so a 4-GPU machine runs a 3-seed
# plan about 4x faster than one GPU; every trial still has a GPU to itself. A trial that would
# start after SESSION_S seconds (default 540) is skipped and listed as such, so the logs always
# come back inside the device call's 600 s.
# Trials skip the replay page (`--no-replay`) unless REPLAY=1. Flags that begin with
# `--binary PATH` run that binary instead of the staged one: an older build beside the new one
# in one campaign (before/after), e.g. `spinkick_before|spinkick|0 1 2|30|--binary /tmp/before/instantmimic`.
set -uo pipefail
cd "$(dirname "$0")/../.."
. tests/device/common.sh
mkdir -p "$OUT/runs"
# cuBLAS for the policy's GEMMs (policy.gemm = "auto"), as the committed configs measure.
LD_LIBRARY_PATH=$(toolkit_libs)
export LD_LIBRARY_PATH
deadline=$(( $(date +%s) + ${SESSION_S:-540} ))
replay_flag=--no-replay
[ "${REPLAY:-0}" = 1 ] && replay_flag=
tsv="$OUT/campaign.tsv"
[ -f "$tsv" ] || printf 'name\tmotion\tseed\tsuccess\ttime_s\tframes_M\tpose_time_s\tclip_start_time_s\trobotics_rule_time_s\tactive_s\tfps_M\tlast_rate\tlast_mpjpe\tlast_ape\twall_s\tstop\tgpu\n' > "$tsv"
nvidia-smi --query-gpu=index,name,driver_version,clocks.sm,clocks.max.sm --format=csv,noheader | tee "$OUT/gpu.txt"
GPUS=${GPUS:-$(nvidia-smi --query-gpu=index --format=csv,noheader | tr '\n' ' ')}
# Check every plan before the first trial: a malformed line fails the call at once, in one line.
[ "$#" -ge 1 ] || { echo "usage: campaign.sh PLAN [PLAN...]" >&2; exit 2; }
jobs_file="$OUT/jobs.txt"; : > "$jobs_file"
for plan in "$@"; do
  [ -f "$plan" ] || { echo "$plan: no such plan file" >&2; exit 2; }
  n=0
  while IFS='|' read -r name motion seeds budget flags; do
    n=$((n + 1))
    case "$name" in ''|'#'*) continue ;; esac
    if [ -z "$motion" ] || ! [[ "$seeds" =~ ^[0-9]+( [0-9]+)*$ ]] || ! [[ "$budget" =~ ^[0-9]+$ ]]; then
      echo "$plan:$n: expected name|motion|seeds (integers)|budget_s (integer)|flags, got: $name|$motion|$seeds|$budget|$flags" >&2
      exit 2
    fi
    for seed in $seeds; do printf '%s|%s|%s|%s|%s\n' "$name" "$motion" "$seed" "$budget" "$flags" >> "$jobs_file"; done
  done < "$plan"
done
echo "$(wc -l < "$jobs_file") trials on GPUs: $GPUS"
echo 0 > "$OUT/next.txt"

# Takes the next trial's line number under a lock; prints nothing when none is left.
next_job() {
  (
    flock 9
    i=$(cat "$OUT/next.txt")
    if [ "$i" -lt "$(wc -l < "$jobs_file")" ]; then echo $((i + 1)) > "$OUT/next.txt"; echo $((i + 1)); fi
  ) 9> "$OUT/next.lock"
}

run_trial() { # gpu name motion seed budget flags
  local gpu=$1 name=$2 motion=$3 seed=$4 budget=$5 flags=$6
  local left=$(( deadline - $(date +%s) ))
  if [ "$left" -lt $(( ${budget%.*} / 2 + 10 )) ]; then
    echo "skipped $name seed $seed (session time)" | tee -a "$OUT/skipped.txt"
    return
  fi
  local dir="$OUT/runs/${name}_s$seed" start rc wall_ms row binary="$BIN/instantmimic"
  if [[ "$flags" == --binary\ * ]]; then
    flags=${flags#--binary }; binary=${flags%% *}
    [[ "$flags" == *\ * ]] && flags=${flags#* } || flags=
  fi
  local replay=$replay_flag
  # An older build without `--no-replay` runs without the flag.
  "$binary" train --help 2>/dev/null | grep -q -- --no-replay || replay=
  start=$(date +%s%N)
  # shellcheck disable=SC2086
  CUDA_VISIBLE_DEVICES=$gpu timeout $(( left < ${budget%.*} * 4 + 60 ? left : ${budget%.*} * 4 + 60 )) \
    "$binary" train --motion "$motion" --seed "$seed" --time-budget "$budget" \
    --out "$dir" --overwrite --progress lines $replay $flags > "$OUT/runs/${name}_s$seed.log" 2>&1
  rc=$?
  wall_ms=$(( ($(date +%s%N) - start) / 1000000 ))
  row=$(python3 - "$dir/summary.json" "$name" "$motion" "$seed" "$wall_ms" "$rc" "$gpu" <<'PY'
import json, sys
path, name, motion, seed, wall_ms, rc, gpu = sys.argv[1:]
wall = float(wall_ms) / 1000
try:
    s = json.load(open(path))
except Exception:
    print("\t".join([name, motion, seed, "error", "", "", "", "", "", "", "", "", "", "", f"{float(wall):.1f}", f"rc {rc}", gpu]))
    sys.exit()
e = s.get("last_evaluation") or {}
f = lambda x, d=3: "" if x is None else f"{x:.{d}f}"
frames = s.get("frames_to_success")
print("\t".join([name, motion, seed, str(s["time_to_success_s"] is not None).lower(),
    f(s["time_to_success_s"]), f(frames / 1e6 if frames else None, 2), f(s.get("time_to_pose_error_s")),
    f(s.get("time_to_clip_start_success_s")), f(s.get("time_to_robotics_rule_success_s")), f(s["active_time_s"], 2), f(s["frames_per_s"] / 1e6),
    f(e.get("success_rate")), f(e.get("global_mpjpe_m")), f(e.get("pose_error_m")), f"{float(wall):.1f}", s["stop_reason"], gpu]))
PY
)
  ( flock 9; echo "$row" >> "$tsv" ) 9> "$OUT/tsv.lock"
  echo "$row"
}

worker() { # gpu
  local gpu=$1 i line name motion seed budget flags
  while i=$(next_job) && [ -n "$i" ]; do
    line=$(sed -n "${i}p" "$jobs_file")
    IFS='|' read -r name motion seed budget flags <<< "$line"
    run_trial "$gpu" "$name" "$motion" "$seed" "$budget" "$flags"
  done
}

for gpu in $GPUS; do worker "$gpu" & done
wait

python3 - "$tsv" "$jobs_file" <<'PY' | tee "$OUT/table.txt"
import csv, statistics, sys
rows = list(csv.DictReader(open(sys.argv[1]), delimiter="\t"))
# Plan order, whatever order the workers finished in.
order = []
for line in open(sys.argv[2]):
    name, motion = line.split("|")[:2]
    if (name, motion) not in order:
        order.append((name, motion))
print(f"{'variant':34} {'motion':10} {'ok':>5} {'median s':>9} {'seeds s':>22} {'M frames':>9} {'pose s':>7} {'clip0 s':>7} {'rule0 s':>7} {'Mf/s':>5} {'wall':>6}")
for name, motion in order:
    rs = sorted((r for r in rows if r["name"] == name and r["motion"] == motion), key=lambda r: int(r["seed"]))
    if not rs:
        continue
    ok = [r for r in rs if r["success"] == "true"]
    # A failed seed counts as its active time (at least the budget): the median is then a bound.
    times = [float(r["time_s"]) if r["success"] == "true" else float(r["active_s"] or "nan") for r in rs]
    med = statistics.median(times) if times else float("nan")
    frames = [float(r["frames_M"]) for r in ok]
    pose = [float(r["pose_time_s"]) for r in rs if r["pose_time_s"]]
    clip0 = [float(r["clip_start_time_s"]) for r in rs if r["clip_start_time_s"]]
    rule0 = [float(r["robotics_rule_time_s"]) for r in rs if r.get("robotics_rule_time_s")]
    fps = [float(r["fps_M"]) for r in rs if r["fps_M"]]
    seeds = " ".join((r["time_s"] if r["success"] == "true" else f">{float(r['active_s'] or 0):.0f}") for r in rs)
    m = lambda xs: f"{statistics.median(xs):.2f}" if xs else "-"
    print(f"{name:34} {motion:10} {len(ok)}/{len(rs):<3} {med:9.2f} {seeds:>22} {m(frames):>9} {m(pose):>7} {m(clip0):>7} {m(rule0):>7} {m(fps):>5} {sum(float(r['wall_s']) for r in rs):6.0f}")
PY
tar czf /tmp/campaign.tgz -C "$OUT" --exclude='*.safetensors' --exclude='curve.png' --exclude='replay.html' . && rm -rf "${OUT:?}"/* && mv /tmp/campaign.tgz "$OUT/campaign.tgz"
