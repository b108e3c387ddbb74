# Issue 20 on one H100, one call: the per-env kernels in 64-thread blocks and the minibatch
# gather at four columns a thread, checked on the GPU (gpu_env_kernels and gpu_physics against
# f64 and the kinematics plan, gpu_ppo against f64), the whole loop at the committed backflip
# config in `bench full`, the backflip's time to success in 3 seeds, and the 22-clip library
# with the committed configs' new loop settings, seed 1 (tests/device/lanes.sh plan).
#   tests/device/stage.sh --only "gpu_env_kernels gpu_ppo gpu_physics" .device-small
#   BIN=.device-small tests/device/lanes.sh experiments/plans/h100_blocks.sh   (carry .device-small)
SESSION_S=${SESSION_S:-545}
KEEP=${KEEP:-}
FULL='full --motion backflip --envs 4096'
LANE0="gpu_test gpu_env_kernels gpu_ppo gpu_physics; bench full_committed 80 $FULL; train backflip_0 60 --motion backflip --seed 0 --time-budget 45; train backflip_1 60 --motion backflip --seed 1 --time-budget 45; train backflip_2 60 --motion backflip --seed 2 --time-budget 45; train library_all_1 330 --config configs/train/library_all.toml --seed 1"
