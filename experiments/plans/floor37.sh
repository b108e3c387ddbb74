# Issue 37, 2026-11-28 (twelfth session): the physics-floor lever. `bench full` (counts37.sh) put
# the whole loop at 1.31x the frames/s with 3 Newton iterations and 6 linesearch iterations
# (experiments/plans/physics37/iter3.toml) and 1.14x with 5 and 10, tolerance 1e-6 and 1e-4
# nothing. Here the time to success with `iter3train` (training on the iter3 plans, the evaluation
# on the committed physics: the yardstick unchanged) and `iter3` (both on iter3), against the
# committed physics in the same call, seeds 0-2: the backflip and spinkick on GPU 0, walk, run and
# cartwheel on GPU 1; then what iter3 gives up: gpu_physics's replay of iter3 against MuJoCo Warp's
# states with the committed settings (tests/fixtures/physics_reference/default_32).
#   carry .device-small (with gpu_physics) and .assets37 (experiments/plans/capture37.sh's plans)
#   BIN=.device-small tests/device/lanes.sh experiments/plans/floor37.sh
SESSION_S=${SESSION_S:-540}
for d in .assets37/*/; do
  mkdir -p "$d/mjwarp" && cp -n ptx/mjwarp/*.ptx "$d/mjwarp/"
  [ -d "$d/mjwarp_extra" ] && cp "$d/mjwarp_extra/"*.ptx "$d/mjwarp/"
done
three() { # CLIP BUDGET SEED: committed physics, iter3 training, iter3 throughout
  train "$1_s$3" $(( $2 * 3 + 30 )) --motion "$1" --seed "$3" --time-budget "$2"
  train "$1_iter3train_s$3" $(( $2 * 3 + 30 )) --motion "$1" --seed "$3" --time-budget "$2" --assets .assets37/iter3train
  [ "$1" = backflip ] && train "$1_iter3_s$3" $(( $2 * 3 + 30 )) --motion "$1" --seed "$3" --time-budget "$2" --assets .assets37/iter3
}
fidelity() {
  local t0; t0=$(date +%s)
  INSTANTMIMIC_NO_SKIP=1 INSTANTMIMIC_PHYSICS_REFERENCE=tests/fixtures/physics_reference/default_32 \
    INSTANTMIMIC_ASSETS=.assets37/iter3 run_bounded 150 "$OUT/test_gpu_physics_iter3.log" \
    "$BIN/gpu_physics" --nocapture --test-threads 1
  note "gpu_physics iter3 against default_32 (rc $?, $(( $(date +%s) - t0 )) s): $(grep -o 'test result: .*; [0-9]* ignored' "$OUT/test_gpu_physics_iter3.log" | tail -1)"
  grep -E "panicked|differ|error|max" "$OUT/test_gpu_physics_iter3.log" | head -8 | tee -a "$summary"
}
LANE0="for s in 0 1 2; do three backflip 30 \$s; done; for s in 0 1 2; do three spinkick 20 \$s; done"
LANE1="fidelity; for s in 0 1 2; do three walk 10 \$s; three run 10 \$s; done; for s in 0 1 2; do three cartwheel 30 \$s; done"
