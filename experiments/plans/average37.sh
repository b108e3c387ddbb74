# Issue 37: the evaluation on the actor's average (ppo.evaluation_average 0.9, landed in
# 119517d for the backflip and the general default) on the other four clips, seeds 0-2, against
# their committed configs (which evaluate the last update's parameters), and the GPU tests the
# change touches, on 2 GPUs in one call (tests/device/lanes.sh plan).
#   tests/device/stage.sh --only "gpu_train gpu_replay gpu_ppo gpu_rollout gpu_latent" .device-s4
#   BIN=.device-s4 tests/device/lanes.sh experiments/plans/average37.sh   (carry .device-s4)
SESSION_S=${SESSION_S:-270}
pair() { # CLIP BUDGET SEED
  train "$1_s$3" $(( $2 * 3 + 30 )) --motion "$1" --seed "$3" --time-budget "$2"
  train "$1_average_s$3" $(( $2 * 3 + 30 )) --motion "$1" --seed "$3" --time-budget "$2" --set ppo.evaluation_average=0.9
}
LANE0="gpu_test gpu_train gpu_replay gpu_ppo gpu_rollout gpu_latent; for s in 0 1 2; do pair walk 10 \$s; pair run 10 \$s; done"
LANE1="for s in 0 1 2; do pair cartwheel 30 \$s; pair spinkick 20 \$s; done"
