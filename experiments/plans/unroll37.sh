# Issue 37, 2026-11-29 (sixteenth session), one GPU: the solver loop unrolled (env.solver_loop,
# a graph of kernels only, which could run beside other work). First the GPU checks
# (gpu_physics: the unrolled step against MuJoCo Warp's states, the unrolled training step
# against its conditional loop), then the physics alone, conditional against unrolled, for
# the training step at 4096 worlds and the evaluation's step at 32 and 4096, twice each, and
# the backflip, seeds 0-2, trained both ways.
#   tests/device/stage.sh --only "gpu_physics" .dev1
#   BIN=.dev1 tests/device/lanes.sh experiments/plans/unroll37.sh   (carry .dev1)
SESSION_S=${SESSION_S:-540}
FIRST='INSTANTMIMIC_NO_SKIP=1 timeout 200 $BIN/gpu_physics --nocapture --test-threads 1 > $OUT/test_gpu_physics.log 2>&1; echo "gpu_physics rc $?"; grep -E "test result|Unrolled.*after 1 steps|training step after" $OUT/test_gpu_physics.log | head -40'
LANE0="for r in 1 2; do for l in conditional unrolled; do
    bench ts4096_\${l}_\$r 60 physics --plan training-step --envs 4096 --solver-loop \$l
    bench s32_\${l}_\$r 60 physics --plan step --envs 32 --solver-loop \$l
    bench s4096_\${l}_\$r 60 physics --plan step --envs 4096 --solver-loop \$l
  done; done
  for s in 0 1 2; do
    train backflip_s\$s 60 --motion backflip --seed \$s --time-budget 30
    train backflip_unrolled_s\$s 60 --motion backflip --seed \$s --time-budget 30 --set env.solver_loop=unrolled
  done"
