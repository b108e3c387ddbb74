"""Which float atomics make MuJoCo Warp's contact step differ from run to run (a probe on the GPU).

Runs MuJoCo Warp (Python, no plans) with our contact and constraint sorts and Warp's own
deterministic atomics on a subset of kernels at a time, three runs per variant, and prints the
largest qpos/qvel difference among them (BENCHMARKS.md, "Deterministic physics"). Our fixed-order
solver kernels stay out, so that the probe measures MuJoCo Warp's.
    source .device-py/small/activate.sh && NWORLD=256 python experiments/scripts/det_probe.py
"""
import sys, os, tempfile, pathlib
sys.path.insert(0, "kernels_py")
import numpy as np
import physics, physics_reference
wp = physics.configure_warp()
wp.config.kernel_cache_dir = tempfile.mkdtemp()
wp.init()
from mujoco_warp._src import solver, constraint, types
import deterministic_solver
deterministic_solver.install = lambda: None  # the sorts only; the solver kernels are probed below
DT = types.DeterminismType
orig = {n: getattr(solver, n) for n in ("_update_constraint_init_qfrc_constraint_sparse", "_update_gradient_grad",
                                         "_update_gradient_h_incremental_sparse", "_JTDACJ_sparse")}
orig["_efc_contact_jac_sparse"] = constraint._efc_contact_jac_sparse
mods = {n: (constraint if n == "_efc_contact_jac_sparse" else solver) for n in orig}

def force_nondet(name):
    f = orig[name]
    if name == "_update_constraint_init_qfrc_constraint_sparse":
        return lambda compact, nv, deterministic=False: f(compact, 0, False)
    if name == "_update_gradient_grad":
        return lambda stable_fast, deterministic=False: f(stable_fast, False)
    if name == "_update_gradient_h_incremental_sparse":
        return lambda compact, max_records=0, deterministic=False: f(compact)
    if name == "_JTDACJ_sparse":
        return lambda compact, cone, mc, bd=types.BlockDim.update_gradient_JTDAJ_sparse, max_records=0, deterministic=False: f(compact, cone, mc, bd)
    return lambda cone, nmaxdim, max_records=0, deterministic=False: f(cone, nmaxdim)

cfg = physics.load_physics_config("configs/physics/deterministic.toml")
variants = [
    ("sorts only", DT.CONTACTS | DT.CONSTRAINT, ()),
    ("sorts + all atomics", DT.ALL, ()),
    ("atomics only (no sorts)", DT.ATOMICS, ()),
    ("sorts + atomics except the 5 solver/constraint kernels", DT.ALL, tuple(orig)),
    ("sorts + atomics: qfrc, grad only", DT.ALL, ("_update_gradient_h_incremental_sparse", "_JTDACJ_sparse", "_efc_contact_jac_sparse")),
    ("sorts + atomics: qfrc, grad, h_incr, JTDACJ", DT.ALL, ("_efc_contact_jac_sparse",)),
]
nworld = int(os.environ.get("NWORLD", 4096))
with wp.ScopedDevice("cuda:0"):
    for label, flags, nondet in variants:
        for n in orig:
            setattr(mods[n], n, force_nondet(n) if n in nondet else orig[n])
        runs = []
        try:
            for _ in range(3):
                mjm, m, d = physics_reference.setup(cfg, nworld)
                m.opt.deterministic = int(flags)
                init = physics_reference.initial_state(mjm, nworld, "contact", 7)
                for name, arr in zip(("qpos", "qvel", "ctrl"), init):
                    wp.copy(getattr(d, name), wp.array(arr, dtype=float))
                with wp.ScopedCapture() as cap:
                    import mujoco_warp as mjw
                    mjw.step(m, d)
                wp.capture_launch(cap.graph)
                wp.synchronize()
                runs.append((d.qpos.numpy().copy(), d.qvel.numpy().copy()))
            sp = [max(float(np.abs(a[k] - b[k]).max()) for i, a in enumerate(runs) for b in runs[i + 1:]) for k in (0, 1)]
            print(f"PROBE {label}: spread qpos {sp[0]:.3e} qvel {sp[1]:.3e}", flush=True)
        except Exception as e:
            print(f"PROBE {label}: error {type(e).__name__}: {str(e)[:300]}", flush=True)
