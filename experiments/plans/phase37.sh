# Issue 37, 2026-11-29 (sixteenth session), one GPU: the adaptive start-phase sampler on the
# backflip, whose starts at 0.60-0.88 s of the clip still fail at success: finer phase cells
# (env.phase_bins 40 instead of 20) and faster-forgetting statistics (env.phase_decay 0.95
# instead of 0.99), against the committed config in the same call, seeds 0-2, final code.
#   tests/device/stage.sh --train-only .dev4
#   BIN=.dev4 tests/device/lanes.sh experiments/plans/phase37.sh   (carry .dev4)
SESSION_S=${SESSION_S:-400}
LANE0="for s in 0 1 2; do
    train backflip_s\$s 60 --motion backflip --seed \$s --time-budget 30
    train backflip_bins40_s\$s 60 --motion backflip --seed \$s --time-budget 30 --set env.phase_bins=40
    train backflip_decay95_s\$s 60 --motion backflip --seed \$s --time-budget 30 --set env.phase_decay=0.95
  done"
