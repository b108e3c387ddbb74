# Issue 20 on one H100, one call: the GPU tests the session's changes could touch and the last
# calls did not run, on the final build (gpu_ppo, gpu_blas, gpu_env_kernels, gpu_latent,
# gpu_physics and gpu_rollout ran in the calls before on the same kernels), longest last
# (tests/device/lanes.sh plan). gpu_multi_gpu needs two GPUs.
#   tests/device/stage.sh --only "gpu_train gpu_library_eval gpu_replay gpu_divergence gpu_cuda gpu_reference_table gpu_rollout gpu_physics gpu_overlap gpu_goal gpu_goal_latent" .device-small
#   BIN=.device-small tests/device/lanes.sh experiments/plans/h100_suite.sh   (carry .device-small)
SESSION_S=${SESSION_S:-530}
TEST_TIMEOUT=${TEST_TIMEOUT:-240}
LANE0="gpu_test gpu_cuda gpu_reference_table gpu_rollout gpu_physics gpu_divergence gpu_replay gpu_overlap gpu_library_eval gpu_train gpu_goal gpu_goal_latent"
