#!/usr/bin/env bash
# Every GPU test binary in one device call, spread over the GPUs of a multi-GPU machine: one
# worker per GPU (CUDA_VISIBLE_DEVICES) takes the next binary, longest first, and runs it through
# session.sh's `tests` section with its own log directory. gpu_multi_gpu and gpu_world, which
# need every GPU, run first and alone unless SKIP names them. The summary lines of all the tests are printed last.
#   BIN=.device-bin tests/device/parallel_tests.sh
# GPUS: the GPUs to spread over (default every GPU); SKIP: test binaries to leave out;
# TEST_TIMEOUT as session.sh. Logs: $OUT/<test>/logs.tgz.
set -uo pipefail
cd "$(dirname "$0")/../.."
. tests/device/common.sh
export BIN
GPUS=${GPUS:-$(nvidia-smi --query-gpu=index --format=csv,noheader | tr '\n' ' ')}
summary="$OUT/summary.txt"
: > "$summary"

# Longest first (seconds measured on H100s and H200s, 2026-11), so the last worker is not left
# alone with a long binary; a binary not listed goes last.
order="gpu_goal_latent gpu_goal gpu_latent gpu_library_eval gpu_train gpu_tensorboard gpu_divergence gpu_replay gpu_blas gpu_ppo gpu_rollout gpu_env_kernels gpu_reference_table gpu_cuda gpu_physics"
queue="$OUT/queue.txt"; : > "$queue"
for name in $order $(cd "$BIN" && ls gpu_*); do
  [ -x "$BIN/$name" ] || continue
  case " ${SKIP:-} gpu_multi_gpu gpu_world " in *" $name "*) continue ;; esac
  grep -qx "$name" "$queue" || echo "$name" >> "$queue"
done

run_one() { # gpus name
  OUT="$OUT/$2" GPU_TESTS=$2 CUDA_VISIBLE_DEVICES=$1 tests/device/session.sh tests > "$OUT/$2.console" 2>&1
  tar xzf "$OUT/$2/logs.tgz" -O ./summary.txt >> "$summary" 2>/dev/null || echo "test  $2  NO SUMMARY" >> "$summary"
}

for whole in gpu_multi_gpu gpu_world; do
  case " ${SKIP:-} " in *" $whole "*) ;; *)
    [ -x "$BIN/$whole" ] && run_one "$(echo $GPUS | tr ' ' ,)" "$whole" ;;
  esac
done

echo 0 > "$OUT/next.txt"
next_test() { # prints the next binary's name under a lock; nothing when none is left
  (
    flock 9
    i=$(cat "$OUT/next.txt")
    if [ "$i" -lt "$(wc -l < "$queue")" ]; then echo $((i + 1)) > "$OUT/next.txt"; sed -n "$((i + 1))p" "$queue"; fi
  ) 9> "$OUT/next.lock"
}
for gpu in $GPUS; do
  (
    while name=$(next_test) && [ -n "$name" ]; do run_one "$gpu" "$name"; done
  ) &
done
wait
echo "==== tests"
grep '^test ' "$summary"
