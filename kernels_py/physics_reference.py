"""References for the Rust replay of the physics plans (needs a CUDA GPU and warp-lang).

    python kernels_py/physics_reference.py exact  --nworld 4096 --out DIR
    python kernels_py/physics_reference.py timing --nworld 4096 16384 --steps 1000 --warmup 200

`exact` builds the simulation exactly as capture.py does before capturing (same model, same
warm-up, then mjw.reset_data: the state a plan snapshots), sets seeded initial states and
controls, steps it with MuJoCo Warp and writes the initial state and qpos/qvel after chosen
step counts as little-endian f32 files with `reference.json`. Cases: `contact` (the character
touching the floor, perturbed pose and velocities: each world's root is put where its lowest
geom sits 5 mm into the floor) and `freefall` (high above the floor, no contact). Any character:
the physics configuration names its model. tests/gpu_physics.rs replays the committed plan from
the same state and compares.

`timing` measures Warp's own replay of one mjw.step (wp.capture_launch of a captured graph),
in steps per second (worlds x graph launches / seconds), the number the Rust bench is held to:
by default with Warp's own code path (CUBIN compiled for the device), with --shipped-ptx with
the PTX the Rust runtime loads (physics.run_shipped_ptx), which separates code generation from
replay overhead. `exact` always runs the shipped PTX, so that results can agree bit for bit.
"""

from __future__ import annotations

import argparse
import json
import os
import pathlib
import sys
import tempfile

import numpy as np

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
import physics  # noqa: E402


def setup(config: dict, nworld: int):
    """Model and Data in the state a captured plan starts from (see capture.capture_plans)."""
    import mujoco_warp as mjw
    import warp as wp

    mjm, m, d = physics.make_model_data(config, nworld)
    for name in physics.PLAN_NAMES:
        physics.run_plan(name, m, d)
    mjw.reset_data(m, d)
    wp.synchronize()
    return mjm, m, d


# How deep the lowest geom of a contact case starts in the floor (m): contacts from the first step.
CONTACT_DEPTH = 0.005
# The free-fall case's root height (m): no geom of a human-sized character reaches the floor.
FREEFALL_HEIGHT = 5.0


def lowest_geom_z(mjm, mjd) -> float:
    """The lowest point of the character's geoms (not the world's: the floor) after
    mj_kinematics, exact for primitives, the bounding sphere for meshes."""
    import mujoco

    lowest = np.inf
    for g in range(mjm.ngeom):
        if mjm.geom_bodyid[g] == 0:
            continue
        size = mjm.geom_size[g]
        z = mjd.geom_xpos[g][2]
        z_row = mjd.geom_xmat[g].reshape(3, 3)[2]  # each local axis's world z component
        kind = mjm.geom_type[g]
        if kind == mujoco.mjtGeom.mjGEOM_SPHERE:
            extent = size[0]
        elif kind == mujoco.mjtGeom.mjGEOM_CAPSULE:
            extent = abs(z_row[2]) * size[1] + size[0]
        elif kind == mujoco.mjtGeom.mjGEOM_CYLINDER:
            extent = abs(z_row[2]) * size[1] + size[0] * np.sqrt(max(0.0, 1.0 - z_row[2] ** 2))
        elif kind == mujoco.mjtGeom.mjGEOM_BOX:
            extent = float(np.sum(np.abs(z_row) * size))
        elif kind == mujoco.mjtGeom.mjGEOM_ELLIPSOID:
            extent = float(np.sqrt(np.sum((z_row * size) ** 2)))
        else:
            extent = mjm.geom_rbound[g]
        lowest = min(lowest, z - extent)
    return float(lowest)


def contact_root_heights(mjm, qpos: np.ndarray) -> np.ndarray:
    """Per world, the root height at which the pose's lowest geom is CONTACT_DEPTH into the floor
    (z = 0)."""
    import mujoco

    mjd = mujoco.MjData(mjm)
    heights = np.empty(len(qpos))
    for w, q in enumerate(qpos):
        mjd.qpos[:] = q
        mjd.qpos[2] = 0.0
        mujoco.mj_kinematics(mjm, mjd)
        heights[w] = -lowest_geom_z(mjm, mjd) - CONTACT_DEPTH
    return heights


