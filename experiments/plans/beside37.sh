# Issue 37, 2026-11-29 (sixteenth session), one GPU: the evaluation beside training
# (run.overlap_evaluation, re-landed 46093b9) with the solver loop unrolled (env.solver_loop,
# kernels only: a conditional node would make the evaluation run alone), against the committed
# configs in the same call, seeds 0-2: backflip, walk, cartwheel. First the GPU test of the
# evaluation beside training, and the training runs' test (gpu_train).
#   tests/device/stage.sh --only "gpu_evaluation_beside gpu_train" .dev2
#   BIN=.dev2 tests/device/lanes.sh experiments/plans/beside37.sh   (carry .dev2)
SESSION_S=${SESSION_S:-540}
FIRST='for t in gpu_evaluation_beside gpu_train; do INSTANTMIMIC_NO_SKIP=1 timeout 150 $BIN/$t --nocapture --test-threads 1 > $OUT/test_$t.log 2>&1; echo "$t rc $?"; grep -E "test result|FAILED|panicked" $OUT/test_$t.log | head -8; done'
BESIDE="--set run.overlap_evaluation=true --set env.solver_loop=unrolled"
LANE0="for s in 0 1 2; do for m in backflip walk cartwheel; do
    train \${m}_s\$s 60 --motion \$m --seed \$s --time-budget 30
    train \${m}_beside_s\$s 60 --motion \$m --seed \$s --time-budget 30 $BESIDE
  done; done"
