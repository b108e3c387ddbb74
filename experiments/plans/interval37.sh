# Issue 37, 2026-11-29 (sixteenth session), one GPU: the wall time as evaluations get rarer.
# Every clip with its committed config (evaluations every 5 iterations) against
# --set run.eval_interval=10, seeds 0-2, in one call on the final code: the time to success is
# read at coarser points, the wall time pays for half the evaluations.
#   tests/device/stage.sh --train-only .dev4
#   BIN=.dev4 tests/device/lanes.sh experiments/plans/interval37.sh   (carry .dev4)
SESSION_S=${SESSION_S:-560}
LANE0="for s in 0 1 2; do for m in backflip cartwheel spinkick run walk; do
    train \${m}_s\$s 60 --motion \$m --seed \$s --time-budget 30
    train \${m}_every10_s\$s 60 --motion \$m --seed \$s --time-budget 30 --set run.eval_interval=10
  done; done"
