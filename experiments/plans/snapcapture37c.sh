# Issue 37, 2026-11-29 (nineteenth session), one GPU: the snapshot evaluation's graphs captured a
# step at a time on the training loop's own thread, one step (a chunk's capture, or its
# instantiation) while each of the first iterations runs on the GPU (the build), against the
# build before (852434f: captured at setup, .dev19before); after a first run that fills the
# driver's JIT cache; the five clips, committed configs, seeds 0-2 interleaved; then the GPU tests
# the change touches (gpu_rollout, gpu_train, gpu_cuda, gpu_ppo).
# The build measured: an uncommitted variant on 852434f, rejected and deleted (BENCHMARKS.md,
# "The snapshot graphs captured while training runs").
#   tests/device/stage.sh --only "gpu_rollout gpu_train gpu_cuda gpu_ppo" .dev19
#   SESSION_S=540 BIN=.dev19 BEFORE=.dev19before tests/device/lanes.sh experiments/plans/snapcapture37c.sh
SESSION_S=${SESSION_S:-540}
LANE0="train warmup 40 --motion walk --seed 0 --time-budget 1
  for s in 0 1 2; do
    for m in backflip cartwheel spinkick run walk; do
      train_before \${m}_before_s\$s 40 --motion \$m --seed \$s --time-budget 30
      train \${m}_s\$s 40 --motion \$m --seed \$s --time-budget 30
    done
  done
  grep -h 'graphs (' \$OUT/runs/*.log | sort | uniq -c | head -40 >> \$OUT/summary.txt
  TEST_TIMEOUT=200 gpu_test gpu_rollout gpu_train gpu_cuda gpu_ppo"
