# Issue 20 on one H100, one call, the session's final build: the GPU tests the changes touch
# (the update's graph and padded minibatch rows: gpu_ppo, gpu_blas, gpu_latent, gpu_overlap,
# gpu_train; the epilogues and the PD kernels: gpu_env_kernels; rollouts with pd_targets:
# gpu_rollout, gpu_physics, gpu_replay, gpu_divergence, gpu_library_eval, gpu_goal), `bench full`
# at the committed backflip config twice and the backflip in 3 seeds.
#   tests/device/stage.sh --only "gpu_ppo gpu_blas gpu_latent gpu_overlap gpu_train gpu_env_kernels gpu_rollout gpu_physics gpu_replay gpu_divergence gpu_library_eval gpu_goal" .device-small
#   BIN=.device-small tests/device/lanes.sh experiments/plans/h100_issue20_suite.sh   (carry .device-small)
SESSION_S=${SESSION_S:-560}
KEEP=${KEEP:-}
FULL='full --motion backflip --envs 4096'
LANE0="bench full_committed 80 $FULL; train backflip_0 50 --motion backflip --seed 0 --time-budget 40; train backflip_1 50 --motion backflip --seed 1 --time-budget 40; train backflip_2 50 --motion backflip --seed 2 --time-budget 40; bench full_again 80 $FULL; gpu_test gpu_ppo gpu_blas gpu_env_kernels gpu_latent gpu_overlap gpu_rollout gpu_physics gpu_replay gpu_divergence gpu_library_eval gpu_train gpu_goal"
