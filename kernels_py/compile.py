"""Regenerate the PTX of every MuJoCo Warp module the committed plans use (no GPU needed).

    python kernels_py/compile.py              # write ptx/mjwarp/*.ptx and ptx/env/ (our kernels)
    python kernels_py/compile.py --check      # exit 1 if ptx/ differs from what this produces
    python kernels_py/compile.py --only env   # only our env kernels (env_build.py; no plans needed)

The plans (ptx/plans/manifest.json) name each module by Warp's content hash and the block size
it was launched with. This script rebuilds the same model with the physics the plans were
captured with, runs each plan's MuJoCo Warp calls once on Warp's CPU device so that Warp creates
the same module objects, checks that each module hashes to the recorded value, and compiles it
ahead of time to PTX for physics.PTX_ARCH with Warp's bundled NVRTC. Virtual registers are then
renumbered canonically (ptx_canon.py), since NVRTC's numbering varies between runs. Same inputs,
same bytes.

Our own env kernels (kernels_py/env/) are compiled in the same run by env_build.py, into ptx/env/
with their manifest (docs/kernels.md).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import pathlib
import sys
import tempfile

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
import env_build  # noqa: E402
import physics  # noqa: E402
import ptx_canon  # noqa: E402

PTX_DIR = physics.REPO / "ptx"
MANIFEST = PTX_DIR / "plans" / "manifest.json"
MJWARP_DIR = "mjwarp"


class CompileError(RuntimeError):
    pass


def character_digest(config: dict) -> str:
    return hashlib.sha256((physics.REPO / config["character"]).read_bytes()).hexdigest()


def instantiate_modules(config: dict, nworlds: list[int]) -> dict:
    """Run every plan once on the CPU device (the training step too, with its solver iterations,
    where the config has them); return Warp's module registry afterwards."""
    import warp as wp
    from warp._src import context as wp_context

    training = physics.training_config(config)
    with wp.ScopedDevice("cpu"):
        for nworld in nworlds:
            _, m, d = physics.make_model_data(config, nworld)
            for name in physics.PLAN_NAMES:
                physics.run_plan(name, m, d)
            if training is not None:
                _, m, d = physics.make_model_data(training, nworld)
                physics.run_plan("step", m, d)
    wp.synchronize()
    return dict(wp_context.user_modules)


def compile_module(module, block_dim: int, workdir: pathlib.Path) -> tuple[str, bytes]:
    """PTX of one block-size variant of a module: (file name Warp gives it, bytes)."""
    import warp as wp

    saved = module.options["block_dim"]
    module.options["block_dim"] = block_dim
    try:
        paths = wp.compile_aot_module(module, arch=physics.PTX_ARCH, use_ptx=True, module_dir=str(workdir))
    finally:
        module.options["block_dim"] = saved
    path = pathlib.Path(paths[-1])
    # NVRTC numbers virtual registers differently from run to run for some modules (see
    # ptx_canon.py); the canonical numbering makes the file a function of the source alone.
    return path.name, ptx_canon.canonicalize(path.read_bytes())


