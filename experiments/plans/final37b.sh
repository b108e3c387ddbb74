# Issue 37, 2026-11-29 (sixteenth session), one GPU: the GPU tests of the session's last code
# (the unrolled loop and the evaluation beside training deleted; bench physics --plan and
# --beside-envs added): the physics replay against MuJoCo Warp (gpu_physics), the rollout
# (gpu_rollout), training runs and bench full (gpu_train).
#   tests/device/stage.sh --only "gpu_physics gpu_rollout gpu_train" .dev5
#   BIN=.dev5 tests/device/lanes.sh experiments/plans/final37b.sh   (carry .dev5)
SESSION_S=${SESSION_S:-540}
TEST_TIMEOUT=300
LANE0="gpu_test gpu_physics gpu_rollout gpu_train"
