# Issue 37, 2026-11-28 (twelfth session): the env-count lever. The backflip, committed config,
# seeds 0-2, at 1024, 2048, 8192 and 16384 training worlds against 4096 (the committed count) in
# the same call, with the plans experiments/plans/capture37.sh captured (default physics; the
# evaluation stays at 32 worlds, every 5 iterations). Then `bench full` (the whole loop and its
# physics floor, committed backflip config) on the four solver settings of the physics-floor
# lever against the committed physics.
# Carries .assets37 (plans only; the PTX is the committed ptx/mjwarp, copied in there, plus the
# two modules each `iterations` variant compiles differently, compiled here by compile.py):
#   tests/device/stage.sh --train-only .device-train
#   BIN=.device-train tests/device/lanes.sh experiments/plans/counts37.sh   (carry .device-train .assets37)
SESSION_S=${SESSION_S:-545}
for d in .assets37/*/; do
  extra=$(ls "$d" | grep -x mjwarp_extra || true)
  mkdir -p "$d/mjwarp" && cp -n ptx/mjwarp/*.ptx "$d/mjwarp/"
  [ -n "$extra" ] && cp "$d/mjwarp_extra/"*.ptx "$d/mjwarp/"
done
bf() { # NAME SEED ARGS...
  local name=$1 seed=$2; shift 2
  train "${name}_s$seed" 150 --motion backflip --seed "$seed" --time-budget 30 "$@"
}
full() { # NAME ARGS...: bench full, its last lines to the summary
  bench "full_$1" 120 full --motion backflip "${@:2}"
}
LANE0="for s in 0 1 2; do bf envs2048 \$s --envs 2048 --assets .assets37/counts; done
  for s in 0 1 2; do bf envs1024 \$s --envs 1024 --assets .assets37/counts; done"
LANE1="for s in 0 1 2; do bf envs4096 \$s; bf envs8192 \$s --envs 8192 --assets .assets37/counts; bf envs16384 \$s --envs 16384 --assets .assets37/counts; done
  full default; for v in iter5 iter3 tol6 tol4; do full \$v --assets .assets37/\$v; done; full default2"
