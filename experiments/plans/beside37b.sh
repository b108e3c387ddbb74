# Issue 37, 2026-11-29 (sixteenth session), one GPU: why the evaluation beside training does
# not hide (beside37.sh: the iteration after an evaluation starts waits for all of it, the solver
# loop unrolled or not). Physics alone: the training step at 4096 worlds and the evaluation's
# step at 32 on two streams, each alone and both at once (bench physics --beside-envs), for the
# conditional and the unrolled solver loop; the same for the step at 32 beside itself.
#   tests/device/stage.sh --train-only .dev3
#   BIN=.dev3 tests/device/lanes.sh experiments/plans/beside37b.sh   (carry .dev3)
SESSION_S=${SESSION_S:-300}
LANE0="for r in 1 2; do for l in conditional unrolled; do
    bench ts4096_b32_\${l}_\$r 60 physics --plan training-step --envs 4096 --beside-envs 32 --steps 200 --solver-loop \$l
    bench s32_b32_\${l}_\$r 60 physics --plan step --envs 32 --beside-envs 32 --steps 200 --solver-loop \$l
  done; done"
