# Issue 37, 2026-11-29 (nineteenth session), one GPU: the snapshot evaluation's graphs captured
# on a thread of their own one chunk per training iteration, begun as the iteration's graph is
# launched (the build), against the build before the capture moved (852434f, .dev19before) and,
# for the walk, the same build capturing freely (IM_CAPTURE_FREE=1, an experiment's switch: a
# free capture delayed 7-10 of the first iterations by 20-40 ms each in snapcapture37.sh); after a
# first run that fills the driver's JIT cache; the five clips, committed configs, seeds 0-2
# interleaved; then gpu_rollout and gpu_train.
# The build measured: an uncommitted variant on 852434f, rejected and deleted (BENCHMARKS.md,
# "The snapshot graphs captured while training runs").
#   tests/device/stage.sh --only "gpu_rollout gpu_train" .dev19; .dev19before/instantmimic.xz
#   SESSION_S=540 BIN=.dev19 BEFORE=.dev19before tests/device/lanes.sh experiments/plans/snapcapture37b.sh
SESSION_S=${SESSION_S:-540}
LANE0="train warmup 40 --motion walk --seed 0 --time-budget 1
  for s in 0 1 2; do
    for m in backflip cartwheel spinkick run walk; do
      train_before \${m}_before_s\$s 40 --motion \$m --seed \$s --time-budget 30
      train \${m}_s\$s 40 --motion \$m --seed \$s --time-budget 30
    done
    export IM_CAPTURE_FREE=1
    train walk_free_s\$s 20 --motion walk --seed \$s --time-budget 30
    unset IM_CAPTURE_FREE
  done
  grep -h 'graphs were captured' \$OUT/runs/*.log | sort | uniq -c | head -40 >> \$OUT/summary.txt
  TEST_TIMEOUT=200 gpu_test gpu_rollout gpu_train"
