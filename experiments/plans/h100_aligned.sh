# Issue 20 on one H100, one call: the update's minibatch observations in rows of a multiple of
# 16 bytes (cuBLAS's aligned kernels for the first layer), bias_elu back to one element a
# thread, the rollout's breakdown with the body kinematics apart. GPU tests (gpu_blas: padded
# rows against f64; gpu_ppo: the update against f64 and the sequential one; gpu_env_kernels;
# gpu_rollout), `bench full` at the committed backflip config, the backflip in 3 seeds.
#   tests/device/stage.sh --only "gpu_env_kernels gpu_ppo gpu_blas gpu_rollout" .device-small
#   BIN=.device-small tests/device/lanes.sh experiments/plans/h100_aligned.sh   (carry .device-small)
SESSION_S=${SESSION_S:-400}
KEEP=${KEEP:-}
FULL='full --motion backflip --envs 4096'
LANE0="gpu_test gpu_blas gpu_ppo gpu_env_kernels gpu_rollout; bench full_committed 80 $FULL; train backflip_0 50 --motion backflip --seed 0 --time-budget 40; train backflip_1 50 --motion backflip --seed 1 --time-budget 40; train backflip_2 50 --motion backflip --seed 2 --time-budget 40"
