# Issue 19 on 4 GPUs, one short call (what was left of a session's device time): seeds 1 and 2
# of the library tracker with env.clip_base_share 0.3 (seed 0 met the bar at 196.5 s,
# library_clip_share.sh), the goal head's init_log_std -0.5 on seeds 1 and 2 (seed 0: 7.56
# goals), and the GPU tests of the new sampler key (tests/device/lanes.sh plan).
#   tests/device/stage.sh --only "gpu_env_kernels gpu_train" .device-small
#   BIN=.device-small tests/device/lanes.sh experiments/plans/library_clip_share_seeds.sh   (carry .device-small and .device-runs)
R=${R:-$PWD/.device-runs}
SESSION_S=${SESSION_S:-340}
KEEP=${KEEP:-}
LIB='--config configs/train/library_all.toml --time-budget 900 --set env.phase_share=frames --set env.clip_base_share=0.3'
GOAL="--config configs/goal/reach_latent.toml --time-budget 60 --set run.eval_interval=30 --decoder $R/latent_kl001.safetensors --set goal.latent_action_scale=3.0"
LANE0="train clip30_1 340 $LIB --seed 1"
LANE1="train clip30_2 340 $LIB --seed 2"
LANE2="train goal_std05_1 128 $GOAL --seed 1 --set policy.init_log_std=-0.5; train goal_std05_2 128 $GOAL --seed 2 --set policy.init_log_std=-0.5"
LANE3="gpu_test gpu_env_kernels gpu_train"
