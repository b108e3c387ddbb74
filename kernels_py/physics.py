"""The physics model and plan definitions shared by `capture.py` (GPU) and `compile.py` (CPU).

Both scripts must build the *same* MuJoCo Warp modules: Warp names each module by a hash of its
source and options, and the Rust runtime finds a plan's PTX by that name. So every Warp setting
that changes generated code is set here, once, before Warp initializes (`configure_warp`).
"""

from __future__ import annotations

import dataclasses
import pathlib
import re
import tomllib

REPO = pathlib.Path(__file__).resolve().parent.parent

# PTX is generated for the oldest supported GPU (Ampere, sm_80). The driver JIT-compiles it for
# the GPU it runs on, so one set of PTX serves sm_80 .. sm_120 (CI assembles it for each).
# (compile.py passes it to Warp's AOT compiler; run_shipped_ptx() makes a live Warp use it.)
PTX_ARCH = 80

# Keys of configs/physics/*.toml, with their types. Unknown keys are an error.
PHYSICS_KEYS = {
    "character": str,
    "timestep": float,
    "solver": str,
    "iterations": int,
    "ls_iterations": int,
    "cone": str,
    "integrator": str,
    "nconmax": int,
    "njmax": int,
    "graph_conditional": bool,
    "deterministic": bool,
}
# Optional keys, both or neither: the solver iterations of the training rollouts' step, captured
# as a second step plan, TRAINING_STEP_PLAN (the evaluation keeps `iterations`/`ls_iterations`).
OPTIONAL_PHYSICS_KEYS = {
    "training_iterations": int,
    "training_ls_iterations": int,
}

# The plans the runtime needs. `step` is one mj_step; `kinematics` is what a reset needs before
# observations are built: body poses (kinematics), centers of mass and inertias (com_pos), and
# body velocities (com_vel).
PLAN_NAMES = ("step", "kinematics")
# The step again, with `training_iterations` and `training_ls_iterations`, where the config has
# them (src/plan/store.rs TRAINING_STEP_PLAN; the training rollouts replay it).
TRAINING_STEP_PLAN = "training_step"


def training_config(config: dict) -> dict | None:
    """The config of the training step: `config` with its training solver iterations, or None."""
    if "training_iterations" not in config:
        return None
    return dict(config, iterations=config["training_iterations"], ls_iterations=config["training_ls_iterations"])


class ConfigError(ValueError):
    """A physics config that cannot be used; the message names the file and the key."""


def load_physics_config(path: str | pathlib.Path) -> dict:
    path = pathlib.Path(path)
    try:
        with open(path, "rb") as f:
            raw = tomllib.load(f)
    except (OSError, tomllib.TOMLDecodeError) as e:
        raise ConfigError(f"{path}: {e}") from e
    for key in raw:
        if key not in PHYSICS_KEYS and key not in OPTIONAL_PHYSICS_KEYS:
            known = ", ".join([*PHYSICS_KEYS, *OPTIONAL_PHYSICS_KEYS])
            raise ConfigError(f"{path}: unknown key `{key}` (known: {known})")
    for key, typ in PHYSICS_KEYS.items():
        if key not in raw:
            raise ConfigError(f"{path}: missing key `{key}`")
        value = raw[key]
        if typ is float and isinstance(value, int) and not isinstance(value, bool):
            value = float(value)
        if not isinstance(value, typ) or (typ is int and isinstance(value, bool)):
            raise ConfigError(f"{path}: `{key}` must be a {typ.__name__}, got {value!r}")
        raw[key] = value
    present = [key for key in OPTIONAL_PHYSICS_KEYS if key in raw]
    if present and len(present) != len(OPTIONAL_PHYSICS_KEYS):
        raise ConfigError(f"{path}: give {' and '.join(OPTIONAL_PHYSICS_KEYS)} together, or neither")
    for key in present:
        if not isinstance(raw[key], int) or isinstance(raw[key], bool) or raw[key] <= 0:
            raise ConfigError(f"{path}: `{key}` must be a positive int, got {raw[key]!r}")
    choices = {
        "solver": ("newton", "cg"),
        "cone": ("pyramidal", "elliptic"),
        "integrator": ("euler", "implicitfast", "implicit", "rk4"),
    }
    for key, allowed in choices.items():
        if raw[key] not in allowed:
            raise ConfigError(f"{path}: `{key}` must be one of {allowed}, got {raw[key]!r}")
    for key in ("iterations", "ls_iterations", "nconmax", "njmax"):
        if raw[key] <= 0:
            raise ConfigError(f"{path}: `{key}` must be positive, got {raw[key]}")
    if raw["deterministic"] and raw["cone"] != "pyramidal":
        # deterministic_solver.py replaces the Hessian kernel of pyramidal cones only.
        raise ConfigError(f"{path}: `cone` must be \"pyramidal\" with `deterministic = true`, got {raw['cone']!r}")
    if raw["deterministic"] and raw["njmax"] < 32:
        # deterministic_solver.qfrc_constraint_sparse regroups its (nworld, njmax) launch into
        # one 32-lane warp per world.
        raise ConfigError(f"{path}: `njmax` must be at least 32 with `deterministic = true`, got {raw['njmax']}")
    if not 0.0 < raw["timestep"] <= 0.05:
        raise ConfigError(f"{path}: `timestep` must be in (0, 0.05] s, got {raw['timestep']}")
    return raw


