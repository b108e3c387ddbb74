# Issue 19 on one H100 (nvidia-h100-x1: every multi-GPU call of 2026-11-26 got H200s): the
# 22-clip tracker to the bar (seed 0), then the goal task on the decoder distilled from the
# absolute tracker at the bar (latent_abs2 in $R), seed 0 (tests/device/lanes.sh plan).
#   mkdir -p .device-runs && tar xJf run_latent_abs2.txz -C .device-runs
#   BIN=.device-train tests/device/lanes.sh experiments/plans/h100_bar.sh   (carry .device-train and .device-runs)
R=${R:-$PWD/.device-runs}
SESSION_S=${SESSION_S:-530}
KEEP=${KEEP:-}
DECODER=$(ls "$R"/latent_abs2/checkpoints/*.safetensors 2>/dev/null | sort | tail -1)
LANE0="train tracker_h100 410 --config configs/train/library_all.toml --seed 0; train goal_h100 120 --config configs/goal/reach_latent.toml --time-budget 60 --set run.eval_interval=30 --decoder $DECODER --seed 0"
