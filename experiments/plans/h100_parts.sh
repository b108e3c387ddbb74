# Issue 20 on one H100, one call: the fused body kinematics checked on the GPU and timed, the
# PPO update broken into its parts (committed, 2 and 1 minibatches, TF32), and the backflip's
# time to success with the kinematics plan and with the kernel, seeds 0-2, alternating
# (tests/device/lanes.sh plan).
#   tests/device/stage.sh --only "gpu_physics gpu_env_kernels" .device-small
#   BIN=.device-small tests/device/lanes.sh experiments/plans/h100_parts.sh   (carry .device-small)
SESSION_S=${SESSION_S:-540}
KEEP=${KEEP:-}
FULL='full --motion backflip --envs 4096'
pair() {
  local seed=$1
  train "plan_$seed" 60 --motion backflip --seed "$seed" --time-budget 45
  train "fused_$seed" 60 --motion backflip --seed "$seed" --time-budget 45 --set env.body_kinematics=fused
}
LANE0="gpu_test gpu_physics gpu_env_kernels; bench full_plan 90 $FULL; bench full_fused 90 $FULL --set env.body_kinematics=fused; bench full_mb2 80 $FULL --set ppo.minibatches=2; bench full_mb1 80 $FULL --set ppo.minibatches=1; bench full_tf32 80 $FULL --set policy.gemm=cublas_tf32; pair 0; pair 1; pair 2"
