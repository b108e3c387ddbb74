# Issue 37, 2026-11-29 (fifteenth session), one GPU: the GPU tests of the session's last code
# (the ballistic refit and the assist force deleted) for what it touched: training runs and
# their motion loading (gpu_train), the rollout (gpu_rollout), the env kernels (gpu_env_kernels).
#   tests/device/stage.sh --only "gpu_train gpu_rollout gpu_env_kernels" .device-f1
#   BIN=.device-f1 tests/device/lanes.sh experiments/plans/final37.sh   (carry .device-f1)
SESSION_S=${SESSION_S:-540}
TEST_TIMEOUT=300
LANE0="gpu_test gpu_env_kernels gpu_rollout gpu_train"
