# Issue 37, 2026-11-29 (eighteenth session), one GPU: the issue's lever "reference-state
# initialization from reachable states, e.g. a short simulated rollout from an earlier phase":
# env.flight_starts = "take_off" moves every training start drawn inside a clip's flight (found in
# its table's rows) to the take-off (lead 0) or 0.15 s before it, so the body enters the flight by
# its own motion. Against the committed config of the same seed in the same call, seeds 0-2; the
# backflip first, then the two other clips with flights (spinkick, run); the GPU tests of the
# reset kernel and of the rollouts between them.
#   tests/device/stage.sh --only "gpu_env_kernels gpu_rollout" .dev18
#   SESSION_S=560 BIN=.dev18 tests/device/lanes.sh experiments/plans/flights37.sh   (carry .dev18)
SESSION_S=${SESSION_S:-560}
TAKE_OFF="--set env.flight_starts=take_off"
LANE0="for s in 0 1 2; do
    train backflip_s\$s 40 --motion backflip --seed \$s --time-budget 30
    train backflip_takeoff_s\$s 40 --motion backflip --seed \$s --time-budget 30 $TAKE_OFF
    train backflip_lead15_s\$s 40 --motion backflip --seed \$s --time-budget 30 $TAKE_OFF --set env.flight_start_lead=0.15
  done
  TEST_TIMEOUT=150 gpu_test gpu_env_kernels gpu_rollout
  for s in 0 1 2; do
    train spinkick_s\$s 25 --motion spinkick --seed \$s --time-budget 15
    train spinkick_takeoff_s\$s 25 --motion spinkick --seed \$s --time-budget 15 $TAKE_OFF
    train run_s\$s 20 --motion run --seed \$s --time-budget 15
    train run_takeoff_s\$s 20 --motion run --seed \$s --time-budget 15 $TAKE_OFF
  done"
