"""Capture MuJoCo Warp's step and kinematics as replayable plans (needs a CUDA GPU).

    python kernels_py/capture.py --physics configs/physics/default.toml --nworld 32 4096 --out WORK

For each world count and each plan in physics.PLAN_NAMES (and physics.TRAINING_STEP_PLAN, the step
with the config's training solver iterations, where it has them) this writes, under WORK:
  raw/<plan>_<nworld>.wrp             Warp's APIC recording (uncompressed, with every Model and
                                      Data array bound by name, see physics.named_arrays)
  raw/<plan>_<nworld>_modules/        the binaries Warp compiled on the GPU (CUBIN: driver 580
                                      refuses the PTX 9.4 that Warp's NVRTC writes)
  manifest.json                       plans, their modules (name, hash, PTX file, block dims) and
                                      the physics they were captured with
Then `instantmimic plan pack` compresses each plan into ptx/plans/ and `compile.py` regenerates
the PTX on any machine, no GPU needed (see docs/development.md, "Rebuilding plans").

A plan snapshots the device memory of every bound array when it is saved. Data is reset
(mjw.reset_data) right before each capture, so a plan starts from the model's reset state.
"""

from __future__ import annotations

import argparse
import json
import os
import pathlib
import shutil
import sys
import tempfile
import time

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
import physics  # noqa: E402


def capture_plans(
    config: dict, nworld: int, out: pathlib.Path, plans: dict[str, str] | None = None
) -> tuple[list[dict], object]:
    """Captures each plan of `plans` (its name -> the MuJoCo Warp calls of physics.run_plan;
    default: physics.PLAN_NAMES) on a model built with `config`."""
    import mujoco_warp as mjw
    import warp as wp

    plans = plans or {name: name for name in physics.PLAN_NAMES}
    mjm, m, d = physics.make_model_data(config, nworld)
    # Run each plan once outside a capture: Warp compiles and loads every module it launches.
    for calls in plans.values():
        physics.run_plan(calls, m, d)
    wp.synchronize()

    entries = []
    for name, calls in plans.items():
        mjw.reset_data(m, d)
        wp.synchronize()
        with wp.ScopedCapture(apic=True) as capture:
            physics.run_plan(calls, m, d)
        apic = capture.graph._apic_capture
        stem = f"{name}_{nworld}"
        wrp = out / "raw" / f"{stem}.wrp"
        wp.capture_save(capture.graph, str(wrp), inputs=physics.named_arrays(m, d))

        block_dims: dict[str, set[int]] = {}
        for kernel in apic.collected_kernels.values():
            block_dims.setdefault(kernel["module_hash"], set()).add(int(kernel["block_dim"]))
        modules = []
        for module_hash, info in sorted(apic.collected_modules.items(), key=lambda kv: kv[1]["binary_filename"]):
            modules.append(
                {
                    "name": info["module_name"],
                    "hash": module_hash,
                    "ptx": physics.ptx_file_name(info["binary_filename"]),
                    "block_dims": sorted(block_dims.get(module_hash, ())),
                }
            )
        entries.append(
            {
                "name": name,
                "nworld": nworld,
                "file": f"{stem}.wrp.zst",
                "raw": str(wrp.relative_to(out)),
                "modules": modules,
            }
        )
        print(f"captured {stem}: {len(modules)} modules, {wrp.stat().st_size / 1e6:.1f} MB raw", flush=True)
    return entries, mjm


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--physics", default=str(physics.REPO / "configs/physics/default.toml"))
    parser.add_argument("--nworld", type=int, nargs="+", required=True)
    parser.add_argument("--out", required=True, help="work directory for raw plans and the manifest")
    args = parser.parse_args(argv)

    try:
        config = physics.load_physics_config(args.physics)
    except physics.ConfigError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    if any(n <= 0 for n in args.nworld):
        print("error: --nworld values must be positive", file=sys.stderr)
        return 2

    wp = physics.configure_warp()
    # A private kernel cache: every module is compiled by this run, with the settings above.
    # A private kernel cache unless INSTANTMIMIC_WARP_CACHE names one to share between runs.
    wp.config.kernel_cache_dir = os.environ.get("INSTANTMIMIC_WARP_CACHE") or tempfile.mkdtemp(
        prefix="instantmimic-warp-cache-"
    )
    wp.init()
    if not wp.is_cuda_available():
        print("error: capture needs a CUDA GPU (plans recorded on the CPU do not describe CUDA launches)",
              file=sys.stderr)
        return 1

    out = pathlib.Path(args.out)
    (out / "raw").mkdir(parents=True, exist_ok=True)
    started = time.time()
    plans = []
    mjm = None
    with wp.ScopedDevice("cuda:0"):
        training = physics.training_config(config)
        for nworld in args.nworld:
            entries, mjm = capture_plans(config, nworld, out)
            plans.extend(entries)
            if training is not None:
                entries, _ = capture_plans(training, nworld, out, {physics.TRAINING_STEP_PLAN: "step"})
                plans.extend(entries)
    device = wp.get_device("cuda:0")
    manifest = {
        "format": 1,
        "warp": wp.__version__,
        "captured_on": {"gpu": device.name, "arch": device.arch},
        "ptx_arch": physics.PTX_ARCH,
        "physics": physics.physics_info(config, mjm),
        "plans": plans,
    }
    (out / "manifest.json").write_text(json.dumps(manifest, indent=1, sort_keys=True) + "\n")
    if not os.environ.get("INSTANTMIMIC_WARP_CACHE"):
        shutil.rmtree(wp.config.kernel_cache_dir, ignore_errors=True)
    print(f"captured {len(plans)} plans in {time.time() - started:.1f} s -> {out}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
