# Issue 37, 2026-11-29 (twentieth session), two GPUs: the two levers of levers37 whose three seeds
# all came out faster than every committed run of that call, GAE lambda 0.95 (committed 0.99, the
# paper's search's value) and 4 epochs (committed 3), and both, on new seeds beside the
# committed config; then lambda 0.95 on the other four clips' committed configs.
# `train --motion M --seed S --time-budget 20`, the build of 714f4b5.
#   SESSION_S=520 BIN=.dev20 tests/device/lanes.sh experiments/plans/confirm37.sh   (nvidia-h200-x2)
SESSION_S=${SESSION_S:-520}
# confirm_lane LANE "SEEDS" "CLIPS": the backflip's four variants seed by seed, then lambda 0.95
# against the committed config on CLIPS (seeds 0-2).
confirm_lane() {
  local lane=$1 seeds=$2 clips=$3 s m
  train "warmup_$lane" 40 --motion walk --seed 0 --time-budget 1
  for s in $seeds; do
    train "backflip_base_s$s" 40 --motion backflip --seed "$s" --time-budget 20
    train "backflip_lambda_s$s" 40 --motion backflip --seed "$s" --time-budget 20 --set ppo.lambda=0.95
    train "backflip_epochs_s$s" 40 --motion backflip --seed "$s" --time-budget 20 --set ppo.epochs=4
    train "backflip_both_s$s" 40 --motion backflip --seed "$s" --time-budget 20 --set ppo.lambda=0.95 --set ppo.epochs=4
  done
  for s in 0 1 2; do
    for m in $clips; do
      train "${m}_base_s$s" 40 --motion "$m" --seed "$s" --time-budget 20
      train "${m}_lambda_s$s" 40 --motion "$m" --seed "$s" --time-budget 20 --set ppo.lambda=0.95
    done
  done
}
LANE0="confirm_lane 0 '3 4 5' 'walk run'"
LANE1="confirm_lane 1 '6 7 8' 'spinkick cartwheel'"