def configure_warp():
    """Warp settings that change generated code. Call before anything creates a Warp module.

    Output format and target arch are not among them: Warp hashes neither into module names,
    so a capture that runs Warp's default CUBIN path names the same modules compile.py turns
    into PTX.
    """
    import warp as wp

    wp.config.quiet = True
    # libmathdx tile kernels link LTO code and come out as CUBIN only; Warp's own tile
    # implementations give portable PTX. (These options are part of each module's hash.)
    wp.config.enable_mathdx_gemm = False
    wp.config.enable_mathdx_solver = False
    wp.config.enable_mathdx_fft = False
    return wp


def ptx_file_name(binary_filename: str) -> str:
    """ptx/mjwarp/ file of a module: Warp's binary name without its arch and format suffix
    (`wp_smooth_0b7e74a.sm90.cubin` -> `wp_smooth_0b7e74a.ptx`); one PTX serves every arch."""
    stem = re.sub(r"\.sm\d+[af]?\.(ptx|cubin)$", "", binary_filename)
    if stem == binary_filename:
        raise ValueError(f"unexpected Warp module binary name {binary_filename!r}")
    return stem + ".ptx"


def run_shipped_ptx():
    """Make this process's Warp run the PTX the Rust runtime loads, for bit-for-bit comparisons.

    Warp would otherwise compile CUBIN for the device's own arch, whose floating-point code can
    differ from the driver's JIT of our sm_80 PTX. With this hook Warp compiles every module to
    PTX for PTX_ARCH and, at its one CUDA module load site, loads that PTX after the two
    rewrites the shipped files and the runtime apply: canonical register numbering
    (compile.py) and `.version` lowered to what the driver accepts (src/cuda/ptx.rs). Warp's
    own conditional-node kernels keep their CUBIN path. Uses Warp internals (warp-lang 1.19).
    """
    import tempfile

    import warp as wp
    from warp._src import build, context

    import ptx_canon

    context.Module._use_ptx = lambda self, device: True
    original_arch = context.Module._get_compile_arch

    def compile_arch(self, device=None):
        arch = original_arch(self, device)
        return PTX_ARCH if arch is not None else None

    context.Module._get_compile_arch = compile_arch
    major, minor = context.runtime.driver_version[:2]  # e.g. (13, 0)
    isa = f"{major - 4}.{minor}" if major >= 13 else None
    original_load = build.load_cuda
    scratch = tempfile.mkdtemp(prefix="instantmimic-shipped-ptx-")

    def load_cuda(input_path, device):
        if not str(input_path).endswith(".ptx"):
            return original_load(input_path, device)
        text = ptx_canon.canonicalize(pathlib.Path(input_path).read_bytes()).rstrip(b"\0").decode()
        if isa is not None:
            text = re.sub(r"^\.version \d+\.\d+", f".version {isa}", text, count=1, flags=re.MULTILINE)
        out = pathlib.Path(scratch) / pathlib.Path(input_path).name
        out.write_text(text)
        return original_load(str(out), device)

    build.load_cuda = load_cuda
    return wp


