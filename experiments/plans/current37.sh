# 2026-11-29 (fifteenth session), one GPU: the committed configs on the session's last code
# (8da7b96), for BENCHMARKS.md's current numbers: the backflip over seeds 0-7, walk, run,
# spinkick and cartwheel over seeds 0-2.
#   BIN=.device-f1 tests/device/lanes.sh experiments/plans/current37.sh   (carry .device-f1)
SESSION_S=${SESSION_S:-540}
LANE0="for s in 0 1 2 3 4 5 6 7; do train backflip_s\$s 60 --motion backflip --seed \$s --time-budget 30; done
  for m in walk run spinkick cartwheel; do for s in 0 1 2; do
    train \${m}_s\$s 40 --motion \$m --seed \$s --time-budget 15
  done; done"