def initial_state(mjm, nworld: int, case: str, seed: int):
    rng = np.random.default_rng(seed)
    qpos = np.tile(mjm.qpos0.astype(np.float64), (nworld, 1))
    # Perturb every ball/free quaternion and hinge a little, and renormalize.
    for j in range(mjm.njnt):
        adr = mjm.jnt_qposadr[j]
        if mjm.jnt_type[j] in (0, 1):  # free (quaternion after position), ball
            q0 = adr + (3 if mjm.jnt_type[j] == 0 else 0)
            qpos[:, q0:q0 + 4] += rng.normal(0.0, 0.05, (nworld, 4))
            qpos[:, q0:q0 + 4] /= np.linalg.norm(qpos[:, q0:q0 + 4], axis=1, keepdims=True)
        else:
            lo, hi = mjm.jnt_range[j]
            qpos[:, adr] = np.clip(qpos[:, adr] + rng.normal(0.0, 0.2, nworld), lo, hi)
    qpos[:, 2] = contact_root_heights(mjm, qpos) if case == "contact" else FREEFALL_HEIGHT
    qvel = rng.normal(0.0, 0.5, (nworld, mjm.nv))
    ctrl = rng.uniform(-0.3, 0.3, (nworld, mjm.nu)) * mjm.actuator_ctrlrange[:, 1]
    return qpos.astype(np.float32), qvel.astype(np.float32), ctrl.astype(np.float32)


def step_case(config: dict, nworld: int, case: str, seed: int, checkpoints: list[int]):
    """Runs one case from a fresh simulation; returns the initial arrays and qpos/qvel at each
    checkpoint."""
    import mujoco_warp as mjw
    import warp as wp

    mjm, m, d = setup(config, nworld)
    init = dict(zip(("qpos", "qvel", "ctrl"), initial_state(mjm, nworld, case, seed)))
    for name, arr in init.items():
        wp.copy(getattr(d, name), wp.array(arr, dtype=float))
    with wp.ScopedCapture() as capture:
        mjw.step(m, d)
    done = 0
    states = []
    for target in checkpoints:
        while done < target:
            wp.capture_launch(capture.graph)
            done += 1
        wp.synchronize()
        states.append({"qpos": d.qpos.numpy().copy(), "qvel": d.qvel.numpy().copy(),
                       "ncon": int(d.nacon.numpy()[0])})
    return init, states


def run_exact(config: dict, nworld: int, out: pathlib.Path, seed: int) -> dict:
    cases = {"contact": [1, 100], "freefall": [1, 20]}
    summary = {
        "nworld": nworld,
        "seed": seed,
        "deterministic": config.get("deterministic", False),
        # The character's name (its description's stem): the Rust test loads the same one.
        "character": pathlib.Path(config["character"]).stem,
        "cases": [],
    }
    for case, checkpoints in cases.items():
        init, states = step_case(config, nworld, case, seed, checkpoints)
        # MuJoCo Warp against itself: two more runs from fresh simulations. Without the
        # determinism features (which APIC cannot record), contact order comes from atomics and
        # runs differ; the largest pairwise difference is the spread the Rust replay is held to.
        others = [step_case(config, nworld, case, seed, checkpoints)[1] for _ in range(2)]
        files = {}
        for name, arr in init.items():
            path = out / f"{case}_init_{name}.f32"
            arr.astype("<f4").tofile(path)
            files[f"init_{name}"] = path.name
        steps = []
        for k, (target, state) in enumerate(zip(checkpoints, states)):
            entry = {"steps": target, "ncon": state["ncon"], "warp_vs_warp": {}}
            runs = [state] + [o[k] for o in others]
            for name in ("qpos", "qvel"):
                path = out / f"{case}_step{target}_{name}.f32"
                state[name].astype("<f4").tofile(path)
                entry[name] = path.name
                entry["warp_vs_warp"][name] = max(
                    float(np.max(np.abs(a[name] - b[name]))) for i, a in enumerate(runs) for b in runs[i + 1:]
                )
            steps.append(entry)
        summary["cases"].append({"name": case, "files": files, "checkpoints": steps})
        spreads = ", ".join(f"{e['steps']} steps: {e['warp_vs_warp']}" for e in steps)
        print(f"exact reference {case}: {nworld} worlds, contacts at the end {steps[-1]['ncon']}; "
              f"MuJoCo Warp against itself: {spreads}", flush=True)
    return summary


