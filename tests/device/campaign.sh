#!/usr/bin/env bash
# A training campaign on the GPU machine: every trial of a plan file, one `instantmimic train`
# each, a table of medians printed last and the per-trial rows in $OUT/campaign.tsv.
#   tests/device/stage.sh --train-only      (here; or stage.sh for the GPU tests too)
#   BIN=.device-bin tests/device/campaign.sh PLAN [PLAN...]      (there)
# A plan line is `name|motion|seeds|budget_s|flags`: flags are passed to `train` as they are
# (e.g. `--set ppo.value_normalization=true --set env.substeps=2`); seeds are space-separated.
# Lines starting with # are skipped. Trials run in file order, seed by seed; a trial that would
# start after SESSION_S seconds (default 540) is skipped and listed as such, so the logs always
# come back inside the device call's 600 s.
set -uo pipefail
cd "$(dirname "$0")/../.."
. tests/device/common.sh
mkdir -p "$OUT/runs"
# cuBLAS for the policy's GEMMs (policy.gemm = "auto"), as the committed configs measure.
LD_LIBRARY_PATH=$(toolkit_libs)
export LD_LIBRARY_PATH
deadline=$(( $(date +%s) + ${SESSION_S:-540} ))
tsv="$OUT/campaign.tsv"
[ -f "$tsv" ] || printf 'name\tmotion\tseed\tsuccess\ttime_s\tframes_M\tpose_time_s\tclip_start_time_s\tactive_s\tfps_M\tlast_rate\tlast_mpjpe\tlast_ape\twall_s\tstop\n' > "$tsv"
nvidia-smi --query-gpu=name,driver_version,clocks.sm,clocks.max.sm --format=csv,noheader | tee "$OUT/gpu.txt"
# Check every plan before the first trial: a malformed line fails the call at once, in one line.
[ "$#" -ge 1 ] || { echo "usage: campaign.sh PLAN [PLAN...]" >&2; exit 2; }
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
  done < "$plan"
done
for plan in "$@"; do
  while IFS='|' read -r name motion seeds budget flags; do
    case "$name" in ''|'#'*) continue ;; esac
    for seed in $seeds; do
      left=$(( deadline - $(date +%s) ))
      if [ "$left" -lt $(( ${budget%.*} / 2 + 10 )) ]; then
        echo "skipped $name seed $seed (session time)" | tee -a "$OUT/skipped.txt"
        continue
      fi
      dir="$OUT/runs/${name}_s$seed"
      start=$(date +%s%N)
      # shellcheck disable=SC2086
      timeout $(( left < ${budget%.*} * 4 + 60 ? left : ${budget%.*} * 4 + 60 )) \
        "$BIN/instantmimic" train --motion "$motion" --seed "$seed" --time-budget "$budget" \
        --out "$dir" --overwrite --progress lines $flags > "$OUT/runs/${name}_s$seed.log" 2>&1
      rc=$?
      wall_ms=$(( ($(date +%s%N) - start) / 1000000 ))
      python3 - "$dir/summary.json" "$name" "$motion" "$seed" "$wall_ms" "$rc" >> "$tsv" <<'PY'
import json, sys
path, name, motion, seed, wall_ms, rc = sys.argv[1:]
wall = float(wall_ms) / 1000
try:
    s = json.load(open(path))
except Exception:
    print("\t".join([name, motion, seed, "error", "", "", "", "", "", "", "", "", "", f"{float(wall):.1f}", f"rc {rc}"]))
    sys.exit()
e = s.get("last_evaluation") or {}
f = lambda x, d=3: "" if x is None else f"{x:.{d}f}"
frames = s.get("frames_to_success")
print("\t".join([name, motion, seed, str(s["time_to_success_s"] is not None).lower(),
    f(s["time_to_success_s"]), f(frames / 1e6 if frames else None, 2), f(s.get("time_to_pose_error_s")),
    f(s.get("time_to_clip_start_success_s")), f(s["active_time_s"], 2), f(s["frames_per_s"] / 1e6),
    f(e.get("success_rate")), f(e.get("global_mpjpe_m")), f(e.get("pose_error_m")), f"{float(wall):.1f}", s["stop_reason"]]))
PY
      tail -1 "$tsv"
    done
  done < "$plan"
done
python3 - "$tsv" <<'PY' | tee "$OUT/table.txt"
import csv, statistics, sys
rows = list(csv.DictReader(open(sys.argv[1]), delimiter="\t"))
order = []
for r in rows:
    if (r["name"], r["motion"]) not in order:
        order.append((r["name"], r["motion"]))
print(f"{'variant':34} {'motion':10} {'ok':>5} {'median s':>9} {'seeds s':>22} {'M frames':>9} {'pose s':>7} {'clip0 s':>7} {'Mf/s':>5} {'wall':>6}")
for name, motion in order:
    rs = [r for r in rows if r["name"] == name and r["motion"] == motion]
    ok = [r for r in rs if r["success"] == "true"]
    # A failed seed counts as its active time (at least the budget): the median is then a bound.
    times = [float(r["time_s"]) if r["success"] == "true" else float(r["active_s"] or "nan") for r in rs]
    med = statistics.median(times) if times else float("nan")
    frames = [float(r["frames_M"]) for r in ok]
    pose = [float(r["pose_time_s"]) for r in rs if r["pose_time_s"]]
    clip0 = [float(r["clip_start_time_s"]) for r in rs if r["clip_start_time_s"]]
    fps = [float(r["fps_M"]) for r in rs if r["fps_M"]]
    seeds = " ".join((r["time_s"] if r["success"] == "true" else f">{float(r['active_s'] or 0):.0f}") for r in rs)
    m = lambda xs: f"{statistics.median(xs):.2f}" if xs else "-"
    print(f"{name:34} {motion:10} {len(ok)}/{len(rs):<3} {med:9.2f} {seeds:>22} {m(frames):>9} {m(pose):>7} {m(clip0):>7} {m(fps):>5} {sum(float(r['wall_s']) for r in rs):6.0f}")
PY
tar czf /tmp/campaign.tgz -C "$OUT" --exclude='*.safetensors' --exclude='curve.png' . && rm -rf "${OUT:?}"/* && mv /tmp/campaign.tgz "$OUT/campaign.tgz"