def build_mjmodel(config: dict):
    import mujoco

    mjm = mujoco.MjModel.from_xml_path(str(REPO / config["character"]))
    mjm.opt.timestep = config["timestep"]
    mjm.opt.iterations = config["iterations"]
    mjm.opt.ls_iterations = config["ls_iterations"]
    mjm.opt.solver = {"newton": mujoco.mjtSolver.mjSOL_NEWTON, "cg": mujoco.mjtSolver.mjSOL_CG}[config["solver"]]
    mjm.opt.cone = {"pyramidal": mujoco.mjtCone.mjCONE_PYRAMIDAL, "elliptic": mujoco.mjtCone.mjCONE_ELLIPTIC}[
        config["cone"]
    ]
    mjm.opt.integrator = {
        "euler": mujoco.mjtIntegrator.mjINT_EULER,
        "implicitfast": mujoco.mjtIntegrator.mjINT_IMPLICITFAST,
        "implicit": mujoco.mjtIntegrator.mjINT_IMPLICIT,
        "rk4": mujoco.mjtIntegrator.mjINT_RK4,
    }[config["integrator"]]
    return mjm


def make_model_data(config: dict, nworld: int):
    """Model and Data on the current Warp device, in the reset state."""
    import mujoco
    import mujoco_warp as mjw
    from mujoco_warp._src.types import DeterminismType

    mjm = build_mjmodel(config)
    mjd = mujoco.MjData(mjm)
    mujoco.mj_forward(mjm, mjd)
    m = mjw.put_model(mjm)
    m.opt.graph_conditional = config["graph_conditional"]
    # MuJoCo Warp prints from its kernels when a world's solver or linesearch stops at its
    # iteration limit: routine with a few Newton iterations, and its advice names Python settings
    # a user of the binary does not have. The per-world flags in d.overflow are still set.
    # Capacity overflows (contacts, constraint rows: physics silently dropped) keep their warning.
    from mujoco_warp._src.types import OverflowType

    m.opt.warn_overflow = int(OverflowType.ALL & ~(OverflowType.ITERATIONS | OverflowType.LS_ITERATIONS))
    # Stable contact order and canonical constraint rows (determinism.py fills MuJoCo Warp's
    # empty hooks for both), and the solver's racing float sums in a fixed order
    # (deterministic_solver.py). Not DeterminismType.ATOMICS: Warp cannot record its
    # deterministic atomics into a plan.
    if config.get("deterministic", False):
        import determinism
        import deterministic_solver

        determinism.install()
        deterministic_solver.install()
        m.opt.deterministic = int(DeterminismType.CONTACTS | DeterminismType.CONSTRAINT)
    else:
        m.opt.deterministic = int(DeterminismType.NONE)
    d = mjw.put_data(mjm, mjd, nworld=nworld, nconmax=config["nconmax"], njmax=config["njmax"])
    return mjm, m, d


def run_plan(name: str, m, d):
    """The MuJoCo Warp calls one plan records."""
    import mujoco_warp as mjw
    from mujoco_warp._src import smooth

    if name == "step":
        mjw.step(m, d)
    elif name == "kinematics":
        mjw.fwd_kinematics(m, d)
        smooth.com_vel(m, d)
    else:
        raise ValueError(f"unknown plan {name!r} (known: {', '.join(PLAN_NAMES)})")


def named_arrays(m, d) -> dict:
    """Every Warp array of Model and Data, by a stable dotted name ("m.body_pos", "d.efc.J").

    Plans bind every array by name, so several plans share one buffer per name and the Rust
    runtime finds `d.qpos`, `d.xpos`, ... without knowing region ids.
    """
    import warp as wp

    out = {}

    def walk(prefix, obj, depth):
        if depth > 4 or not dataclasses.is_dataclass(obj):
            return
        for field in dataclasses.fields(obj):
            value = getattr(obj, field.name, None)
            name = f"{prefix}.{field.name}"
            if isinstance(value, wp.array):
                if value.ptr is not None and value.size > 0:
                    out[name] = value
            elif dataclasses.is_dataclass(value):
                walk(name, value, depth + 1)

    walk("m", m, 0)
    walk("d", d, 0)
    return out


def physics_info(config: dict, mjm) -> dict:
    """What a plan's consumer needs to know about the model it was captured from."""
    import hashlib

    return {
        "config": config,
        "character_sha256": hashlib.sha256((REPO / config["character"]).read_bytes()).hexdigest(),
        "nq": int(mjm.nq),
        "nv": int(mjm.nv),
        "nu": int(mjm.nu),
        "nbody": int(mjm.nbody),
    }
