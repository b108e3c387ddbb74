# Issue 37, 2026-11-29 (seventeenth session), one GPU, the build landed: several snapshots in one
# evaluation (default 8) with the 32-world evaluation's graphs captured at first use (a run that
# evaluates snapshots together never captures them: setup was 0.5-2.8 s longer without it,
# experiments/plans/snapshots37.sh). The GPU tests of the run loop and of the snapshot
# evaluation, then every clip with its committed config, 8 snapshots against 1
# (`--set run.eval_snapshots=1`), seeds 0-2, interleaved.
#   tests/device/stage.sh --only "gpu_rollout gpu_train" .device-w3
#   SESSION_S=480 BIN=.device-w3 tests/device/lanes.sh experiments/plans/snapshots37c.sh   (carry .device-w3)
# Table: python3 experiments/scripts/pairs_table.py runs/ (logs.txz, which lanes.sh packs)
SESSION_S=${SESSION_S:-480}
LANE0="TEST_TIMEOUT=150 gpu_test gpu_rollout gpu_train
  for s in 0 1 2; do for m in backflip cartwheel spinkick run walk; do
    train \${m}_snap1_s\$s 60 --motion \$m --seed \$s --time-budget 30 --set run.eval_snapshots=1
    train \${m}_snap8_s\$s 60 --motion \$m --seed \$s --time-budget 30
  done; done"
