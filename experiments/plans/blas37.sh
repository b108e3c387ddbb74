# Issue 37, 2026-11-29 (twentieth session), one GPU: libcublas loaded on a thread of its own from
# the command's start (Blas::load_library_beside), against the build before (714f4b5, the GPU and
# the plans opened beside the checks) in the same call, after a run that fills the JIT cache;
# backflip (3 s of training), walk and run to success, seeds 0-2 interleaved.
#   tests/device/stage.sh --train-only .dev20b   (second call: .dev20c, the library loaded after the plans' threads start)
#   SESSION_S=300 BIN=.dev20b BEFORE=.dev20prefetch tests/device/lanes.sh experiments/plans/blas37.sh
SESSION_S=${SESSION_S:-300}
LANE0="train warmup 40 --motion walk --seed 0 --time-budget 1
  for s in 0 1 2; do
    train_before backflip_before_s\$s 40 --motion backflip --seed \$s --time-budget 3
    train backflip_s\$s 40 --motion backflip --seed \$s --time-budget 3
    for m in walk run; do
      train_before \${m}_before_s\$s 40 --motion \$m --seed \$s --time-budget 30
      train \${m}_s\$s 40 --motion \$m --seed \$s --time-budget 30
    done
  done
  grep -h '^setup' \$OUT/runs/*_s*.log >> \$OUT/summary.txt"
