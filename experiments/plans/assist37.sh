# Issue 37, 2026-11-29 (fifteenth session), one GPU: the assist force (env.assist_frequency,
# c19c439) on the backflip, 3 seeds, against the committed config in the same call: a 2-Hz root
# PD fading over 30 or 60 iterations (about 0.8 and 1.7 s of training); first the GPU checks of
# root_assist and of the step applying it.
#   tests/device/stage.sh --only "gpu_rollout gpu_env_kernels" .device-a1
#   BIN=.device-a1 tests/device/lanes.sh experiments/plans/assist37.sh   (carry .device-a1)
SESSION_S=${SESSION_S:-560}
FIRST='for t in "gpu_env_kernels pd_control" "gpu_rollout assist"; do set -- $t; INSTANTMIMIC_NO_SKIP=1 timeout 120 $BIN/$1 $2 --nocapture --test-threads 1 > $OUT/test_$1_$2.log 2>&1; echo "$1 $2 rc $?"; grep -E "test result|root_assist|without:" $OUT/test_$1_$2.log; done'
A30="--set env.assist_frequency=2 --set env.assist_iterations=30"
A60="--set env.assist_frequency=2 --set env.assist_iterations=60"
LANE0="for s in 0 1 2; do
    train backflip_s\$s 60 --motion backflip --seed \$s --time-budget 30
    train backflip_assist30_s\$s 60 --motion backflip --seed \$s --time-budget 30 $A30
    train backflip_assist60_s\$s 60 --motion backflip --seed \$s --time-budget 30 $A60
  done"
