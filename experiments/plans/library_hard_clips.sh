# Issue 19, the library tracker's hard clips after ppo.min_log_std (tests/device/lanes.sh plan;
# 2 GPUs, one call). With the floor at -2.0 the 22-clip tracker reached 0.766 and 17 of 22 clips
# in 403 s (H100, 2026-11-26; 0.637 and 13 without), every walk, run, crawl, punch and
# getup_facedown learnt, and backflip, cartwheel, dance_b, getup_faceup and spinkick still at
# 0-1%, which single-clip runs learn in 5-12 s. Two questions, one GPU each, from scratch:
#   wide:  is it the networks' size? Actor and critic [1024, 512, 256] instead of 400-200-100.
#   hard5: is it the other 17 clips? The five alone, as a library, same keys. If they learn here
#          they compete with the rest for the networks (or the normalizer); if not, something
#          in the library itself keeps them from being learnt.
#   BIN=.device-train tests/device/lanes.sh experiments/plans/library_hard_clips.sh
SESSION_S=${SESSION_S:-530}
KEEP=${KEEP:-"wide"}
LIB='--config configs/train/library_all.toml --time-budget 420 --set ppo.min_log_std=-2.0'
HARD5='motion_library.clips=["backflip","cartwheel","dance_b","getup_faceup","spinkick"]'
LANE0="train wide 520 $LIB --set policy.actor_hidden=[1024,512,256] --set policy.critic_hidden=[1024,512,256]"
LANE1="train hard5 520 $LIB --set '$HARD5' --set run.eval_interval=100"
