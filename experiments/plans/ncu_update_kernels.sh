# Sourced by device plans (experiments/plans/h100_kernels.sh, h100_profile_tf32.sh): `kernels`,
# a lanes.sh step that profiles every kernel node of two `bench $FULL` iterations whose name is
# not MuJoCo Warp's physics with Nsight Compute (gpu__time_duration, clocks left alone) into
# $OUT/runs/ncu.csv. Nsight Compute does not profile kernel nodes of graphs with conditional
# nodes, so the rollout's kernels are not in it.
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
