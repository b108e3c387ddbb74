# Issue 37, 2026-11-29 (eighteenth session), one GPU, the session's last code (852434f): the five
# clips with the committed configs (8 snapshots per evaluation), seeds 0-2, after a first run
# that fills the driver's JIT cache.
#   tests/device/stage.sh (the release binary of 852434f in .dev18f)
#   SESSION_S=300 BIN=.dev18f tests/device/lanes.sh experiments/plans/final37d.sh   (carry .dev18f)
SESSION_S=${SESSION_S:-300}
LANE0="train warmup 40 --motion walk --seed 0 --time-budget 1
  for s in 0 1 2; do
    for m in backflip cartwheel spinkick run walk; do
      train \${m}_s\$s 40 --motion \$m --seed \$s --time-budget 30
    done
  done"
