# Issue 20 on one H100, one call: the fused body kinematics as one thread per env and body
# (`body_frames`, `body_velocities`). GPU tests (gpu_env_kernels: both against f64; gpu_physics:
# against MuJoCo Warp's kinematics plan; gpu_rollout; gpu_train), `bench full` at the committed
# backflip config twice, the backflip in 3 seeds.
#   tests/device/stage.sh --only "gpu_env_kernels gpu_physics gpu_rollout gpu_train" .device-small
#   BIN=.device-small tests/device/lanes.sh experiments/plans/h100_parallel_kinematics.sh   (carry .device-small)
SESSION_S=${SESSION_S:-400}
KEEP=${KEEP:-}
FULL='full --motion backflip --envs 4096'
LANE0="gpu_test gpu_env_kernels gpu_physics; bench full_committed 80 $FULL; train backflip_0 50 --motion backflip --seed 0 --time-budget 40; train backflip_1 50 --motion backflip --seed 1 --time-budget 40; train backflip_2 50 --motion backflip --seed 2 --time-budget 40; bench full_again 80 $FULL; gpu_test gpu_rollout gpu_train"
