# Issue 37, 2026-11-29 (twentieth session), one GPU: the GPU tests that read the committed
# backflip config, on the session's last code (the backflip's GAE lambda 0.95, b36c263).
#   tests/device/stage.sh --only "gpu_train gpu_ppo gpu_tensorboard" .dev20d
#   SESSION_S=200 BIN=.dev20d tests/device/lanes.sh experiments/plans/gpu_tests20.sh
SESSION_S=${SESSION_S:-200}
LANE0="TEST_TIMEOUT=150 gpu_test gpu_train gpu_tensorboard gpu_ppo"
