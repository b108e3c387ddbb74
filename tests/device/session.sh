#!/usr/bin/env bash
# One call on the GPU machine: GPU tests, rollout benchmarks and training runs, with a short
# table printed last and full logs under $OUT. Stage the binaries first (tests/device/stage.sh)
# and carry that directory:
#   BIN=.device-bin tests/device/session.sh [tests] [bench] [gemm] [train] [hpo] [gpus]
#   (default: tests bench train; hpo runs HPO_CYCLES (10) offline cycles on backflip; gpus runs
#   `bench train-gpus` on every visible GPU and `train --gpus` for GPU_SETS (default "0,1" and
#   all visible GPUs) x MOTIONS_LIST (default backflip) x SEEDS, with NCCL from nccl_libs)
# Environment: BIN (staged binaries), OUT (logs; default /tmp/instantmimic-out),
# SEEDS (train: default "0 1 2"), MOTIONS_LIST (train: default all five clips),
# TRAIN_ARGS (extra flags for every `instantmimic train`), GPU_TESTS (test binaries to run;
# default every gpu_*).
# GEMMs (`policy.gemm`): GEMMS="warp cublas cublas_tf32" runs every bench variant and every
# training run once per setting (default: none given, so each config's own, `auto`); bench
# passes `--gemm`, train a copy of the config with `gemm` replaced. cuBLAS comes with the CUDA
# toolkit, not the driver: CUBLAS=1 puts the toolkit's lib64 on LD_LIBRARY_PATH for every test,
# bench and train run (a GEMMS entry starting with "cublas" does so for its own runs; gpu_blas
# always gets it). Without it the tests run on the driver alone, so `auto` takes Warp tiles.
set -uo pipefail
cd "$(dirname "$0")/../.."
. tests/device/common.sh
export PYTHONPATH=
export INSTANTMIMIC_BIN=$BIN/instantmimic
# A GPU test that would skip (a missing tool, reference or plan) fails instead (issue 17): the
# physics references are committed fixtures, so every GPU test checks something here.
export INSTANTMIMIC_NO_SKIP=1
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

# The library path for a run with GEMM setting $1 (empty: the config's own): the toolkit's
# libraries when CUBLAS=1 or the setting is a cuBLAS one, else the path as it is.
libs_for() {
  case "${CUBLAS:-0}:${1:-}" in 1:*|*:cublas*) toolkit_libs ;; *) echo "${LD_LIBRARY_PATH:-}" ;; esac
}

# A copy of config $1 with `gemm = "$2"` in its [policy] section; prints the copy's path.
config_with_gemm() {
  local out="$OUT/configs/$(basename "$1" .toml)-$2.toml"
  mkdir -p "$OUT/configs"
  awk -v g="$2" '/^gemm *=/ {next} {print} /^\[policy\]/ {print "gemm = \"" g "\""}' "$1" > "$out"
  grep -q '^\[policy\]' "$1" || printf '\n[policy]\ngemm = "%s"\n' "$2" >> "$out"
  echo "$out"
}

run_tests() {
  for t in "$BIN"/gpu_*; do
    name=$(basename "$t")
    # GPU_TESTS: the test binaries to run (default: every gpu_* binary)
    case " ${GPU_TESTS:-$name} " in *" $name "*) ;; *) continue ;; esac
    start=$(date +%s)
    # The cuBLAS tests see the toolkit's libraries; everything else runs on the driver alone
    # (`policy.gemm = "auto"` then takes Warp tiles) unless CUBLAS=1.
    libs=$(libs_for); [ "$name" = gpu_blas ] && libs=$(toolkit_libs)
    # Several GPUs need NCCL; on a machine with one GPU their tests are left out, and the
    # summary says so (with INSTANTMIMIC_NO_SKIP=1 they would fail for want of a second GPU).
    filter=(); left_out=
    if [ "$name" = gpu_multi_gpu ] || [ "$name" = gpu_world ]; then
      libs=$(LD_LIBRARY_PATH=$libs nccl_libs)
      if [ "$(gpu_count)" -lt 2 ]; then filter=(--skip several_gpus); left_out=" (several_gpus_* left out: $(gpu_count) GPU)"; fi
    fi
    if LD_LIBRARY_PATH=$libs timeout "$(budget "${TEST_TIMEOUT:-180}")" "$t" --nocapture --test-threads 1 "${filter[@]}" > "$OUT/test_$name.log" 2>&1; then status=PASS; else status=FAIL; fi
    note "test  $name  $status  $(( $(date +%s) - start )) s  $(grep -o 'test result: .*; [0-9]* ignored' "$OUT/test_$name.log" | tail -1)$left_out"
    [ "$status" = FAIL ] && grep -E "panicked|FAILED|failed" "$OUT/test_$name.log" | head -5
  done
}

