# Issue 37, 2026-11-29 (eighteenth session), one GPU: where the setup goes (the run's `setup`
# line, broken down by what the trainer builds), after a first run that fills the driver's JIT
# cache: the backflip and the walk with 8 snapshots per evaluation (the default) and with 1.
#   tests/device/stage.sh --train-only .dev18b
#   SESSION_S=200 BIN=.dev18b tests/device/lanes.sh experiments/plans/setup37.sh   (carry .dev18b)
SESSION_S=${SESSION_S:-200}
LANE0="train warmup 40 --motion walk --seed 0 --time-budget 1
  for s in 0 1; do
    train backflip_s\$s 40 --motion backflip --seed \$s --time-budget 30
    train backflip_one_s\$s 40 --motion backflip --seed \$s --time-budget 30 --set run.eval_snapshots=1
    train walk_s\$s 20 --motion walk --seed \$s --time-budget 30
    train walk_one_s\$s 20 --motion walk --seed \$s --time-budget 30 --set run.eval_snapshots=1
  done
  grep -h '^setup\\|setup [0-9.]* s' \$OUT/runs/*.log | tee -a \$OUT/summary.txt"
