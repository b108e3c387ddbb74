# Issue 37, 2026-11-28 (fourteenth session), on one GPU (the 2-GPU kind was not lent): the
# ballistic flight lever (env.reference_flight = "ballistic", 6e96b7f) and mirror augmentation
# (ppo.mirror_augmentation, this session) against the committed configs, 3 seeds, the baseline
# interleaved in the same call; the mirror's GPU test first.
#   tests/device/stage.sh --only "gpu_ppo gpu_goal_latent gpu_cuda gpu_jit_cache gpu_blas gpu_env_kernels gpu_reference_table" .device-s2
#   BIN=.device-s2 tests/device/lanes.sh experiments/plans/mirror37.sh   (carry .device-s2)
SESSION_S=${SESSION_S:-545}
TEST_TIMEOUT=120
FIRST='INSTANTMIMIC_NO_SKIP=1 timeout 120 $BIN/gpu_ppo mirror --nocapture --test-threads 1 > $OUT/test_gpu_ppo_mirror.log 2>&1; echo "gpu_ppo mirror rc $?"; grep "test result" $OUT/test_gpu_ppo_mirror.log'
BALLISTIC="--set env.reference_flight=ballistic"
MIRROR="--set ppo.mirror_augmentation=true"
LANE0="for s in 0 1 2; do
    train backflip_s\$s 60 --motion backflip --seed \$s --time-budget 30
    train backflip_ballistic_s\$s 60 --motion backflip --seed \$s --time-budget 30 $BALLISTIC
    train backflip_mirror_s\$s 60 --motion backflip --seed \$s --time-budget 30 $MIRROR
  done
  for m in walk run spinkick cartwheel; do for s in 0 1 2; do
    train \${m}_s\$s 40 --motion \$m --seed \$s --time-budget 15
    train \${m}_mirror_s\$s 40 --motion \$m --seed \$s --time-budget 15 $MIRROR
  done; done
  for m in spinkick run; do for s in 0 1 2; do
    train \${m}_ballistic_s\$s 40 --motion \$m --seed \$s --time-budget 15 $BALLISTIC
  done; done
  gpu_test gpu_reference_table gpu_env_kernels gpu_cuda gpu_blas gpu_jit_cache gpu_goal_latent"
