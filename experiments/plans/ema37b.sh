# Issue 37: the evaluation on the actor's parameter average (experiment build, branch exp-ema,
# `ppo.evaluation_average` 0.9) against the committed config on five more seeds, 3-7, on 2 GPUs
# (tests/device/lanes.sh plan; each GPU runs both settings of its seeds, one after the other).
#   the binaries of ema37.sh: BIN=.device-s3 tests/device/lanes.sh experiments/plans/ema37b.sh
SESSION_S=${SESSION_S:-300}
bf() { train "backflip_s$1" 150 --motion backflip --seed "$1" --time-budget 40; }
bf_ema() { train_with "$BIN/instantmimic_ema" "backflip_ema9_s$1" 150 --motion backflip --seed "$1" --time-budget 40 --set ppo.evaluation_average=0.9; }
LANE0="for s in 3 5 7; do bf \$s; bf_ema \$s; done"
LANE1="for s in 4 6; do bf \$s; bf_ema \$s; done"
