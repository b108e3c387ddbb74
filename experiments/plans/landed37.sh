# Issue 37, 2026-11-28 (twelfth session): the reduced training solver as landed (the committed
# plans' `training_step`, env.training_solver = "reduced" by default): the GPU tests it touches,
# and the backflip, walk and cartwheel with the committed configs, seeds 0-2 (the backflip) and
# seed 0 (the others), to check the landed build against floor37.sh's `iter3train` runs.
#   tests/device/stage.sh --only "gpu_rollout gpu_train gpu_replay gpu_divergence gpu_physics gpu_ppo gpu_tensorboard gpu_library_eval gpu_latent gpu_world gpu_goal" .device-final
#   BIN=.device-final tests/device/lanes.sh experiments/plans/landed37.sh   (carry .device-final)
SESSION_S=${SESSION_S:-420}
TEST_TIMEOUT=240
FIRST='INSTANTMIMIC_NO_SKIP=1 INSTANTMIMIC_BIN=$BIN/instantmimic timeout 120 $BIN/gpu_world --nocapture --test-threads 1 > $OUT/test_gpu_world.log 2>&1; echo "gpu_world rc $?"; grep "test result" $OUT/test_gpu_world.log'
LANE0="gpu_test gpu_rollout gpu_train gpu_physics gpu_replay gpu_divergence gpu_ppo gpu_tensorboard gpu_library_eval gpu_latent"
LANE1="for s in 0 1 2; do train backflip_s\$s 90 --motion backflip --seed \$s --time-budget 30; done
  train walk_s0 40 --motion walk --seed 0 --time-budget 10; train cartwheel_s0 60 --motion cartwheel --seed 0 --time-budget 30
  train backflip_full_s0 90 --motion backflip --seed 0 --time-budget 30 --set env.training_solver=full
  gpu_test gpu_goal"
