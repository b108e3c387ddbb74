# Issue 37, 2026-11-29 (twentieth session), one GPU: the setup before the trainer hidden behind
# itself: the GPU opened on a thread of its own while the command reads its inputs, and the
# run's plans decoded on threads of their own, checked in place and handed to the simulations
# (each was decoded twice: by the checks and by the trainer), against the build before (0d1a219
# with the timestamps of exp-setup20, off) in the same call, after a first run that fills the
# driver's JIT cache; the five clips, committed configs, seeds 0-2 interleaved; then the GPU
# tests of the code it touches.
#   tests/device/stage.sh --only "gpu_train gpu_latent gpu_replay gpu_tensorboard gpu_goal gpu_library_eval" .dev20
#   SESSION_S=540 BIN=.dev20 BEFORE=.dev20before tests/device/lanes.sh experiments/plans/prefetch37.sh
SESSION_S=${SESSION_S:-540}
LANE0="train warmup 40 --motion walk --seed 0 --time-budget 1
  for s in 0 1 2; do
    for m in backflip cartwheel spinkick run walk; do
      train_before \${m}_before_s\$s 40 --motion \$m --seed \$s --time-budget 30
      train \${m}_s\$s 40 --motion \$m --seed \$s --time-budget 30
    done
  done
  grep -h '^setup' \$OUT/runs/*_s0.log >> \$OUT/summary.txt
  TEST_TIMEOUT=200 gpu_test gpu_train gpu_latent gpu_replay gpu_tensorboard gpu_goal gpu_library_eval"
