# Issue 20 on one H100, one call: the first layer's product in cuBLAS over the first K - K % 4
# inputs (aligned rows: the update's minibatch) and the last K % 4 in the `bias_elu` epilogue,
# against main's build (`bench full`, alternating, twice), with the GPU tests of the changed
# kernels and paths and the backflip's time to success over 3 seeds.
#   here:  tests/device/stage.sh --only "gpu_env_kernels gpu_ppo gpu_blas gpu_latent gpu_rollout gpu_train" .device-small
#          (main's build in .device-small/before/instantmimic.xz, see h100_lanes.sh)
#   there: BEFORE=.device-small/before BIN=.device-small tests/device/lanes.sh tests/device/plans/h100_tail.sh
SESSION_S=${SESSION_S:-540}
FULL='full --motion backflip --envs 4096'
LANE0="gpu_test gpu_env_kernels gpu_blas gpu_ppo; bench_before full_before_1 80 $FULL; bench full_after_1 80 $FULL; bench_before full_before_2 80 $FULL; bench full_after_2 80 $FULL; train backflip_0 50 --motion backflip --seed 0 --time-budget 40; train backflip_1 50 --motion backflip --seed 1 --time-budget 40; train backflip_2 50 --motion backflip --seed 2 --time-budget 40"
