# Issue 37, 2026-11-28 (fourteenth session): the ballistic flights on backflip seeds 3-6 beside
# the baseline of the same seed, with the device time left after mirror37*.sh (one H200).
#   BIN=.device-s3 tests/device/lanes.sh experiments/plans/ballistic37.sh   (carry .device-s3)
SESSION_S=${SESSION_S:-270}
BALLISTIC="--set env.reference_flight=ballistic"
LANE0="for s in 3 4 5 6; do
    train backflip_s\$s 45 --motion backflip --seed \$s --time-budget 30
    train backflip_ballistic_s\$s 45 --motion backflip --seed \$s --time-budget 30 $BALLISTIC
  done"
