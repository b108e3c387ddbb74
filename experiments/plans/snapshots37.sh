# Issue 37, 2026-11-29 (seventeenth session), one GPU: several policy snapshots in one evaluation
# (`run.eval_snapshots`, plans for 64-256 worlds committed in 69aa76e; the default 8 in this
# build). Every clip with its committed config and the default 8 snapshots (256 worlds) against
# one snapshot per evaluation (`--set run.eval_snapshots=1`, as before), the backflip also
# against 4 (128 worlds), seeds 0-2, interleaved in one call; first the GPU tests of the run loop
# and of the snapshot evaluation (each group against its snapshot alone).
#   tests/device/stage.sh --only "gpu_rollout gpu_train gpu_divergence gpu_tensorboard" .device-w2
#   SESSION_S=540 BIN=.device-w2 tests/device/lanes.sh experiments/plans/snapshots37.sh   (carry .device-w2)
# Table: python3 experiments/scripts/pairs_table.py runs/ (logs.txz, which lanes.sh packs)
SESSION_S=${SESSION_S:-540}
LANE0="TEST_TIMEOUT=150 gpu_test gpu_rollout gpu_train
  for s in 0 1 2; do for m in backflip cartwheel spinkick run walk; do
    train \${m}_snap1_s\$s 60 --motion \$m --seed \$s --time-budget 30 --set run.eval_snapshots=1
    train \${m}_snap8_s\$s 60 --motion \$m --seed \$s --time-budget 30
    [ \$m = backflip ] && train \${m}_snap4_s\$s 60 --motion \$m --seed \$s --time-budget 30 --set run.eval_snapshots=4
  done; done
  TEST_TIMEOUT=120 gpu_test gpu_divergence gpu_tensorboard"
