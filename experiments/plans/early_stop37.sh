# Issue 37, wall time: evaluations that stop once they can no longer succeed
# (run.eval_early_stop), on 2 GPUs in one call (tests/device/lanes.sh plan).
# - GPU 0: the GPU tests the change touches (gpu_rollout: the evaluation in chunks plays the
#   whole graph's episodes; gpu_train: a short run's evaluations stop, its last runs whole),
#   then walk, run and spinkick, seeds 0-2, each with whole evaluations and with early stops
#   (the training is the same: only the wall time may change), then gpu_jit_cache last (its
#   cold-cache helpers load the CPU).
# - GPU 1: the backflip and the cartwheel the same way, then two backflip levers of the tail
#   (a smaller step): ppo.kl_threshold 0.08 (committed 0.12) and ppo.minibatches 2 (4).
#   tests/device/stage.sh --only "gpu_rollout gpu_train gpu_cuda gpu_jit_cache gpu_tensorboard" .device-s1
#   BIN=.device-s1 tests/device/lanes.sh experiments/plans/early_stop37.sh   (carry .device-s1)
SESSION_S=${SESSION_S:-550}
# pair NAME MOTION BUDGET SEED: whole evaluations, then early stops.
pair() {
  train "$1_whole_s$4" $(( $3 * 3 + 30 )) --motion "$2" --seed "$4" --time-budget "$3" --set run.eval_early_stop=false
  train "$1_stop_s$4" $(( $3 * 3 + 30 )) --motion "$2" --seed "$4" --time-budget "$3"
}
LANE0="gpu_test gpu_rollout gpu_train gpu_cuda gpu_tensorboard; for s in 0 1 2; do pair walk walk 10 \$s; pair run run 10 \$s; pair spinkick spinkick 20 \$s; done; gpu_test gpu_jit_cache"
LANE1="for s in 0 1 2; do pair backflip backflip 40 \$s; done; for s in 0 1 2; do pair cartwheel cartwheel 30 \$s; done; for s in 0 1 2; do train backflip_kl08_s\$s 150 --motion backflip --seed \$s --time-budget 40 --set ppo.kl_threshold=0.08; done; for s in 0 1 2; do train backflip_mb2_s\$s 150 --motion backflip --seed \$s --time-budget 40 --set ppo.minibatches=2; done"
