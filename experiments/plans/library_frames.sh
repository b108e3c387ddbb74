# Issue 19, the library tracker's hard clips: frames, not resets (tests/device/lanes.sh plan;
# one call, 2 or 4 GPUs). The reset sampler gives a failing clip most of the resets, but the
# tracking kernel plays each env until its episode ends: a backflip episode that fails within
# 10-20 steps holds its env for that long, a walk's for 300 steps (env.max_episode_steps). With
# 70% of the resets, the five hard clips would still get about a tenth of the frames, and in
# the 22-clip library far less, so the update hears little of them (single-clip runs give the
# backflip every frame). Every run records it: clips.tsv's frame_share (f181c7a). Shorter
# training episodes turn the envs over faster, so that the sampler's resets decide more of the
# frames; the value bootstraps truncated episodes, and the evaluation keeps its own lengths.
# env.phase_share = "frames" instead weights each clip's resets by its episodes per step, so
# that the sampler sets the clips' shares of the frames (docs/library.md, "The reset sampler").
# With 2 GPUs: the two remedies (the base of 2026-11-26, 0.766 and 17 clips at 403 s, is the
# reference); with 4: the base again (with its frame shares) and 30-step episodes too.
#   tests/device/stage.sh --train-only .device-train
#   BIN=.device-train tests/device/lanes.sh experiments/plans/library_frames.sh
SESSION_S=${SESSION_S:-530}
KEEP=${KEEP:-"frames episodes60"}
LIB='--config configs/train/library_all.toml --time-budget 420'
GPUS=$(nvidia-smi -L 2>/dev/null | wc -l)
LANE0="train frames 520 $LIB --set env.phase_share=frames"
LANE1="train episodes60 520 $LIB --set env.max_episode_steps=60"
if [ "$GPUS" -ge 4 ]; then
  LANE2="train base 520 $LIB"
  LANE3="train episodes30 520 $LIB --set env.max_episode_steps=30"
fi
