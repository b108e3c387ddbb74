# Issue 19, the library tracker's hard clips (tests/device/lanes.sh plan; 2 GPUs, one call).
# On 2026-11-26 the 22-clip tracker of configs/train/library_all.toml learnt none of the
# acrobatic clips in 816 s while the sampler gave them most resets. Its metrics show why it
# might: the shared log std fell from -1.5 to a mean of -3.6 per action (entropy -60.7 at
# 420 s; a single-clip backflip succeeds near -2.0), and the adaptive learning rate sat at
# 1e-5 to 1e-4 with KL spikes, as a KL that grows as 1/sigma^2 per unit of mean change does.
# ppo.min_log_std keeps exploration; compare the hard clips' success in clips.tsv with the
# committed config's 420-s run of 2026-11-26 (0.637, 13 of 22 clips; backflip, dance_b,
# getup_faceup, spinkick 0, cartwheel 0.011).
#   tests/device/stage.sh --train-only .device-train
#   BIN=.device-train tests/device/lanes.sh experiments/plans/library_exploration.sh
SESSION_S=${SESSION_S:-530}
KEEP=${KEEP:-"floor2 floor25"}
LIB='--config configs/train/library_all.toml --time-budget 420'
LANE0="train floor2 520 $LIB --set ppo.min_log_std=-2.0"
LANE1="train floor25 520 $LIB --set ppo.min_log_std=-2.5"
