# Issue 37, 2026-11-29 (nineteenth session), one GPU: a tracking evaluation's full chunks captured
# as one graph, launched once per chunk (each chunk writes its storage rows from 0), against the
# build before (852434f, .dev19before: a graph per chunk) in the same call, after a first run
# that fills the driver's JIT cache; the five clips, committed configs, seeds 0-2 interleaved;
# then the GPU tests the change touches.
#   tests/device/stage.sh --only "gpu_rollout gpu_train gpu_goal gpu_library_eval" .dev19
#   SESSION_S=540 BIN=.dev19 BEFORE=.dev19before tests/device/lanes.sh experiments/plans/onechunk37.sh
SESSION_S=${SESSION_S:-540}
LANE0="train warmup 40 --motion walk --seed 0 --time-budget 1
  for s in 0 1 2; do
    for m in backflip cartwheel spinkick run walk; do
      train_before \${m}_before_s\$s 40 --motion \$m --seed \$s --time-budget 30
      train \${m}_s\$s 40 --motion \$m --seed \$s --time-budget 30
    done
  done
  grep -h '^setup' \$OUT/runs/*.log | sort | head -40 >> \$OUT/summary.txt
  TEST_TIMEOUT=200 gpu_test gpu_rollout gpu_train gpu_goal gpu_library_eval"
