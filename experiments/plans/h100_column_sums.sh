# Issue 20 on one H100, one call: `column_sums` as a plain kernel (one thread per column and
# chunk of rows, where the tile kernel took 40-50 us a launch) checked on the GPU (gpu_ppo,
# gpu_blas, gpu_train) and timed in `bench full`, f32 with the kinematics plan (as committed)
# and with the fused kinematics and TF32 products; then the backflip's time to success, seeds
# 0-2, as committed and with fused kinematics, TF32 and the concurrent networks, alternating
# (tests/device/lanes.sh plan).
#   tests/device/stage.sh --only "gpu_ppo gpu_blas gpu_train" .device-small
#   BIN=.device-small tests/device/lanes.sh experiments/plans/h100_column_sums.sh   (carry .device-small)
SESSION_S=${SESSION_S:-540}
KEEP=${KEEP:-}
FULL='full --motion backflip --envs 4096'
CANDIDATE='--set env.body_kinematics=fused --set policy.gemm=cublas_tf32 --set ppo.concurrent_networks=true'
pair() {
  local seed=$1
  train "committed_$seed" 60 --motion backflip --seed "$seed" --time-budget 45
  train "candidate_$seed" 60 --motion backflip --seed "$seed" --time-budget 45 $CANDIDATE
}
LANE0="gpu_test gpu_ppo gpu_blas; bench full_f32 80 $FULL; bench full_fused_tf32 80 $FULL --set env.body_kinematics=fused --set policy.gemm=cublas_tf32; pair 0; pair 1; pair 2; gpu_test gpu_train"