def run_timing(config: dict, nworlds: list[int], steps: int, warmup: int, shipped: bool,
               modes=(True, False)) -> list[dict]:
    import mujoco_warp as mjw
    import warp as wp

    rows = []
    for nworld in nworlds:
        for conditional in modes:
            cfg = dict(config, graph_conditional=conditional)
            _, m, d = setup(cfg, nworld)
            with wp.ScopedCapture() as capture:
                mjw.step(m, d)
            for _ in range(warmup):
                wp.capture_launch(capture.graph)
            start = wp.Event(enable_timing=True)
            end = wp.Event(enable_timing=True)
            wp.record_event(start)
            for _ in range(steps):
                wp.capture_launch(capture.graph)
            wp.record_event(end)
            wp.synchronize()
            seconds = wp.get_event_elapsed_time(start, end) / 1000.0
            row = {
                "nworld": nworld,
                "graph_conditional": conditional,
                "code": "shipped PTX (sm_80, driver JIT)" if shipped else "Warp default (CUBIN for the device)",
                "steps": steps,
                "seconds": seconds,
                "steps_per_s": nworld * steps / seconds,
            }
            rows.append(row)
            print(f"warp capture_launch ({'shipped PTX' if shipped else 'CUBIN'}): {nworld:6d} worlds, graph_conditional={conditional!s:5}: "
                  f"{row['steps_per_s'] / 1e6:.3f} M steps/s ({seconds * 1e3 / steps:.3f} ms/step)", flush=True)
    return rows


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("mode", choices=("exact", "timing"))
    parser.add_argument("--physics", default=str(physics.REPO / "configs/physics/default.toml"))
    parser.add_argument("--nworld", type=int, nargs="+", default=[4096])
    parser.add_argument("--out", help="output directory (exact)")
    parser.add_argument("--json", help="write the timing rows here (timing)")
    parser.add_argument("--seed", type=int, default=7)
    parser.add_argument("--steps", type=int, default=1000)
    parser.add_argument("--warmup", type=int, default=200)
    parser.add_argument("--graph-conditional", choices=("true", "false", "both"), default="both",
                        help="timing: the solver loop as a conditional node, unrolled, or both")
    parser.add_argument("--shipped-ptx", action="store_true",
                        help="timing: run the PTX the Rust runtime ships (exact always does)")
    args = parser.parse_args(argv)

    config = physics.load_physics_config(args.physics)
    wp = physics.configure_warp()
    # A private kernel cache unless INSTANTMIMIC_WARP_CACHE names one to share between runs.
    wp.config.kernel_cache_dir = os.environ.get("INSTANTMIMIC_WARP_CACHE") or tempfile.mkdtemp(
        prefix="instantmimic-warp-cache-"
    )
    wp.init()
    if not wp.is_cuda_available():
        print("error: this script needs a CUDA GPU", file=sys.stderr)
        return 1
    shipped = args.mode == "exact" or args.shipped_ptx
    if shipped:
        physics.run_shipped_ptx()
    with wp.ScopedDevice("cuda:0"):
        if args.mode == "exact":
            if not args.out:
                print("error: exact needs --out", file=sys.stderr)
                return 2
            out = pathlib.Path(args.out)
            out.mkdir(parents=True, exist_ok=True)
            summary = run_exact(config, args.nworld[0], out, args.seed)
            (out / "reference.json").write_text(json.dumps(summary, indent=1) + "\n")
        else:
            modes = {"true": (True,), "false": (False,), "both": (True, False)}[args.graph_conditional]
            rows = run_timing(config, args.nworld, args.steps, args.warmup, shipped, modes)
            if args.json:
                pathlib.Path(args.json).write_text(json.dumps(rows, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
