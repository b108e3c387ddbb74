# Issue 19, after library_exploration.sh and library_hard_clips.sh (tests/device/lanes.sh plan;
# 2 GPUs, one call, with the GPU tests of ppo.min_log_std). With the floor at -2.0 the five
# hard clips alone, as a library, learnt cartwheel, spinkick and getup_faceup in 9-27 s but not
# backflip (2%) or dance_b (27%) in 403 s, while they had most of the resets from 45 s on: by
# then every log std sat at the floor (entropy -16.3). A single-clip backflip succeeds while its
# log std is still coming down from -1.5 (mean -2.03 at success). So:
#   hard5_floor15: the five with the floor at the initial log std (-1.5: sigma stays 0.22);
#   all_floor15:   the 22 clips so, against floor2 (0.70 and 15 clips at 216 s);
#   backflip_floor2: the single-clip backflip with the floor at -2.0 (11.6 s without, seed 0):
#                  whether the floor alone slows it.
#   tests/device/stage.sh --only "gpu_ppo gpu_train" .device-small
#   BIN=.device-small tests/device/lanes.sh experiments/plans/library_exploration2.sh
SESSION_S=${SESSION_S:-470}
KEEP=${KEEP:-}
LIB='--config configs/train/library_all.toml'
HARD5='motion_library.clips=["backflip","cartwheel","dance_b","getup_faceup","spinkick"]'
LANE0="gpu_test gpu_ppo gpu_train; train all_floor15 400 $LIB --set ppo.min_log_std=-1.5"
LANE1="train hard5_floor15 330 $LIB --time-budget 250 --set ppo.min_log_std=-1.5 --set '$HARD5' --set run.eval_interval=100; train backflip_floor2 120 --config configs/train/backflip.toml --set ppo.min_log_std=-2.0"
