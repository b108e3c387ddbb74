"""Kernel times of one MuJoCo Warp step, default physics against the deterministic variant
(a probe on the GPU; Warp's activity timing, launches outside a graph).
    source .device-py/small/activate.sh && python experiments/scripts/det_profile.py [NWORLD]
"""
import collections, sys, tempfile
sys.path.insert(0, "kernels_py")
import physics, physics_reference
wp = physics.configure_warp()
wp.config.kernel_cache_dir = tempfile.mkdtemp()
wp.init()
import mujoco_warp as mjw

nworld = int(sys.argv[1]) if len(sys.argv) > 1 else 4096
STEPS = 5
for name in ("default", "deterministic"):
    cfg = physics.load_physics_config(f"configs/physics/{name}.toml")
    with wp.ScopedDevice("cuda:0"):
        mjm, m, d = physics_reference.setup(cfg, nworld)
        for key, arr in zip(("qpos", "qvel", "ctrl"), physics_reference.initial_state(mjm, nworld, "contact", 7)):
            wp.copy(getattr(d, key), wp.array(arr, dtype=float))
        mjw.step(m, d)
        wp.timing_begin(cuda_filter=wp.TIMING_KERNEL)
        for _ in range(STEPS):
            mjw.step(m, d)
        results = wp.timing_end()
    per = collections.defaultdict(float)
    for r in results:
        per[r.name.split("_cuda_kernel")[0][:70]] += r.elapsed / STEPS
    total = sum(per.values())
    print(f"== {name}: {total:.3f} ms of kernels per step ({nworld} worlds)")
    for k, v in sorted(per.items(), key=lambda kv: -kv[1])[:16]:
        print(f"  {v:8.3f} ms  {k}")