def generate(manifest: dict) -> dict[str, bytes]:
    """Every PTX file the manifest's plans need, by path relative to ptx/."""
    config = manifest["physics"]["config"]
    expected_digest = manifest["physics"].get("character_sha256")
    if expected_digest and character_digest(config) != expected_digest:
        raise CompileError(
            f"{config['character']} changed since the plans were captured: capture them again "
            "(kernels_py/capture.py) before compiling"
        )
    wanted = {}
    for plan in manifest["plans"]:
        for mod in plan["modules"]:
            if len(mod["block_dims"]) != 1:
                raise CompileError(f"module {mod['ptx']}: expected one block size, the plan recorded {mod['block_dims']}")
            wanted[mod["ptx"]] = mod
    registry = instantiate_modules(config, sorted({p["nworld"] for p in manifest["plans"]}))

    out = {}
    problems = []
    with tempfile.TemporaryDirectory(prefix="instantmimic-aot-") as tmp:
        for ptx_name, mod in sorted(wanted.items()):
            module = registry.get(mod["name"])
            if module is None:
                problems.append(f"{ptx_name}: Warp module {mod['name']!r} was not created by the CPU run")
                continue
            block_dim = mod["block_dims"][0]
            digest = module.get_module_hash(block_dim).hex()
            if digest != mod["hash"]:
                problems.append(
                    f"{ptx_name}: module {mod['name']!r} at block_dim {block_dim} hashes to {digest[:7]}, "
                    f"the plan recorded {mod['hash'][:7]} (different warp/mujoco_warp version or physics?)"
                )
                continue
            name, data = compile_module(module, block_dim, pathlib.Path(tmp))
            if physics.ptx_file_name(name) != ptx_name:
                problems.append(f"{ptx_name}: Warp named the compiled module {name}")
                continue
            out[f"{MJWARP_DIR}/{ptx_name}"] = data
    if problems:
        raise CompileError("cannot reproduce the plans' modules:\n  " + "\n  ".join(problems))
    return out


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--manifest", default=str(MANIFEST))
    parser.add_argument("--out", default=str(PTX_DIR), help="the ptx/ directory to write or check")
    parser.add_argument("--check", action="store_true", help="compare with --out instead of writing")
    parser.add_argument(
        "--only",
        choices=("all", "mjwarp", "env"),
        default="all",
        help="which files: the plans' MuJoCo Warp modules, our env kernels, or both (default)",
    )
    args = parser.parse_args(argv)

    wp = physics.configure_warp()
    wp.config.kernel_cache_dir = tempfile.mkdtemp(prefix="instantmimic-warp-cache-")
    wp.init()
    status = 0
    if args.only in ("all", "mjwarp"):
        status = max(status, compile_mjwarp(args))
    if args.only in ("all", "env"):
        status = max(status, compile_env(args))
    return status


def compile_env(args) -> int:
    """ptx/env/: our kernels and their manifest (env_build.py)."""
    try:
        files = env_build.generate()
    except env_build.EnvBuildError as e:
        print(f"error: {e}", file=sys.stderr)
        return 1
    return env_build.sync(files, pathlib.Path(args.out), args.check)


def compile_mjwarp(args) -> int:
    """ptx/mjwarp/: the MuJoCo Warp modules the committed plans launch. Warp is initialized."""
    try:
        manifest = json.loads(pathlib.Path(args.manifest).read_text())
    except (OSError, json.JSONDecodeError) as e:
        print(f"error: {args.manifest}: {e}", file=sys.stderr)
        return 2

    try:
        files = generate(manifest)
    except CompileError as e:
        print(f"error: {e}", file=sys.stderr)
        return 1

    out = pathlib.Path(args.out)
    existing = {p.relative_to(out).as_posix() for p in (out / MJWARP_DIR).glob("*.ptx")}
    if args.check:
        differ = [rel for rel, data in files.items() if not (out / rel).is_file() or (out / rel).read_bytes() != data]
        stale = sorted(existing - files.keys())
        for rel in differ:
            print(f"differs: {rel}", file=sys.stderr)
        for rel in stale:
            print(f"not produced by the plans' modules: {rel}", file=sys.stderr)
        if differ or stale:
            print(f"error: ptx/ is not what kernels_py/compile.py produces ({len(differ)} differ, "
                  f"{len(stale)} stale); run it and commit the result", file=sys.stderr)
            return 1
        print(f"ok: {len(files)} PTX files reproduced byte for byte")
        return 0
    (out / MJWARP_DIR).mkdir(parents=True, exist_ok=True)
    for rel in sorted(existing - files.keys()):
        (out / rel).unlink()
    for rel, data in files.items():
        (out / rel).write_bytes(data)
    print(f"wrote {len(files)} PTX files ({sum(map(len, files.values())) / 1e6:.1f} MB) to {out / MJWARP_DIR}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
