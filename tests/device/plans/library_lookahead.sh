# Issue 19, the library tracker's hard clips (tests/device/lanes.sh plan; 4 GPUs, one call).
# On 2026-11-26 the tracker of configs/train/library_all.toml learnt every walk but none of the
# acrobatic clips (backflip, cartwheel, dance_b, getup_faceup, spinkick at 0-2% after 816 s),
# which single-clip runs learn in 5-12 s, while the adaptive sampler already gives them most of
# the resets. Two guesses, one GPU each, against the committed config in the same call:
#   lookahead: the observation sees the reference 66 ms ahead (2 frames, 1 step apart); a flip's
#              takeoff is prepared about 0.3-0.5 s before. Frames 5 and 10 steps ahead (167 and
#              333 ms) give the policy the coming motion.
#   wide:      one 400-200-100 actor for 22 clips; PHC's trackers are far wider.
# Compare the hard clips' success in clips.tsv at the same active time.
#   tests/device/stage.sh; BIN=.device-bin tests/device/lanes.sh tests/device/plans/library_lookahead.sh
SESSION_S=${SESSION_S:-530}
KEEP=${KEEP:-"base lookahead wide both"}
LIB='--config configs/train/library_all.toml --time-budget 420'
LANE0="train base 520 $LIB"
LANE1="train lookahead 520 $LIB --set obs.future_spacing=5"
LANE2="train wide 520 $LIB --set policy.actor_hidden=[1024,512,256]"
LANE3="train both 520 $LIB --set obs.future_spacing=5 --set policy.actor_hidden=[1024,512,256]"
