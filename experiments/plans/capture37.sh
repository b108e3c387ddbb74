# Issue 37, 2026-11-28 (twelfth session): physics plans for 64-16384 worlds (the env-count lever
# and a wider evaluation need them; only 32 and 4096 are committed) and for four solver settings
# at 32 and 4096 worlds (the physics-floor lever, experiments/plans/physics37/*.toml), beside the
# GPU tests of the last session's untested commits (569e298, db28e00, 0311eab, b4073e5).
# Their PTX is compiled here, not there (kernels_py/compile.py needs no GPU).
# Needs the build-step Python on the warm machine: five calls carrying .device-py/q0 ... q4
# (`bash .device-py/qN/recv.sh`, parts of 30 MB so that one rides beside the tree), then this
# call carrying .device-py/small and the staged binaries:
#   tests/device/stage.sh --only "gpu_train gpu_rollout gpu_ppo gpu_replay gpu_tensorboard gpu_multi_gpu gpu_goal_latent" .device-small
#   source .device-py/small/activate.sh && BIN=.device-small tests/device/lanes.sh experiments/plans/capture37.sh
# Brings back, inside logs.txz, plans37.txz: packed/<N>/plans/{step,kinematics}_<N>.wrp.zst and
# manifest.json per world count, packed/<variant>/plans/... per solver setting.
SESSION_S=${SESSION_S:-540}
FIRST='INSTANTMIMIC_NO_SKIP=1 INSTANTMIMIC_BIN=$BIN/instantmimic timeout 150 $BIN/gpu_multi_gpu --nocapture --test-threads 1 > $OUT/test_gpu_multi_gpu.log 2>&1; echo "gpu_multi_gpu rc $?"; grep "test result" $OUT/test_gpu_multi_gpu.log'
capture_plans() { # N...: capture, then pack each world count in its own process (zstd 19 is slow)
  local work=/tmp/capture37 t0 n
  t0=$(date +%s)
  CUDA_VISIBLE_DEVICES=$GPU timeout 300 python3 kernels_py/capture.py --nworld "$@" --out "$work/capture" \
    > "$OUT/capture.log" 2>&1
  note "capture rc $? in $(( $(date +%s) - t0 )) s: $(tail -1 "$OUT/capture.log")"
  for n in "$@"; do
    timeout 240 python3 kernels_py/pack_plans.py --capture "$work/capture" --out "$work/packed/$n" \
      --packer "$BIN/instantmimic" --only "$n" > "$OUT/pack_$n.log" 2>&1 &
  done
  wait
  note "packed in $(( $(date +%s) - t0 )) s: $(cd "$work/packed" && du -sh -- */plans | tr '\n' ' ')"
}
capture_variant() { # NAME...: experiments/plans/physics37/NAME.toml at 32 and 4096 worlds
  local work=/tmp/capture37 t0 v
  for v in "$@"; do
    if [ "$(left)" -lt 150 ]; then note "variant $v: skipped (session time)"; continue; fi
    t0=$(date +%s)
    CUDA_VISIBLE_DEVICES=$GPU timeout 240 python3 kernels_py/capture.py --physics "experiments/plans/physics37/$v.toml" \
      --nworld 32 4096 --out "$work/capture_$v" > "$OUT/capture_$v.log" 2>&1 &&
      timeout 240 python3 kernels_py/pack_plans.py --capture "$work/capture_$v" --out "$work/packed/$v" \
        --packer "$BIN/instantmimic" >> "$OUT/capture_$v.log" 2>&1
    note "variant $v rc $? in $(( $(date +%s) - t0 )) s: $(tail -1 "$OUT/capture_$v.log")"
  done
}
assets_of() { # DIR: the packed plans of DIR with their PTX: the committed PTX, compiled where it lacks a module
  local missing
  missing=$(python3 -c 'import json,os,sys; m=json.load(open(sys.argv[1]+"/plans/manifest.json")); print(sum(not os.path.exists("ptx/mjwarp/"+x["ptx"]) for p in m["plans"] for x in p["modules"]))' "$1")
  if [ "$missing" = 0 ]; then ln -sfn "$PWD/ptx/mjwarp" "$1/mjwarp"
  else timeout 200 python3 kernels_py/compile.py --only mjwarp --manifest "$1/plans/manifest.json" --out "$1" > "$1.compile.log" 2>&1; fi
  echo "$missing"
}
bench_physics() { # NAME N DIR|committed: bench physics at N worlds
  local assets=() missing=0
  [ "$3" != committed ] && { missing=$(assets_of "$3"); assets=(--assets "$3"); }
  CUDA_VISIBLE_DEVICES=$GPU timeout 120 "$BIN/instantmimic" bench physics --envs "$2" --steps 1000 --warmup 200 \
    "${assets[@]}" > "$OUT/bench_$1.log" 2>&1
  note "bench $1 ($2 worlds, $missing modules compiled): $(grep physics: "$OUT/bench_$1.log" | tail -1)"
}
pack_all() { wait_for "$OUT/lane0.done" 500; wait_for "$OUT/lane1.done" 500; tar cJf "$OUT/plans37.txz" -C /tmp/capture37 packed; note "plans37.txz $(stat -c %s "$OUT/plans37.txz") bytes"; }
export INSTANTMIMIC_WARP_CACHE=/tmp/capture37/warp-cache  # one lane compiles, the others read
LANE0="capture_plans 64 128 1024 2048 8192 16384; capture_variant iter5 tol6; touch \$OUT/lane0.done; pack_all
  bench_physics default 4096 committed; for v in iter5 tol6 iter3 tol4; do bench_physics \$v 4096 /tmp/capture37/packed/\$v; done
  for n in 1024 2048 8192 16384; do bench_physics n\$n \$n /tmp/capture37/packed/\$n; done; bench_physics default 4096 committed"
LANE1="gpu_test gpu_train gpu_rollout gpu_ppo gpu_replay gpu_tensorboard gpu_goal_latent; capture_variant iter3 tol4; touch \$OUT/lane1.done"
