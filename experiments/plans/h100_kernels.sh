# Issue 20 on one H100, one call: the PPO update's kernels one by one (Nsight Compute's
# gpu__time_duration of each kernel node of one `bench full` iteration whose name is not
# MuJoCo Warp's physics), then the backflip's time to success with the fused kinematics and
# TF32 products, alone and with the actor and critic as concurrent branches, seeds 0-2
# (tests/device/lanes.sh plan).
#   BIN=.device-small tests/device/lanes.sh experiments/plans/h100_kernels.sh   (carry .device-small)
SESSION_S=${SESSION_S:-540}
KEEP=${KEEP:-}
FULL='full --motion backflip --envs 4096'
# shellcheck source=experiments/plans/ncu_update_kernels.sh
. "$(dirname "${BASH_SOURCE[0]}")/ncu_update_kernels.sh"
three() {
  local name=$1; shift
  local seed
  for seed in 0 1 2; do
    train "${name}_$seed" 60 --motion backflip --seed "$seed" --time-budget 45 --set env.body_kinematics=fused "$@"
  done
}
LANE0="kernels; bench full_fused_tf32 80 $FULL --set env.body_kinematics=fused --set policy.gemm=cublas_tf32; three tf32 --set policy.gemm=cublas_tf32; three tf32_concurrent --set policy.gemm=cublas_tf32 --set ppo.concurrent_networks=true"
