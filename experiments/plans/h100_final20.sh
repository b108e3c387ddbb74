# Issue 20 on one H100, one call: the kept changes of next/issue20 (reset_masked one thread per
# env and lane; the reward's squared errors in 8 lanes per env; Adam's per-step factors once per
# step) against main's build (`bench full`, alternating, twice each), the GPU tests of every
# changed path, the backflip's time to success over 3 seeds and the other four clips' seed 0.
#   here:  tests/device/stage.sh --only "gpu_env_kernels gpu_ppo gpu_blas gpu_latent gpu_rollout gpu_train" .device-small
#          (main's build in .device-small/before/instantmimic.xz, see h100_lanes.sh)
#   there: BEFORE=.device-small/before BIN=.device-small tests/device/lanes.sh experiments/plans/h100_final20.sh
SESSION_S=${SESSION_S:-560}
FULL='full --motion backflip --envs 4096'
LANE0="gpu_test gpu_env_kernels gpu_blas gpu_ppo gpu_rollout gpu_latent; bench_before full_before_1 80 $FULL; bench full_after_1 80 $FULL; bench_before full_before_2 80 $FULL; bench full_after_2 80 $FULL; train backflip_0 50 --motion backflip --seed 0 --time-budget 40; train backflip_1 50 --motion backflip --seed 1 --time-budget 40; train backflip_2 50 --motion backflip --seed 2 --time-budget 40; train run_0 30 --motion run --seed 0; train walk_0 30 --motion walk --seed 0; train spinkick_0 30 --motion spinkick --seed 0; train cartwheel_0 30 --motion cartwheel --seed 0; gpu_test gpu_train"
