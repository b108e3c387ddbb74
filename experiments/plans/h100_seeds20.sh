# Issue 20 on one H100, one call: the backflip's time to success with main's build and with the
# kept changes of next/issue20, seeds 0-7, alternating (before, after) seed by seed, so that the
# machine's drift falls on both arms alike. Three seeds per arm (2026-11-27) could not tell a
# 3% difference from the spread that the update's atomics give runs of one configuration.
#   here:  as h100_final20.sh
#   there: BEFORE=.device-small/before BIN=.device-small tests/device/lanes.sh experiments/plans/h100_seeds20.sh
SESSION_S=${SESSION_S:-570}
LANE0=""
for seed in 0 1 2 3 4 5 6 7; do
  LANE0="$LANE0 train_before before_$seed 40 --motion backflip --seed $seed --time-budget 30; train after_$seed 40 --motion backflip --seed $seed --time-budget 30;"
done
