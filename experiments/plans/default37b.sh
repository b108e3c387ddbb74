# Issue 37, 2026-11-29 (fifteenth session), one GPU, the call after default37.sh (same build):
# the general default on the eight shipped clips without a config of their own, seeds 1 and 2;
# then a weaker assist force on the backflip (1 Hz over 30 iterations) beside the committed
# config, 3 seeds (assist37b.sh measured 2 Hz over 30 and 60).
#   BIN=.device-a1 tests/device/lanes.sh experiments/plans/default37b.sh   (carry .device-a1)
SESSION_S=${SESSION_S:-540}
A1="--set env.assist_frequency=1 --set env.assist_iterations=30"
LANE0="for s in 1 2; do for m in crawl dance_b dance_spin getup_facedown getup_faceup jog punch stealthy_walk; do
    train default_\${m}_s\$s 65 --motion \$m --seed \$s --time-budget 20
  done; done
  for s in 0 1 2; do
    train backflip_s\$s 60 --motion backflip --seed \$s --time-budget 30
    train backflip_assist1hz30_s\$s 60 --motion backflip --seed \$s --time-budget 30 $A1
  done"
