# Issue 19, the library tracker's hard clips (tests/device/lanes.sh plan; one call, 2 or 4
# GPUs). With ppo.min_log_std = -2.0 (committed in the library configs) the 22-clip tracker had
# 0.766 and 17 of 22 clips after 403 s (H100, 2026-11-26), the acrobatic clips (backflip,
# cartwheel, dance_b, getup_faceup, spinkick) at 0-2%; the five alone learnt three of them
# but not the backflip or dance_b in 403 s; wider networks changed nothing (BENCHMARKS.md,
# "Exploration in a library"). The guess left: the observation sees the reference only 66 ms
# ahead (2 frames, 1 step apart) while a flip's takeoff is prepared 0.3-0.5 s before; frames 5
# and 10 steps ahead (167 and 333 ms) show the coming motion. The base run also records the
# reset sampler's reset share, frame share and failures per step per clip (clips.tsv): whether the
# hard clips get the resets and the frames.
#   tests/device/stage.sh --train-only .device-train
#   BIN=.device-train tests/device/lanes.sh experiments/plans/library_lookahead.sh
SESSION_S=${SESSION_S:-530}
KEEP=${KEEP:-"base lookahead"}
LIB='--config configs/train/library_all.toml --time-budget 420'
HARD5='motion_library.clips=["backflip","cartwheel","dance_b","getup_faceup","spinkick"]'
GPUS=$(nvidia-smi -L 2>/dev/null | wc -l)
LANE0="train base 520 $LIB"
LANE1="train lookahead 520 $LIB --set obs.future_spacing=5"
if [ "$GPUS" -ge 4 ]; then
  LANE2="train hard5_lookahead 520 $LIB --set obs.future_spacing=5 --set '$HARD5' --set run.eval_interval=100"
  LANE3="train lookahead_3 520 $LIB --set obs.future_frames=3 --set obs.future_spacing=5"
fi
