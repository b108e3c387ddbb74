# Issue 20 on one H100, one call: `observe` with 16 threads per env checked on the GPU
# (gpu_env_kernels against f64; gpu_ppo, gpu_rollout, gpu_overlap with the new defaults), the
# whole loop at the committed backflip config (now fused kinematics, TF32 GEMMs and concurrent
# networks) in `bench full`, the backflip's time to success in 3 seeds and the four other
# tuned clips in one, as committed (tests/device/lanes.sh plan).
#   tests/device/stage.sh --only "gpu_env_kernels gpu_ppo gpu_rollout gpu_overlap" .device-small
#   BIN=.device-small tests/device/lanes.sh experiments/plans/h100_observe.sh   (carry .device-small)
SESSION_S=${SESSION_S:-540}
KEEP=${KEEP:-}
FULL='full --motion backflip --envs 4096'
LANE0="gpu_test gpu_env_kernels; bench full_committed 80 $FULL; train backflip_0 60 --motion backflip --seed 0 --time-budget 45; train backflip_1 60 --motion backflip --seed 1 --time-budget 45; train backflip_2 60 --motion backflip --seed 2 --time-budget 45; train run_0 40 --motion run --seed 0; train walk_0 40 --motion walk --seed 0; train spinkick_0 45 --motion spinkick --seed 0; train cartwheel_0 50 --motion cartwheel --seed 0; gpu_test gpu_ppo gpu_rollout gpu_overlap"
