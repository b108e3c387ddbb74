# Issue 19, the goal task through a frozen latent decoder (tests/device/lanes.sh plan; 4 GPUs,
# one call). On 2026-11-26 a decoder distilled with latent.kl_weight 0.01 gave 4.28-4.50 goals
# per 10-s episode after 60 s (3 seeds), one with 0.001 (now committed) 6.00 and a residual
# scale of 2 on the 0.01 decoder 5.91 (seed 0 each); the issue asks 8. GPU 0 distills the
# committed latent controller (kl_weight 0.001) from the absolute-target tracker carried in
# $R (the 407-s one of 2026-11-26: .device-runs/all_absolute.safetensors, carried with
# .device-runs), then every GPU trains the goal task on it: the committed keys (seeds 0-2) and
# the residual scale 2 (seed 0), which were each worth about 1.5 goals alone.
#   BIN=.device-bin tests/device/lanes.sh tests/device/plans/goal_latent.sh   (carry .device-runs)
R=${R:-$PWD/.device-runs}
SESSION_S=${SESSION_S:-530}
KEEP=${KEEP:-latent}
GOAL="--config configs/goal/reach_latent.toml --time-budget 60"
READY='wait_for "$OUT/runs/latent/summary.json" 420'
DECODER='--decoder "$(newest_checkpoint latent)"'
LANE0="train latent 380 --config configs/latent/all.toml --set env.action_mode=absolute --teacher $R/all_absolute.safetensors --time-budget 300; train goal_0 140 $GOAL --seed 0 $DECODER"
LANE1="$READY && train goal_1 140 $GOAL --seed 1 $DECODER"
LANE2="$READY && train goal_2 140 $GOAL --seed 2 $DECODER"
LANE3="$READY && train goal_scale2_0 140 $GOAL --seed 0 --set goal.latent_action_scale=2.0 $DECODER"
