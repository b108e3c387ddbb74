# Issue 19 on 4 GPUs, one call: latent controllers distilled from library trackers at the
# issue's bar (tests/device/lanes.sh plan). On 2026-11-26 the 22-clip tracker with the library's
# sampler keys met the bar in 196-222 s (3 seeds, 4 H200), but every latent controller so far was
# distilled from a tracker at 0.58-0.73, and the goal task's decoder from the 0.58 one.
# - GPU 0: the absolute-target tracker with the library keys (the goal decoder's teacher), then
#   the committed latent controller distilled from it (200 s): the next goal decoder (KEEP).
# - GPU 1: the residual tracker (configs/train/library_all.toml as committed), then the latent
#   controller of configs/latent/all.toml from it: "within 5 points of the tracker".
# - GPU 2: the 13 shipped clips (library_shipped.toml) with the keys, then the held-out tracker
#   (library_held_out.toml, the teacher of docs/latent.md's unseen clips).
# - GPU 3: GPU tests (gpu_train with bench full of a library), then the goal task on the
#   decoder carried in $R (latent_kl001, 7.56 median with the committed keys) with
#   init_log_std 0.0 and with scale 4 (seed 0).
# A tracker stops at success or at its lane's wall limit with a checkpoint; the latent run then
# distils from the newest checkpoint either way.
#   tests/device/stage.sh --only "gpu_goal_latent gpu_library_eval gpu_latent gpu_rollout gpu_train" .device-small
#   BIN=.device-small tests/device/lanes.sh tests/device/plans/latent_at_bar.sh   (carry .device-small and .device-runs)
R=${R:-$PWD/.device-runs}
SESSION_S=${SESSION_S:-530}
KEEP=${KEEP:-"latent_abs abs_tracker latent_res"}
LIB='--config configs/train/library_all.toml'
LATENT='--config configs/latent/all.toml --time-budget 200'
GOAL="--config configs/goal/reach_latent.toml --time-budget 60 --set run.eval_interval=30 --decoder $R/latent_kl001.safetensors"
LANE0="train abs_tracker 290 $LIB --set env.action_mode=absolute; train latent_abs 235 $LATENT --set env.action_mode=absolute --teacher \"\$(newest_checkpoint abs_tracker)\""
LANE1="train tracker 290 $LIB; train latent_res 235 $LATENT --teacher \"\$(newest_checkpoint tracker)\""
LANE2="train shipped 290 --config configs/train/library_shipped.toml; train held_out 235 --config configs/train/library_held_out.toml"
LANE3="gpu_test gpu_goal_latent gpu_library_eval gpu_latent gpu_rollout gpu_train; train goal_std0_0 128 $GOAL --seed 0 --set policy.init_log_std=0.0; train goal_scale4_0 128 $GOAL --seed 0 --set goal.latent_action_scale=4.0"
