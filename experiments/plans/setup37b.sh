# Issue 37, 2026-11-29 (eighteenth session), one GPU: the setup with cuBLAS opened on a thread of
# its own while the training rollout loads, against the build before it (.dev18before, the
# setup line's breakdown alone) in the same call, after a first run that fills the driver's
# JIT cache; the backflip and the walk, seeds 0-2 interleaved; then gpu_train.
#   tests/device/stage.sh --only gpu_train .dev18c; .dev18before/instantmimic.xz: the build before
#   SESSION_S=300 BIN=.dev18c BEFORE=.dev18before tests/device/lanes.sh experiments/plans/setup37b.sh
SESSION_S=${SESSION_S:-300}
LANE0="train warmup 40 --motion walk --seed 0 --time-budget 1
  for s in 0 1 2; do
    train_before backflip_before_s\$s 40 --motion backflip --seed \$s --time-budget 30
    train backflip_s\$s 40 --motion backflip --seed \$s --time-budget 30
    train_before walk_before_s\$s 20 --motion walk --seed \$s --time-budget 30
    train walk_s\$s 20 --motion walk --seed \$s --time-budget 30
  done
  grep 'setup [0-9.]* s (plans' \$OUT/runs/*.log | tee -a \$OUT/summary.txt
  TEST_TIMEOUT=150 gpu_test gpu_train"
