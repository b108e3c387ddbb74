# Issue 37, 2026-11-28 (fourteenth session), second call on one GPU: mirror augmentation with the
# images' log-probabilities and means from the rollout policy at the image (the first call,
# mirror37.sh, used the sample's own, and the adaptive rate sat at its floor), against the
# committed configs, 3 seeds, the baseline interleaved; then the ballistic flights on spinkick
# and run, which the first call had no time left for.
#   tests/device/stage.sh --only "gpu_ppo gpu_goal_latent gpu_cuda gpu_jit_cache gpu_blas gpu_env_kernels gpu_reference_table" .device-s3
#   BIN=.device-s3 tests/device/lanes.sh experiments/plans/mirror37b.sh   (carry .device-s3)
SESSION_S=${SESSION_S:-560}
TEST_TIMEOUT=120
FIRST='INSTANTMIMIC_NO_SKIP=1 timeout 120 $BIN/gpu_ppo mirror --nocapture --test-threads 1 > $OUT/test_gpu_ppo_mirror.log 2>&1; echo "gpu_ppo mirror rc $?"; grep "test result" $OUT/test_gpu_ppo_mirror.log'
BALLISTIC="--set env.reference_flight=ballistic"
MIRROR="--set ppo.mirror_augmentation=true"
LANE0="for s in 0 1 2; do
    train backflip_s\$s 60 --motion backflip --seed \$s --time-budget 30
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
