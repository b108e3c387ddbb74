# Issue 20 on one H100, one call: the PD targets once per control step (`pd_targets`) and the
# torques before every substep from them (`pd_control`). GPU tests (gpu_env_kernels: both
# kernels against f64; gpu_rollout; gpu_train; gpu_ppo), `bench full` at the committed backflip
# config twice, the backflip in 3 seeds, and the other four clips once.
#   tests/device/stage.sh --only "gpu_env_kernels gpu_rollout gpu_train gpu_ppo" .device-small
#   BIN=.device-small tests/device/lanes.sh experiments/plans/h100_pd_targets.sh   (carry .device-small)
SESSION_S=${SESSION_S:-480}
KEEP=${KEEP:-}
FULL='full --motion backflip --envs 4096'
LANE0="gpu_test gpu_env_kernels gpu_ppo; bench full_committed 80 $FULL; train backflip_0 50 --motion backflip --seed 0 --time-budget 40; train backflip_1 50 --motion backflip --seed 1 --time-budget 40; train backflip_2 50 --motion backflip --seed 2 --time-budget 40; bench full_again 80 $FULL; train run_0 30 --motion run --seed 0; train walk_0 30 --motion walk --seed 0; train spinkick_0 30 --motion spinkick --seed 0; train cartwheel_0 30 --motion cartwheel --seed 0; gpu_test gpu_rollout gpu_train"
