# Issue 19 on 4 GPUs, the call after goal_new_decoder.sh: the goal task on the decoder distilled
# from the absolute-target tracker at the bar (latent_abs2, itself at the bar: 0.978, 22 of 22
# clips), 3 seeds with the committed keys, beside the GPU test of the latent goal task (cut by
# the deadline in latent_at_bar.sh's call) (tests/device/lanes.sh plan).
#   mkdir -p .device-runs && tar xJf run_latent_abs2.txz -C .device-runs
#   BIN=.device-small tests/device/lanes.sh experiments/plans/goal_bar_decoder.sh   (carry .device-small and .device-runs)
R=${R:-$PWD/.device-runs}
SESSION_S=${SESSION_S:-330}
KEEP=${KEEP:-}
DECODER=$(ls "$R"/latent_abs2/checkpoints/*.safetensors 2>/dev/null | sort | tail -1)
GOAL="--config configs/goal/reach_latent.toml --time-budget 60 --set run.eval_interval=30 --decoder $DECODER"
LANE0="train goal_bar_0 128 $GOAL --seed 0"
LANE1="train goal_bar_1 128 $GOAL --seed 1"
LANE2="train goal_bar_2 128 $GOAL --seed 2"
LANE3="gpu_test gpu_goal_latent"
