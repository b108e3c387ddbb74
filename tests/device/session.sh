#!/usr/bin/env bash
# One call on the GPU machine: GPU tests, rollout benchmarks and training runs, with a short
# table printed last and full logs under $OUT. Stage the binaries first (tests/device/stage.sh)
# and carry that directory:
#   BIN=.device-bin tests/device/session.sh [tests] [bench] [gemm] [train] [hpo]
#   (default: tests bench train; hpo runs HPO_CYCLES (10) offline cycles on backflip)
# Environment: BIN (staged binaries), OUT (logs; default /tmp/instantmimic-out),
# SEEDS (train: default "0 1 2"), MOTIONS_LIST (train: default all five clips),
# TRAIN_ARGS (extra flags for every `instantmimic train`), GPU_TESTS (test binaries to run;
# default every gpu_*).
set -uo pipefail
cd "$(dirname "$0")/../.."
BIN=${BIN:-.device-bin}
if [ -f "$BIN/bin.txz" ]; then
  mkdir -p /tmp/instantmimic-bin && tar xJf "$BIN/bin.txz" -C /tmp/instantmimic-bin && BIN=/tmp/instantmimic-bin
fi
BIN=$(cd "$BIN" && pwd)
OUT=${OUT:-/tmp/instantmimic-out}
mkdir -p "$OUT"
export INSTANTMIMIC_MOTIONS=${INSTANTMIMIC_MOTIONS:-$BIN/motions}
export PYTHONPATH=
export INSTANTMIMIC_BIN=$BIN/instantmimic
summary="$OUT/summary.txt"
: > "$summary"
note() { echo "$*" | tee -a "$summary"; }
# The device call's own limit is 600 s: stop starting new work SESSION_S seconds in, and cap
# each command's timeout by what is left, so the logs are always packed and come back.
deadline=$(( $(date +%s) + ${SESSION_S:-560} ))
budget() { # budget SECONDS: the smaller of SECONDS and the time left (1 when none: `timeout 0` would mean no limit)
  local left=$(( deadline - $(date +%s) )); [ "$left" -lt 1 ] && left=1
  echo $(( $1 < left ? $1 : left ))
}

nvidia-smi --query-gpu=name,driver_version,memory.total,clocks.sm,clocks.max.sm --format=csv,noheader \
  | tee "$OUT/gpu.txt"

# The CUDA toolkit's library directory (cuBLAS), appended to LD_LIBRARY_PATH.
toolkit_libs() {
  local dir; dir=$(ls -d /usr/local/cuda*/lib64 2>/dev/null | sort -V | tail -1)
  echo "${LD_LIBRARY_PATH:+$LD_LIBRARY_PATH:}$dir"
}

run_tests() {
  for t in "$BIN"/gpu_*; do
    name=$(basename "$t")
    # GPU_TESTS: the test binaries to run (default: every gpu_* binary)
    case " ${GPU_TESTS:-$name} " in *" $name "*) ;; *) continue ;; esac
    start=$(date +%s)
    # Only the cuBLAS test sees the toolkit's libraries: everything else must run on the driver.
    libs=${LD_LIBRARY_PATH:-}; [ "$name" = gpu_blas ] && libs=$(toolkit_libs)
    if LD_LIBRARY_PATH=$libs timeout "$(budget "${TEST_TIMEOUT:-180}")" "$t" --nocapture --test-threads 1 > "$OUT/test_$name.log" 2>&1; then status=PASS; else status=FAIL; fi
    note "test  $name  $status  $(( $(date +%s) - start )) s  $(grep -o 'test result: .*; [0-9]* ignored' "$OUT/test_$name.log" | tail -1)"
    [ "$status" = FAIL ] && grep -E "panicked|FAILED|failed" "$OUT/test_$name.log" | head -5
  done
}

