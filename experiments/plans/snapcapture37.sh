# Issue 37, 2026-11-29 (nineteenth session), one GPU: the snapshot evaluation's graphs captured
# on a thread and a stream of their own while the first iterations train, against the build
# before it (852434f, in .dev19before) in the same call, after a first run that fills the
# driver's JIT cache; the five clips, committed configs, seeds 0-2 interleaved; then the GPU
# tests the change touches (gpu_rollout: the graphs captured beside training play as each
# snapshot alone; gpu_train: runs, resume and SIGINT with the capture running).
# The build measured: an uncommitted variant on 852434f, rejected and deleted (BENCHMARKS.md,
# "The snapshot graphs captured while training runs").
#   tests/device/stage.sh --only "gpu_rollout gpu_train" .dev19; .dev19before/instantmimic.xz
#   SESSION_S=540 BIN=.dev19 BEFORE=.dev19before tests/device/lanes.sh experiments/plans/snapcapture37.sh
SESSION_S=${SESSION_S:-540}
LANE0="train warmup 40 --motion walk --seed 0 --time-budget 1
  for s in 0 1 2; do
    for m in backflip cartwheel spinkick run walk; do
      train_before \${m}_before_s\$s 40 --motion \$m --seed \$s --time-budget 30
      train \${m}_s\$s 40 --motion \$m --seed \$s --time-budget 30
    done
  done
  grep -h 'graphs were captured' \$OUT/runs/*.log | sort | uniq -c | head -40 >> \$OUT/summary.txt
  TEST_TIMEOUT=200 gpu_test gpu_rollout gpu_train"
