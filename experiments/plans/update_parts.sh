# Issue 20 on 4 GPUs, one call: where the PPO update's 11.5 ms go, and whether fewer, larger
# minibatches keep the backflip's time to success; beside it issue 19's unseen clips from a
# tracker with the library's keys (tests/device/lanes.sh plan).
# - GPU 0: `bench full` at the committed backflip config with the update broken into its parts
#   (ppo::UpdateStage), then with 2 and 1 minibatches and with TF32 products.
# - GPUs 1-2: the backflip with 4 (committed, twice: the spread of two runs of one
#   configuration), 2 and 1 minibatches (experiments/campaigns/minibatches20.txt's arms), seeds
#   0 and 1 on GPU 1, seed 2 on GPU 2.
# - GPU 3 (issue 19): the held-out tracker (10 clips, with the library's sampler keys, to the
#   bar or its wall), the latent controller distilled from it, and both scored on the 3 clips
#   neither saw (docs/latent.md, "Unseen clips"; before: 0.730 and 0.015 from a tracker
#   without the keys).
#   tests/device/stage.sh --train-only .device-train
#   BIN=.device-train tests/device/lanes.sh experiments/plans/update_parts.sh   (carry .device-train)
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
LANE1="arms 0; arms 1"
LANE2="arms 2"
HELD='configs/library/held_out_test.toml'
LANE3="train held_out 270 --config configs/train/library_held_out.toml; train held_out_latent 160 --config configs/latent/held_out.toml --time-budget 130 --teacher \"\$(newest_checkpoint held_out)\"; library_eval unseen_latent \"\$(newest_checkpoint held_out_latent)\" $HELD; library_eval unseen_tracker \"\$(newest_checkpoint held_out)\" $HELD"