run_bench() {
  # BENCH_VARIANTS: flag sets separated by ';'
  IFS=';' read -ra variants <<< "${BENCH_VARIANTS:---envs 4096 --substeps 4 --horizon 32;--envs 4096 --substeps 4 --horizon 8}"
  for variant in "${variants[@]}"; do
    tag=$(echo "$variant" | tr -cd 'A-Za-z0-9_')
    if timeout "$(budget 180)" "$BIN/instantmimic" bench rollout --motion backflip $variant --json > "$OUT/bench_$tag.json" 2> "$OUT/bench_$tag.err"; then
      python3 - "$OUT/bench_$tag.json" "$variant" <<'PY' | tee -a "$summary"
import json, sys
# MuJoCo Warp's kernels printf their overflow warnings to stdout, before the JSON.
text = open(sys.argv[1]).read()
r = json.loads(text[text.index("\n{") + 1 if not text.startswith("{") else 0:])
print(f"bench {sys.argv[2]}: {r['frames_per_s']/1e6:.3f} M frames/s, physics only "
      f"{r['physics_only_frames_per_s']/1e6:.3f}, ratio {r['ratio']:.3f}; from the rollout's states "
      f"{r['physics_only_from_rollout_states_frames_per_s']/1e6:.3f}, ratio {r['ratio_to_rollout_states']:.3f}; physics share "
      f"{r['phase_ms']['physics'] / sum(r['phase_ms'].values()):.3f}; "
      + ", ".join(f"{k} {v:.2f} ms" for k, v in r["phase_ms"].items()))
PY
    else
      note "bench $variant FAILED: $(tail -2 "$OUT/bench_$tag.err")"
    fi
  done
}

run_gemm() {
  # Issue 4: Warp's tile GEMM against cuBLAS on the policy's shapes.
  if LD_LIBRARY_PATH=$(toolkit_libs) timeout "$(budget 120)" "$BIN/instantmimic" bench gemm > "$OUT/gemm.txt" 2> "$OUT/gemm.err"; then
    tee -a "$summary" < "$OUT/gemm.txt"
  else
    note "bench gemm FAILED: $(tail -2 "$OUT/gemm.err")"
  fi
}

run_train() {
  for motion in ${MOTIONS_LIST:-walk run spinkick backflip cartwheel}; do
    for seed in ${SEEDS:-0 1 2}; do
      dir="$OUT/runs/${motion}_$seed"
      if timeout "$(budget "${TRAIN_TIMEOUT:-150}")" "$BIN/instantmimic" train --motion "$motion" --config "${CONFIG_DIR:-configs/train}/$motion${CONFIG_SUFFIX:-}.toml" --seed "$seed" \
          --out "$dir" ${TRAIN_ARGS:-} > "$OUT/train_${motion}_$seed.log" 2>&1; then
        note "train $motion seed $seed: $(tail -1 "$OUT/train_${motion}_$seed.log")"
      else
        note "train $motion seed $seed FAILED: $(tail -2 "$OUT/train_${motion}_$seed.log" | tr '\n' ' ')"
      fi
    done
  done
}

run_hpo() {
  # Issue 6: an offline (no LLM) search on backflip from the paper's baseline. HPO_DIR: the
  # search directory of an earlier call (carried back) to resume; HPO_ARGS: flags of a new
  # search (e.g. --seeds 0 --max-candidates 2); HPO_CYCLES: run until this cycle (10).
  local dir="$OUT/hpo" args
  if [ -n "${HPO_DIR:-}" ] && [ -d "$HPO_DIR" ]; then
    cp -r "$HPO_DIR" "$dir"
    args=(--resume "$dir")
  else
    args=(--config "${HPO_CONFIG:-configs/hpo/backflip.toml}" --out "$dir" ${HPO_ARGS:-})
  fi
  # Stop between cycles 15 s before the session's end, so no half-run cycle is lost.
  local stop=$(( deadline - $(date +%s) - 15 )); [ "$stop" -lt 1 ] && stop=1
  if timeout "$(budget 600)" "$BIN/instantmimic" hpo "${args[@]}" --cycles "${HPO_CYCLES:-10}" --stop-after "$stop" \
      > "$OUT/hpo.log" 2>&1; then
    note "hpo: $(tail -3 "$OUT/hpo.log" | tr '\n' ' ')"
  else
    note "hpo stopped (resume with HPO_DIR): $(grep -v 'overflow\|limit reached' "$OUT/hpo.log" | tail -3 | tr '\n' ' ')"
  fi
}

sections=${*:-tests bench train}
for s in $sections; do
  case "$s" in
    tests) run_tests ;;
    bench) run_bench ;;
    gemm) run_gemm ;;
    train) run_train ;;
    hpo) run_hpo ;;
    *) echo "unknown section $s (tests, bench, gemm, train, hpo)" >&2; exit 2 ;;
  esac
done
# The device hands back at most 8 files: pack the logs, metrics and curves (not checkpoints).
tar czf /tmp/logs.tgz -C "$OUT" --exclude='*.safetensors' . && rm -rf "${OUT:?}"/* && mv /tmp/logs.tgz "$OUT/logs.tgz"
echo "==== summary"; tar xzf "$OUT/logs.tgz" -O ./summary.txt
