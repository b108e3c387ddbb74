# Issue 37, 2026-11-29 (twentieth session), two GPUs: GAE lambda 0.95 (confirm37: faster on the
# backflip, walk, run and spinkick, slower on the cartwheel) in the general default, on the eight
# shipped clips without a config of their own, seeds 0-2 beside the general default as it is;
# `train --motion M --seed S --time-budget 20`, the build of 714f4b5.
#   SESSION_S=400 BIN=.dev20 tests/device/lanes.sh experiments/plans/default37c.sh   (nvidia-h200-x2)
SESSION_S=${SESSION_S:-400}
default_lane() {
  local lane=$1 clips=$2 s m
  train "warmup_$lane" 40 --motion walk --seed 0 --time-budget 1
  for s in 0 1 2; do
    for m in $clips; do
      train "${m}_default_s$s" 40 --motion "$m" --seed "$s" --time-budget 20
      train "${m}_lambda_s$s" 40 --motion "$m" --seed "$s" --time-budget 20 --set ppo.lambda=0.95
    done
  done
}
LANE0="default_lane 0 'crawl dance_b dance_spin getup_facedown'"
LANE1="default_lane 1 'getup_faceup jog punch stealthy_walk'"
