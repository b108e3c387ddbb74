# Issue 19 on 4 GPUs, the call after latent_at_bar.sh: the goal task on the decoder distilled
# from the absolute-target tracker with the library keys (run directories latent_abs and
# abs_tracker, carried back in $R), and that tracker continued to the bar (tests/device/lanes.sh
# plan).
# - GPUs 0-2: the goal task, seeds 0-2 (committed keys: scale 3, init_log_std -0.5; 7.56 median
#   on the earlier decoder), then one variant each on seed 0: init_log_std 0.0, scale 4,
#   kl_threshold 0.05.
# - GPU 3: the absolute-target tracker resumed until the bar (it stood at 0.914, 21 of 22 clips
#   after 213 s), then the latent controller distilled from it (KEEP: the next goal decoder).
#   mkdir -p .device-runs && tar xJf run_latent_abs.txz -C .device-runs && tar xJf run_abs_tracker.txz -C .device-runs
#   BIN=.device-train tests/device/lanes.sh experiments/plans/goal_new_decoder.sh   (carry .device-train and .device-runs)
R=${R:-$PWD/.device-runs}
SESSION_S=${SESSION_S:-540}
KEEP=${KEEP:-"latent_abs2 abs_tracker_bar"}
DECODER=$(ls "$R"/latent_abs/checkpoints/*.safetensors 2>/dev/null | sort | tail -1)
GOAL="--config configs/goal/reach_latent.toml --time-budget 60 --set run.eval_interval=30 --decoder $DECODER"
LANE0="train goal_0 128 $GOAL --seed 0; train goal_std0_0 128 $GOAL --seed 0 --set policy.init_log_std=0.0"
LANE1="train goal_1 128 $GOAL --seed 1; train goal_scale4_0 128 $GOAL --seed 0 --set goal.latent_action_scale=4.0"
LANE2="train goal_2 128 $GOAL --seed 2; train goal_kl05_0 128 $GOAL --seed 0 --set ppo.kl_threshold=0.05"
LANE3="resume abs_tracker_bar $R/abs_tracker 270; train latent_abs2 240 --config configs/latent/all.toml --time-budget 200 --set env.action_mode=absolute --teacher \"\$(newest_checkpoint abs_tracker_bar)\""
