# Issue 37, 2026-11-29 (seventeenth session), one GPU, the session's last code (0ab6749: the reset
# launched through one path for a rollout's rows and a snapshot evaluation's groups): the GPU
# tests of the rollouts and of the run loop, then the backflip and the walk with the committed
# configs (8 snapshots per evaluation, the default), seed 0.
#   tests/device/stage.sh --only "gpu_rollout gpu_train" .device-w4
#   SESSION_S=200 BIN=.device-w4 tests/device/lanes.sh experiments/plans/final37c.sh   (carry .device-w4)
SESSION_S=${SESSION_S:-200}
LANE0="TEST_TIMEOUT=120 gpu_test gpu_rollout gpu_train
  train backflip_s0 40 --motion backflip --seed 0 --time-budget 30
  train walk_s0 20 --motion walk --seed 0 --time-budget 30"
