# Issue 37, 2026-11-29 (sixteenth session), one GPU: the final code's physics benchmarks (the
# unrolled loop and the evaluation beside training deleted): the training step and the step at
# 4096 worlds, and the training step beside the evaluation's 32-world step, twice each.
#   tests/device/stage.sh --train-only .dev4
#   BIN=.dev4 tests/device/lanes.sh experiments/plans/beside37c.sh   (carry .dev4)
SESSION_S=${SESSION_S:-240}
LANE0="for r in 1 2; do
    bench ts4096_\$r 60 physics --plan training-step --envs 4096
    bench s4096_\$r 60 physics --plan step --envs 4096
    bench ts4096_b32_\$r 60 physics --plan training-step --envs 4096 --beside-envs 32 --steps 200
    bench s32_b32_\$r 60 physics --plan step --envs 32 --beside-envs 32 --steps 200
  done"
