# Issue 19 on 4 GPUs, one call: env.clip_base_share, the frames run resumed toward 15 minutes,
# and the goal task's latent action scale over seeds (tests/device/lanes.sh plan).
# On 2026-11-26 (4 H200, library_frames_goal.sh) env.phase_share = "frames" took the 22-clip
# tracker to 0.881 with 19 clips at 0.8 after 406 s (the floor's base: 0.766, 17), but the
# backflip still had 7% of the frames (a learnt walk 4-5%) and stayed at 0.01-0.09: the
# sampler's per-step floor outweighs every clip's failures per step. env.clip_base_share s gives
# clip c w_c (s + (1 - s) h_c / H) of the frames instead (docs/library.md, "The reset sampler").
# - GPUs 0 and 1: frames with s = 0.3 and 0.5 (seed 0; 900-s budget, kept to be resumed).
# - GPU 2: the frames run of that call ($R/frames) resumed toward its 900 s.
# - GPU 3: the goal task on the latent controller of that call ($R/latent_kl001.safetensors,
#   kl_weight 0.001; 6.72 with scale 2, 6.84 with 3 on seed 0): scale 3 on seeds 1 and 2, then
#   scale 3 with the head's init_log_std -0.5 and with learning rate 1e-3 (seed 0).
#   tests/device/stage.sh --train-only .device-train
#   BIN=.device-train tests/device/lanes.sh experiments/plans/library_clip_share.sh   (carry .device-train and .device-runs)
R=${R:-$PWD/.device-runs}
SESSION_S=${SESSION_S:-530}
KEEP=${KEEP:-"clip30 clip50 frames_resumed"}
LIB='--config configs/train/library_all.toml --time-budget 900 --set env.phase_share=frames'
GOAL="--config configs/goal/reach_latent.toml --time-budget 60 --set run.eval_interval=30 --decoder $R/latent_kl001.safetensors --set goal.latent_action_scale=3.0"
LANE0="train clip30 530 $LIB --set env.clip_base_share=0.3"
LANE1="train clip50 530 $LIB --set env.clip_base_share=0.5"
LANE2="resume frames_resumed $R/frames 530"
LANE3="train goal_scale3_1 128 $GOAL --seed 1; train goal_scale3_2 128 $GOAL --seed 2; train goal_scale3_std05_0 128 $GOAL --seed 0 --set policy.init_log_std=-0.5; train goal_scale3_lr1e3_0 128 $GOAL --seed 0 --set ppo.learning_rate=1e-3"
