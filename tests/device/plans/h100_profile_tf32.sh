# Issue 20 on one H100, one call: the update's kernels one by one with the committed config
# (TF32 cuBLAS, concurrent networks; Nsight Compute's gpu__time_duration of each kernel node of
# one `bench full` iteration whose name is not MuJoCo Warp's physics), and `bench full` with
# the PD control as a stage of its own (tests/device/lanes.sh plan).
#   tests/device/stage.sh --only "gpu_env_kernels" .device-small
#   BIN=.device-small tests/device/lanes.sh tests/device/plans/h100_profile_tf32.sh   (carry .device-small)
SESSION_S=${SESSION_S:-400}
KEEP=${KEEP:-}
FULL='full --motion backflip --envs 4096'
UPDATE_KERNELS='regex:gemm|xmma|cutlass|splitK|Kernel|column_sums|elu|bias|ppo|adam|gather|minibatch|sum_of|sum_and|shuffle|gae|schedule|value|log_std|statistic|bootstrap|policy|sample'
kernels() {
  local ncu; ncu=$(command -v ncu || ls /opt/nvidia/nsight-compute/*/ncu 2>/dev/null | tail -1)
  [ -n "$ncu" ] || { note "kernels: no ncu"; return; }
  local t0; t0=$(date +%s)
  CUDA_VISIBLE_DEVICES=$GPU timeout 200 "$ncu" --clock-control none --metrics gpu__time_duration.sum \
    --kernel-name "$UPDATE_KERNELS" --launch-count 2500 --csv --page raw \
    "$BIN/instantmimic" bench $FULL --iterations 2 --warmup 1 --rounds 1 > "$OUT/runs/ncu.csv" 2> "$OUT/runs/ncu.err"
  note "kernels (rc $?, $(( $(date +%s) - t0 )) s): $(wc -l < "$OUT/runs/ncu.csv") lines"
}
LANE0="bench full_committed 80 $FULL; kernels; gpu_test gpu_env_kernels"
