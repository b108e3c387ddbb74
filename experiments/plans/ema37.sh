# Issue 37, the backflip's tail: the evaluation on an exponential moving average of the actor's
# parameters (experiment build, branch exp-ema: `ppo.evaluation_average`, the decay per
# iteration), and the last GPU test files of the session's code, on 2 GPUs in one call
# (tests/device/lanes.sh plan).
# - Both GPUs first: gpu_world (a world of processes; rank 0's evaluation stops when decided).
# - GPU 0: gpu_goal_latent, then the backflip seeds 0-2 with decay 0.8.
# - GPU 1: the backflip seeds 0-2, the committed config (this call's baseline), decay 0.9 and 0.95.
#   tests/device/stage.sh --only "gpu_world gpu_goal_latent" .device-s3; the experiment build's
#   stripped binary added as instantmimic_ema, repacked with XZ_OPT=-9
#   BIN=.device-s3 tests/device/lanes.sh experiments/plans/ema37.sh   (carry .device-s3)
SESSION_S=${SESSION_S:-520}
FIRST='INSTANTMIMIC_NO_SKIP=1 INSTANTMIMIC_BIN=$BIN/instantmimic timeout 200 $BIN/gpu_world --nocapture --test-threads 1 > $OUT/test_gpu_world.log 2>&1; echo "gpu_world rc $?"; grep "test result" $OUT/test_gpu_world.log'
bf() { # NAME SEED ARGS...: the backflip with the staged build
  local name=$1 seed=$2; shift 2
  train "${name}_s$seed" 150 --motion backflip --seed "$seed" --time-budget 40 "$@"
}
bf_ema() { # DECAY SEED: the experiment build, staged beside the others as instantmimic_ema
  train_with "$BIN/instantmimic_ema" "backflip_ema${1#0.}_s$2" 150 --motion backflip --seed "$2" --time-budget 40 --set ppo.evaluation_average="$1"
}
LANE0="gpu_test gpu_goal_latent; for s in 0 1 2; do bf_ema 0.8 \$s; done"
LANE1="for s in 0 1 2; do bf backflip \$s; bf_ema 0.9 \$s; bf_ema 0.95 \$s; done"
