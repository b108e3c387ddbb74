# Issue 20 on one H100, one call: the update's kernels one by one with the committed config
# (TF32 cuBLAS, concurrent networks; Nsight Compute's gpu__time_duration of each kernel node of
# one `bench full` iteration whose name is not MuJoCo Warp's physics), and `bench full` with
# the PD control as a stage of its own (tests/device/lanes.sh plan).
#   tests/device/stage.sh --only "gpu_env_kernels" .device-small
#   BIN=.device-small tests/device/lanes.sh experiments/plans/h100_profile_tf32.sh   (carry .device-small)
SESSION_S=${SESSION_S:-400}
KEEP=${KEEP:-}
FULL='full --motion backflip --envs 4096'
# shellcheck source=experiments/plans/ncu_update_kernels.sh
. "$(dirname "${BASH_SOURCE[0]}")/ncu_update_kernels.sh"
LANE0="bench full_committed 80 $FULL; kernels; gpu_test gpu_env_kernels"
