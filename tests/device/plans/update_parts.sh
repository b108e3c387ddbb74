# Issue 20 on 4 GPUs, one call: where the PPO update's 11.5 ms go, and whether fewer, larger
# minibatches keep the backflip's time to success (tests/device/lanes.sh plan).
# - GPU 0: `bench full` at the committed backflip config with the update broken into its parts
#   (ppo::UpdateStage), then with 2 and 1 minibatches and with TF32 products.
# - GPUs 1-3: the backflip, seed 1, 2 or 3 per GPU, with 4 (committed, twice: the spread of
#   two runs of one configuration), 2 and 1 minibatches (tests/device/campaigns/minibatches20.txt's
#   arms, one seed per GPU).
#   tests/device/stage.sh --train-only .device-train
#   BIN=.device-train tests/device/lanes.sh tests/device/plans/update_parts.sh   (carry .device-train)
SESSION_S=${SESSION_S:-540}
KEEP=${KEEP:-}
FULL='full --motion backflip --envs 4096'
LANE0="bench full_committed 150 $FULL; bench full_minibatches2 120 $FULL --set ppo.minibatches=2; bench full_minibatches1 120 $FULL --set ppo.minibatches=1; bench full_tf32 120 $FULL --set policy.gemm=cublas_tf32"
arms() {
  local seed=$1
  train "mb4_$seed" 75 --motion backflip --seed "$seed" --time-budget 60
  train "mb2_$seed" 75 --motion backflip --seed "$seed" --time-budget 60 --set ppo.minibatches=2
  train "mb1_$seed" 75 --motion backflip --seed "$seed" --time-budget 60 --set ppo.minibatches=1
  train "mb4again_$seed" 75 --motion backflip --seed "$seed" --time-budget 60
}
LANE1="arms 0"
LANE2="arms 1"
LANE3="arms 2"
