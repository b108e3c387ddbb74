# Issue 37, 2026-11-29 (twentieth session), two GPUs: the backflip's frames, twelve levers not yet
# tried on the current code (horizon 4, the reduced training solver, the evaluation on an
# average of the actor), each with seeds 0-2 beside the committed config on the same GPU;
# `train --motion backflip --seed S --time-budget 20`, the build of 714f4b5.
#   tests/device/stage.sh --only "gpu_train" .dev20
#   SESSION_S=540 BIN=.dev20 tests/device/lanes.sh experiments/plans/levers37.sh   (nvidia-h200-x2)
SESSION_S=${SESSION_S:-540}
# levers_lane LANE KEY=VALUE...: the committed config and each lever, seed by seed.
levers_lane() {
  local lane=$1 s i kv
  shift
  train "warmup_$lane" 40 --motion walk --seed 0 --time-budget 1
  for s in 0 1 2; do
    train "base${lane}_s$s" 40 --motion backflip --seed "$s" --time-budget 20
    i=0
    for kv in "$@"; do
      i=$((i + 1))
      train "lever${lane}_${i}_s$s" 40 --motion backflip --seed "$s" --time-budget 20 --set "$kv"
    done
  done
}
LANE0="levers_lane 0 policy.init_log_std=-1.0 policy.init_log_std=-2.0 ppo.epochs=4 ppo.epochs=2 ppo.minibatches=8 ppo.gamma=0.95"
LANE1="levers_lane 1 ppo.lambda=0.95 ppo.entropy_coef=0.001 obs.future_frames=3 ppo.value_coef=2 env.action_scale=1.0 env.phase_floor=0.3"
