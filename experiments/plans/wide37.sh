# Issue 37, 2026-11-29 (seventeenth session): step and kinematics plans for 64, 128 and 256 worlds
# (a wider evaluation: several policy snapshots in one evaluation rollout, 32 worlds each), and
# what a control step costs at each count against the committed 32 (`bench rollout` with the
# evaluation's full solver, horizon 53 = the backflip's evaluation episode; `bench physics`).
# Needs the build-step Python: six calls carrying .device-q/q0 ... q5 (`bash .device-q/qN/recv.sh`,
# 29 MB parts of the wheels of ../shared/tools/stage-device-python.sh, so that one rides beside
# the 34 MB tree), then this call carrying .device-q/q6, .device-q/sha and the staged binary:
#   tests/device/stage.sh --train-only .device-t1
#   SESSION_S=540 BIN=.device-t1 tests/device/lanes.sh experiments/plans/wide37.sh
# Brings back plans37w.txz: packed/<N>/plans/{step,training_step,kinematics}_<N>.wrp.zst and manifest.json.
SESSION_S=${SESSION_S:-540}
install_python() {
  cp .device-q/q6/part6 /root/.wheel-q/ &&
    cat /root/.wheel-q/part0 /root/.wheel-q/part1 /root/.wheel-q/part2 /root/.wheel-q/part3 \
      /root/.wheel-q/part4 /root/.wheel-q/part5 /root/.wheel-q/part6 > /root/wheels.tar &&
    echo "$(cat .device-q/sha)  /root/wheels.tar" | sha256sum -c - &&
    mkdir -p /root/wheels && tar xf /root/wheels.tar -C /root/wheels &&
    python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --target /root/site /root/wheels/*.whl
  note "python install rc $?"
  export PYTHONPATH=/root/site PYTHONUNBUFFERED=1
  python3 -c "import warp, mujoco, mujoco_warp; print('warp', warp.__version__, 'mujoco_warp', mujoco_warp.__version__)" 2>&1 | tail -1 | tee -a "$summary"
}
capture_plans() { # N...
  local work=/tmp/capture37w t0 n
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
  tar cJf "$OUT/plans37w.txz" -C "$work" packed
}
assets_of() { # DIR: its PTX: the committed modules, compiled where one is missing
  local missing
  missing=$(python3 -c 'import json,os,sys; m=json.load(open(sys.argv[1]+"/plans/manifest.json")); print(sum(not os.path.exists("ptx/mjwarp/"+x["ptx"]) for p in m["plans"] for x in p["modules"]))' "$1")
  if [ "$missing" = 0 ]; then ln -sfn "$PWD/ptx/mjwarp" "$1/mjwarp"; ln -sfn "$PWD/ptx/env" "$1/env"
  else timeout 200 python3 kernels_py/compile.py --only mjwarp --manifest "$1/plans/manifest.json" --out "$1" > "$1.compile.log" 2>&1; ln -sfn "$PWD/ptx/env" "$1/env"; fi
  echo "$missing"
}
# The backflip config with the evaluation's solver for training rollouts: bench rollout then
# steps as an evaluation does.
sed 's/^training_solver = "reduced"/training_solver = "full"/' configs/train/backflip.toml > /tmp/full_solver.toml
grep -q '^training_solver = "full"' /tmp/full_solver.toml || echo "full_solver.toml: no training_solver line" >> "$OUT/summary.txt"
wide() {
  local n dir missing
  install_python
  capture_plans 64 128 256
  for n in 32 64 128 256 32; do
    if [ "$n" = 32 ]; then
      bench rollout_$n 90 rollout --config /tmp/full_solver.toml --envs 32 --horizon 53 --launches 10 --rounds 3
      bench physics_$n 60 physics --envs 32 --plan step --steps 500 --warmup 100
    else
      dir=/tmp/capture37w/packed/$n; missing=$(assets_of "$dir"); note "$n worlds: $missing modules compiled"
      bench rollout_$n 90 rollout --config /tmp/full_solver.toml --envs "$n" --horizon 53 --launches 10 --rounds 3 --assets "$dir"
      bench physics_$n 60 physics --envs "$n" --plan step --steps 500 --warmup 100 --assets "$dir"
    fi
  done
}
LANE0="wide"
