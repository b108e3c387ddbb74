# Issue 20 on one H100, one call: the update's minibatch steps as a dependency graph (gathers
# one step ahead into two buffers; schedule and gradient norms as branches), elu_input_gradient
# loading 16 rows before it stores, bias_elu 4 columns a thread. GPU tests (gpu_env_kernels:
# the epilogues against f64; gpu_ppo: the pipelined update against the sequential one; gpu_blas),
# `bench full` at the committed backflip config, the backflip's time to success in 3 seeds.
#   tests/device/stage.sh --only "gpu_env_kernels gpu_ppo gpu_blas" .device-small
#   BIN=.device-small tests/device/lanes.sh experiments/plans/h100_pipeline.sh   (carry .device-small)
SESSION_S=${SESSION_S:-400}
KEEP=${KEEP:-}
FULL='full --motion backflip --envs 4096'
LANE0="gpu_test gpu_env_kernels gpu_ppo gpu_blas; bench full_committed 80 $FULL; train backflip_0 50 --motion backflip --seed 0 --time-budget 40; train backflip_1 50 --motion backflip --seed 1 --time-budget 40; train backflip_2 50 --motion backflip --seed 2 --time-budget 40"
