# Issue 19 on 4 GPUs, one call: the library tracker's frames remedies, the next goal decoder's
# teacher, and the goal task's latent action scale (tests/device/lanes.sh plan).
# - GPU 0 distills the committed latent controller (kl_weight 0.001, 200 s) from the
#   absolute-target tracker in $R (.device-runs/all_absolute.safetensors), then trains the goal
#   task on it with goal.latent_action_scale 2 and 3 (seed 0; 2.0 gave 5.91 against 4.28 on the
#   0.01 decoder, 2026-11-26).
# - GPUs 1 and 2: env.phase_share = "frames" and 60-step training episodes (library_frames.sh
#   says why), against the floor's base of 2026-11-26 (0.766, 17 of 22 clips at 403 s).
# - GPU 3: the absolute-target tracker again, now with the library configs' log-std floor: the
#   teacher of the next decoder.
# Each library run has the 900-s budget and stops at the call's end with a checkpoint,
# kept (KEEP) to be resumed in the next call.
#   tests/device/stage.sh --train-only .device-train
#   BIN=.device-train tests/device/lanes.sh experiments/plans/library_frames_goal.sh   (carry .device-train and .device-runs)
R=${R:-$PWD/.device-runs}
SESSION_S=${SESSION_S:-530}
KEEP=${KEEP:-"frames episodes60 absolute_floor latent"}
LIB='--config configs/train/library_all.toml --time-budget 900'
# Evaluations every 30 iterations rather than 10: 40 s less wall time, the same training.
GOAL="--config configs/goal/reach_latent.toml --time-budget 60 --set run.eval_interval=30"
DECODER='--decoder "$(newest_checkpoint latent)"'
LANE0="train latent 280 --config configs/latent/all.toml --set env.action_mode=absolute --teacher $R/all_absolute.safetensors --time-budget 200; train goal_scale2_0 130 $GOAL --seed 0 --set goal.latent_action_scale=2.0 $DECODER; train goal_scale3_0 130 $GOAL --seed 0 --set goal.latent_action_scale=3.0 $DECODER"
LANE1="train frames 530 $LIB --set env.phase_share=frames"
LANE2="train episodes60 530 $LIB --set env.max_episode_steps=60"
LANE3="train absolute_floor 530 $LIB --set env.action_mode=absolute"
