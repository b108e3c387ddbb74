# Issue 20 on one H100, two calls: the branch's four kernel changes (reset_masked one thread
# per env and lane; the reward's squared errors in 8 lanes per env, `tracking_error_sums`; Adam's
# per-step factors once per step; observation_moments four rows a pass), each checked on Warp's
# CPU device but not yet on a GPU (`bench full`'s stages tell their effects apart), and
# `policy.cublas_api = "lt"` (cuBLASLt without split-K reduction kernels).
# (policy.cublas_api was removed after this plan ran, 2026-11-27: its full_lt step now stops at
# the unknown key; BENCHMARKS.md keeps what it measured.)
# Call 1 (PART=1): gpu_env_kernels, gpu_ppo and gpu_blas (the new kernels and cuBLASLt against
# f64), then `bench full` of the older build (main) and of this one, alternating, twice, this one
# with cuBLASLt, and the backflip's seed 0.
# Call 2 (PART=2): seeds 1 and 2, the other four clips, gpu_latent (adam_advance), gpu_rollout
# and gpu_train.
#   here:  tests/device/stage.sh --only "gpu_env_kernels gpu_ppo gpu_blas gpu_latent gpu_rollout gpu_train" .device-small
#          and the older build: git worktree add /tmp/before main && (cd /tmp/before && cargo build --release)
#          && mkdir -p .device-small/before && xz -T2 -c /tmp/before/target/release/instantmimic > .device-small/before/instantmimic.xz
#   there: PART=1 BEFORE=.device-small/before BIN=.device-small tests/device/lanes.sh experiments/plans/h100_lanes.sh
#          (carry .device-small); then PART=2 without BEFORE.
SESSION_S=${SESSION_S:-540}
KEEP=${KEEP:-}
FULL='full --motion backflip --envs 4096'
case "${PART:-1}" in
  1) LANE0="gpu_test gpu_env_kernels gpu_ppo gpu_blas; bench_before full_before_1 80 $FULL; bench full_after_1 80 $FULL; bench_before full_before_2 80 $FULL; bench full_after_2 80 $FULL; bench full_lt 80 $FULL --set policy.cublas_api=lt; train backflip_0 50 --motion backflip --seed 0 --time-budget 40" ;;
  2) LANE0="train backflip_1 50 --motion backflip --seed 1 --time-budget 40; train backflip_2 50 --motion backflip --seed 2 --time-budget 40; train run_0 30 --motion run --seed 0; train walk_0 30 --motion walk --seed 0; train spinkick_0 30 --motion spinkick --seed 0; train cartwheel_0 30 --motion cartwheel --seed 0; gpu_test gpu_latent gpu_rollout gpu_train" ;;
  *) echo "h100_lanes.sh: PART is 1 or 2" >&2; exit 2 ;;
esac
