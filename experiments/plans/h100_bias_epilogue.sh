# Issue 20 on one H100, one call: the hidden layers' bias gradients in elu_input_gradient's
# epilogue (cuBLAS path), checked on the GPU (gpu_blas: every GEMM path of an MLP against f64
# and Warp tiles; gpu_env_kernels against f64; gpu_ppo; gpu_latent, whose distillation shares
# the backward), the whole loop at the committed backflip config in `bench full` twice, and the
# backflip's time to success in 3 seeds (tests/device/lanes.sh plan).
#   tests/device/stage.sh --only "gpu_env_kernels gpu_ppo gpu_blas gpu_latent" .device-small
#   BIN=.device-small tests/device/lanes.sh experiments/plans/h100_bias_epilogue.sh   (carry .device-small)
SESSION_S=${SESSION_S:-540}
KEEP=${KEEP:-}
FULL='full --motion backflip --envs 4096'
LANE0="gpu_test gpu_blas gpu_env_kernels gpu_ppo; bench full_committed 80 $FULL; train backflip_0 60 --motion backflip --seed 0 --time-budget 45; train backflip_1 60 --motion backflip --seed 1 --time-budget 45; train backflip_2 60 --motion backflip --seed 2 --time-budget 45; bench full_again 80 $FULL; gpu_test gpu_latent"
