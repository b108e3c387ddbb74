# Issue 37, 2026-11-28 (thirteenth session): the ballistic flight lever (env.reference_flight =
# "ballistic", 6e96b7f) against the committed configs, the general default on the eight shipped
# clips without a config of their own, and the GPU tests not yet run on the training step's build.
#   tests/device/stage.sh --only "gpu_multi_gpu gpu_goal_latent gpu_cuda gpu_jit_cache gpu_blas gpu_env_kernels gpu_reference_table" .device-s1
#   BIN=.device-s1 tests/device/lanes.sh experiments/plans/flight37.sh   (carry .device-s1)
SESSION_S=${SESSION_S:-530}
TEST_TIMEOUT=200
FIRST='INSTANTMIMIC_NO_SKIP=1 INSTANTMIMIC_BIN=$BIN/instantmimic timeout 150 $BIN/gpu_multi_gpu --nocapture --test-threads 1 > $OUT/test_gpu_multi_gpu.log 2>&1; echo "gpu_multi_gpu rc $?"; grep "test result" $OUT/test_gpu_multi_gpu.log'
BALLISTIC="--set env.reference_flight=ballistic"
LANE0="for s in 0 1 2; do train backflip_s\$s 60 --motion backflip --seed \$s --time-budget 30; train backflip_ballistic_s\$s 60 --motion backflip --seed \$s --time-budget 30 $BALLISTIC; done
  for m in spinkick run; do train \${m}_s0 40 --motion \$m --seed 0 --time-budget 15; train \${m}_ballistic_s0 40 --motion \$m --seed 0 --time-budget 15 $BALLISTIC; done
  for s in 3 4; do train backflip_s\$s 60 --motion backflip --seed \$s --time-budget 30; train backflip_ballistic_s\$s 60 --motion backflip --seed \$s --time-budget 30 $BALLISTIC; done"
LANE1="for m in crawl dance_b dance_spin getup_facedown getup_faceup jog punch stealthy_walk; do train default_\${m}_s0 60 --motion \$m --seed 0 --time-budget 30; done
  gpu_test gpu_goal_latent gpu_cuda gpu_jit_cache gpu_blas gpu_env_kernels gpu_reference_table"
