# Issue 37, 2026-11-29 (twentieth session), one GPU: where the setup before the trainer goes,
# and two ways to hide it, on the experiment build exp-setup20 (timestamps with EXP_MARKS=1):
# the GPU opened on a thread at the command's start (EXP_EARLY_GPU=1), and there also the run's
# modules loaded while the command reads its inputs (EXP_WARM_MODULES=1); after a first run
# that fills the driver's JIT cache; backflip and walk, seeds 0-4 interleaved, 2 s of training.
#   tests/device/stage.sh --train-only .dev20exp
#   SESSION_S=540 BIN=.dev20exp tests/device/lanes.sh experiments/plans/setup37c.sh
SESSION_S=${SESSION_S:-540}
LANE0="train warmup 40 --motion walk --seed 0 --time-budget 1
  for s in 0 1 2 3 4; do
    for m in backflip walk; do
      date +%s.%N > \$OUT/runs/\${m}_base_s\$s.t0
      EXP_MARKS=1 train \${m}_base_s\$s 40 --motion \$m --seed \$s --time-budget 2
      date +%s.%N > \$OUT/runs/\${m}_early_s\$s.t0
      EXP_MARKS=1 EXP_EARLY_GPU=1 train \${m}_early_s\$s 40 --motion \$m --seed \$s --time-budget 2
      date +%s.%N > \$OUT/runs/\${m}_warm_s\$s.t0
      EXP_MARKS=1 EXP_EARLY_GPU=1 EXP_WARM_MODULES=1 train \${m}_warm_s\$s 40 --motion \$m --seed \$s --time-budget 2
    done
  done
  grep -h '^setup' \$OUT/runs/*.log | sort | head -40 >> \$OUT/summary.txt"
