# Issue 20 on 4 GPUs, one call: env.body_kinematics = "fused" (one kernel of ours instead of
# the kinematics plan, twice per control step; after a reset only for the envs reset) checked
# and measured (tests/device/lanes.sh plan).
# - GPU 0: the GPU tests (gpu_physics: the kernel against the kinematics plan on MuJoCo Warp's
#   states; gpu_env_kernels: against f64), then `bench full` at the committed backflip config
#   with the plan and with the kernel.
# - GPUs 1-3: the backflip, seed 0, 1 or 2 per GPU, with the plan and with the kernel (time to
#   success and frames/s; seeds 1 and 2 twice, for the spread of two runs of one setting), then the 22-clip library with the kernel (seed 1 on GPU 1; the
#   plan's 213.1 s on H200 and 256.4 s on H100 are the reference).
#   tests/device/stage.sh --only "gpu_physics gpu_env_kernels" .device-small
#   BIN=.device-small tests/device/lanes.sh experiments/plans/fused_kinematics.sh   (carry .device-small)
SESSION_S=${SESSION_S:-540}
KEEP=${KEEP:-}
FULL='full --motion backflip --envs 4096'
LANE0="gpu_test gpu_physics gpu_env_kernels; bench full_plan 130 $FULL; bench full_fused 130 $FULL --set env.body_kinematics=fused"
# pair SEED TAG: the backflip with the plan, then with the kernel.
pair() {
  local seed=$1 tag=${2:-}
  train "plan_$seed$tag" 75 --motion backflip --seed "$seed" --time-budget 60
  train "fused_$seed$tag" 75 --motion backflip --seed "$seed" --time-budget 60 --set env.body_kinematics=fused
}
LANE1="pair 0; train library_fused_1 360 --config configs/train/library_all.toml --seed 1 --set env.body_kinematics=fused"
LANE2="pair 1; pair 1 again"
LANE3="pair 2; pair 2 again"