run_bench() {
  # BENCH_VARIANTS: flag sets separated by ';'
  IFS=';' read -ra variants <<< "${BENCH_VARIANTS:---envs 4096 --substeps 4 --horizon 32;--envs 4096 --substeps 4 --horizon 8}"
  for variant in "${variants[@]}"; do
    for gemm in "${gemm_settings[@]}"; do
      tag=$(echo "$variant $gemm" | tr -cd 'A-Za-z0-9_')
      label="$variant${gemm:+ --gemm $gemm}"
      if LD_LIBRARY_PATH=$(libs_for "$gemm") timeout "$(budget 180)" "$BIN/instantmimic" bench rollout --motion backflip $variant ${gemm:+--gemm "$gemm"} --json > "$OUT/bench_$tag.json" 2> "$OUT/bench_$tag.err"; then
        python3 - "$OUT/bench_$tag.json" "$label" <<'PY' | tee -a "$summary"
import json, sys
# MuJoCo Warp's kernels printf their overflow warnings to stdout, before the JSON.
text = open(sys.argv[1]).read()
r = json.loads(text[text.index("\n{") + 1 if not text.startswith("{") else 0:])
print(f"bench {sys.argv[2]}: {r['frames_per_s']/1e6:.3f} M frames/s, physics only "
      f"{r['physics_only_frames_per_s']/1e6:.3f}, ratio {r['ratio']:.3f}; from the rollout's states "
      f"{r['physics_only_from_rollout_states_frames_per_s']/1e6:.3f}, ratio {r['ratio_to_rollout_states']:.3f}; physics share "
      f"{r['stage_ms']['physics'] / sum(r['stage_ms'].values()):.3f}; "
      + ", ".join(f"{k} {v:.2f} ms" for k, v in r["stage_ms"].items()) + f"; GEMMs: {r['gemm']}")
PY
      else
        note "bench $label FAILED: $(tail -2 "$OUT/bench_$tag.err")"
      fi
    done
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
    for gemm in "${gemm_settings[@]}"; do
      config="${CONFIG_DIR:-configs/train}/$motion${CONFIG_SUFFIX:-}.toml"
      [ -n "$gemm" ] && config=$(config_with_gemm "$config" "$gemm")
      for seed in ${SEEDS:-0 1 2}; do
        run="${motion}${gemm:+_$gemm}_$seed"
        dir="$OUT/runs/$run"
        if LD_LIBRARY_PATH=$(libs_for "$gemm") timeout "$(budget "${TRAIN_TIMEOUT:-150}")" "$BIN/instantmimic" train --motion "$motion" --config "$config" --seed "$seed" \
            --out "$dir" ${TRAIN_ARGS:-} > "$OUT/train_$run.log" 2>&1; then
          note "train $motion${gemm:+ gemm $gemm} seed $seed: $(grep -m1 '^GEMMs:' "$OUT/train_$run.log" | cut -c1-60); $(tail -1 "$OUT/train_$run.log")"
        else
          note "train $motion${gemm:+ gemm $gemm} seed $seed FAILED: $(tail -2 "$OUT/train_$run.log" | tr '\n' ' ')"
        fi
      done
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

run_gpus() {
  # Issue 21: whole-iteration frames/s on 1, 2, 4, ... GPUs, then training runs on GPU_SETS.
  local n all libs; n=$(gpu_count); libs=$(nccl_libs)
  all=$(seq -s, 0 $(( n - 1 )))
  if [ "$n" -lt 2 ]; then note "gpus: $n GPU visible; nothing to run"; return; fi
  if LD_LIBRARY_PATH=$libs timeout "$(budget 300)" "$BIN/instantmimic" bench train-gpus --motion backflip --gpus "$all" \
      > "$OUT/train_gpus.txt" 2> "$OUT/train_gpus.err"; then
    tee -a "$summary" < "$OUT/train_gpus.txt"
  else
    note "bench train-gpus FAILED: $(tail -2 "$OUT/train_gpus.err" | tr '\n' ' ')"
  fi
  local sets="0,1"; [ "$all" = 0,1 ] || sets="0,1 $all"
  for set in ${GPU_SETS:-$sets}; do
    for motion in ${MOTIONS_LIST:-backflip}; do
      for seed in ${SEEDS:-0 1 2}; do
        run="${motion}_gpus${set//,/}_$seed"
        if LD_LIBRARY_PATH=$libs timeout "$(budget "${TRAIN_TIMEOUT:-150}")" "$BIN/instantmimic" train --motion "$motion" --gpus "$set" --seed "$seed" \
            --out "$OUT/runs/$run" ${TRAIN_ARGS:-} > "$OUT/train_$run.log" 2>&1; then
          note "train $motion --gpus $set seed $seed: $(tail -1 "$OUT/train_$run.log")"
        else
          note "train $motion --gpus $set seed $seed FAILED: $(tail -2 "$OUT/train_$run.log" | tr '\n' ' ')"
        fi
      done
    done
  done
}

# GEMMS as an array; one empty entry (the config's own setting) when none is given.
read -ra gemm_settings <<< "${GEMMS:-}"
[ "${#gemm_settings[@]}" -eq 0 ] && gemm_settings=("")
sections=${*:-tests bench train}
for s in $sections; do
  case "$s" in
    tests) run_tests ;;
    bench) run_bench ;;
    gemm) run_gemm ;;
    train) run_train ;;
    hpo) run_hpo ;;
    gpus) run_gpus ;;
    *) echo "unknown section $s (tests, bench, gemm, train, hpo, gpus)" >&2; exit 2 ;;
  esac
done
# The device hands back at most 8 files: pack the logs, metrics and curves (not checkpoints).
tar czf /tmp/logs.tgz -C "$OUT" --exclude='*.safetensors' . && rm -rf "${OUT:?}"/* && mv /tmp/logs.tgz "$OUT/logs.tgz"
echo "==== summary"; tar xzf "$OUT/logs.tgz" -O ./summary.txt
