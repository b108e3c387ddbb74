# Issue 37, the backflip's frames, and the GPU tests of the session's code, on 2 GPUs in one
# call (tests/device/lanes.sh plan).
# - Both GPUs first: gpu_multi_gpu (one clip's evaluation on rank 0 of several GPUs stops when
#   decided through Replicas::evaluate_until).
# - GPU 0: the GPU test files not run in the first call, then the backflip, seeds 3 and 4, with
#   the committed config and with ppo.minibatches 2 (more samples per update).
# - GPU 1: the backflip, seeds 0-2, committed config (the baseline of this call), ppo.minibatches
#   2 again, and the experiment build's ppo.evaluation_average 0.9 and 0.95 (the evaluation runs
#   an exponential moving average of the actor's parameters).
#   tests/device/stage.sh --only "gpu_tensorboard ... gpu_goal" .device-s2
#   (branch exp-ema) cargo build --release; the stripped binary added to .device-s2's bin.txz as
#   instantmimic_ema (all repacked with XZ_OPT=-9: 16 MB instead of 35)
#   BIN=.device-s2 tests/device/lanes.sh experiments/plans/levers37.sh   (carry .device-s2)
SESSION_S=${SESSION_S:-545}
FIRST='INSTANTMIMIC_NO_SKIP=1 INSTANTMIMIC_BIN=$BIN/instantmimic timeout 150 $BIN/gpu_multi_gpu --nocapture --test-threads 1 > $OUT/test_gpu_multi_gpu.log 2>&1; echo "gpu_multi_gpu rc $?"; grep "test result" $OUT/test_gpu_multi_gpu.log'
bf() { # NAME SEED ARGS...: the backflip with the staged build
  local name=$1 seed=$2; shift 2
  train "${name}_s$seed" 150 --motion backflip --seed "$seed" --time-budget 40 "$@"
}
bf_ema() { # DECAY SEED: the experiment build, staged beside the others as instantmimic_ema
  train_with "$BIN/instantmimic_ema" "backflip_ema${1#0.}_s$2" 150 --motion backflip --seed "$2" --time-budget 40 --set ppo.evaluation_average="$1"
}
LANE0="gpu_test gpu_tensorboard gpu_ppo gpu_physics gpu_env_kernels gpu_replay gpu_divergence gpu_latent gpu_reference_table gpu_blas gpu_library_eval gpu_goal; for s in 3 4; do bf backflip \$s; bf backflip_mb2 \$s --set ppo.minibatches=2; done"
LANE1="for s in 0 1 2; do bf backflip \$s; bf backflip_mb2 \$s --set ppo.minibatches=2; bf_ema 0.9 \$s; bf_ema 0.95 \$s; done"
