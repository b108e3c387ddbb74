# Issue 37, 2026-11-29 (fifteenth session), one GPU: the general default config
# (configs/train/default.toml, what `train --motion M` uses for a clip without a config of its
# own) on the eight shipped clips that have none, seed 0, 20 s of active time each: the issue
# asks for success within 15 s (`spread`).
#   tests/device/stage.sh --only "gpu_rollout gpu_env_kernels" .device-a1
#   BIN=.device-a1 tests/device/lanes.sh experiments/plans/default37.sh   (carry .device-a1)
SESSION_S=${SESSION_S:-560}
LANE0="for m in crawl dance_b dance_spin getup_facedown getup_faceup jog punch stealthy_walk; do
    train default_\${m}_s0 65 --motion \$m --seed 0 --time-budget 20
  done"
