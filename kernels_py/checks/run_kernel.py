"""Run env kernels on Warp's CPU device for the f64 reference checks (tests/env_kernels_cpu.rs).

    python kernels_py/checks/run_kernel.py SPEC_DIR [--cache DIR]

SPEC_DIR/spec.json lists programs. A program owns named buffers (raw little-endian `.bin` files
in its directory, with dtype and shape) and runs steps in order: kernel launches, with every
argument given by name in the kernel's parameter order (a buffer, a scalar, or a `@wp.struct` as
a dict of its fields), and element copies between buffers (what the Rust rollout does with
`memcpy_dtod` between launches). After the last step every buffer is written back to
`<name>.out.bin`. The Rust side (tests/kernel_checks/) writes the spec, compares the outputs with
its f64 references, and runs the very same programs through the generated launchers on a GPU
(tests/gpu_env_kernels.rs).

    {"format": 1, "programs": [{
        "name": "pd_control: ...", "dir": "p000",
        "buffers": [{"name": "qpos", "dtype": "float32", "shape": [64, 43]}, ...],
        "steps": [
            {"launch": {"module": "control", "kernel": "pd_control", "dim": 768, "block_dim": 256,
                        "args": [{"name": "actions", "buffer": "actions"},
                                 {"name": "action_scale", "scalar": {"dtype": "float32", "value": 1.0}},
                                 {"name": "params", "struct": {"dt": {"dtype": "float32", "value": 0.033}}}]}},
            {"copy": {"src": "count", "src_offset": 1, "dst": "count", "dst_offset": 0, "count": 1}}]}]}

Every name, dtype and dimensionality is checked against the kernel's own signature, so a spec
that does not match the kernel fails here with a message instead of running garbage.

`--cache DIR` keeps compiled CPU modules between runs, in a subdirectory named after a digest of
the kernel sources (older ones are removed). Warp's own module hash is not enough: in Warp 1.19
it does not cover the body of a `@wp.func` passed to `wp.tile_map` (editing policy.py's
`add_elu` reloads the stale cached module), so a cache keyed by Warp's hash alone can run old
code.
"""

from __future__ import annotations

import argparse
import hashlib
import importlib
import json
import pathlib
import re
import shutil
import sys

KERNELS_PY = pathlib.Path(__file__).resolve().parent.parent
sys.path.insert(0, str(KERNELS_PY))

SPEC_FORMAT = 1
DTYPES = {"float32": "<f4", "float64": "<f8", "int32": "<i4"}
NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")


class SpecError(RuntimeError):
    """A spec that does not describe a valid run; the message says where."""


def warp_dtype(wp, name: str):
    return {"float32": wp.float32, "float64": wp.float64, "int32": wp.int32}[name]


def load_buffers(wp, program: dict, directory: pathlib.Path) -> dict:
    import numpy as np

    buffers = {}
    for b in program["buffers"]:
        name, dtype, shape = b["name"], b["dtype"], tuple(b["shape"])
        if not NAME.match(name) or name in buffers:
            raise SpecError(f"buffer name {name!r} is not a unique identifier")
        if dtype not in DTYPES:
            raise SpecError(f"buffer {name}: dtype {dtype} (supported: {', '.join(DTYPES)})")
        data = np.fromfile(directory / f"{name}.bin", dtype=DTYPES[dtype])
        count = int(np.prod(shape)) if shape else 1
        if data.size != count:
            raise SpecError(f"buffer {name}: {data.size} values in the file, shape {list(shape)} needs {count}")
        buffers[name] = wp.array(data.reshape(shape), dtype=warp_dtype(wp, dtype), device="cpu")
    return buffers


def scalar_value(wp, spec: dict, expected, where: str):
    dtype = warp_dtype(wp, spec["dtype"])
    if dtype is not expected:
        raise SpecError(f"{where}: {spec['dtype']} given, the kernel takes {expected.__name__}")
    return dtype(spec["value"])


def build_struct(wp, struct_type, fields: dict, where: str):
    declared = list(struct_type.vars.keys())
    if sorted(declared) != sorted(fields):
        raise SpecError(f"{where}: fields {sorted(fields)} given, {struct_type.key} has {declared}")
    value = struct_type()
    for field in declared:
        setattr(value, field, scalar_value(wp, fields[field], struct_type.vars[field].type, f"{where}.{field}"))
    return value


def launch_args(wp, kernel, launch: dict, buffers: dict) -> list:
    from warp._src import codegen
    from warp._src import types as wt

    declared = kernel.adj.args
    given = launch["args"]
    names = [a["name"] for a in given]
    if names != [a.label for a in declared]:
        raise SpecError(f"{kernel.key}: arguments {names}, the kernel takes {[a.label for a in declared]}")
    values = []
    for arg, spec in zip(declared, given):
        where = f"{kernel.key}({arg.label})"
        if isinstance(arg.type, wt.array):
            if "buffer" not in spec:
                raise SpecError(f"{where}: an array parameter needs a buffer")
            array = buffers.get(spec["buffer"])
            if array is None:
                raise SpecError(f"{where}: no buffer {spec['buffer']!r}")
            if array.dtype is not arg.type.dtype or array.ndim != arg.type.ndim:
                raise SpecError(
                    f"{where}: buffer {spec['buffer']} is {array.ndim}-D {array.dtype.__name__}, "
                    f"the kernel takes {arg.type.ndim}-D {arg.type.dtype.__name__}"
                )
            values.append(array)
        elif isinstance(arg.type, codegen.Struct):
            if "struct" not in spec:
                raise SpecError(f"{where}: a struct parameter needs a field dict")
            values.append(build_struct(wp, arg.type, spec["struct"], where))
        else:
            if "scalar" not in spec:
                raise SpecError(f"{where}: a scalar parameter needs a scalar")
            values.append(scalar_value(wp, spec["scalar"], arg.type, where))
    return values


def run_program(wp, program: dict, root: pathlib.Path) -> None:
    directory = root / program["dir"]
    buffers = load_buffers(wp, program, directory)
    for step in program["steps"]:
        if "launch" in step:
            launch = step["launch"]
            module = importlib.import_module(f"env.{launch['module']}")
            kernel = getattr(module, launch["kernel"], None)
            if not isinstance(kernel, wp.Kernel):
                raise SpecError(f"env.{launch['module']} has no kernel {launch['kernel']}")
            args = launch_args(wp, kernel, launch, buffers)
            wp.launch(kernel, dim=launch["dim"], inputs=args, block_dim=launch["block_dim"], device="cpu")
        elif "copy" in step:
            c = step["copy"]
            src, dst = buffers[c["src"]], buffers[c["dst"]]
            wp.copy(dst.flatten(), src.flatten(), c["dst_offset"], c["src_offset"], c["count"])
        else:
            raise SpecError(f"{program['name']}: unknown step {sorted(step)}")
    wp.synchronize_device("cpu")
    for name, array in buffers.items():
        array.numpy().tofile(directory / f"{name}.out.bin")


def source_cache_dir(root: pathlib.Path) -> pathlib.Path:
    """`root/<digest of kernels_py/env/*.py and this runner>`; other digests under root are
    removed (they hold modules of sources that no longer exist)."""
    digest = hashlib.sha256()
    for path in sorted((KERNELS_PY / "env").glob("*.py")) + [pathlib.Path(__file__).resolve()]:
        digest.update(path.name.encode() + b"\0" + path.read_bytes())
    name = "src-" + digest.hexdigest()[:16]
    if root.is_dir():
        for old in root.glob("src-*"):
            if old.name != name:
                shutil.rmtree(old, ignore_errors=True)
    return root / name


def main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("spec_dir", type=pathlib.Path)
    parser.add_argument("--cache", type=pathlib.Path, help="Warp kernel cache directory")
    args = parser.parse_args(argv)

    import physics

    wp = physics.configure_warp()
    if args.cache is not None:
        wp.config.kernel_cache_dir = str(source_cache_dir(args.cache))
    wp.init()
    spec = json.loads((args.spec_dir / "spec.json").read_text())
    if spec.get("format") != SPEC_FORMAT:
        raise SpecError(f"spec format {spec.get('format')}, this runner reads {SPEC_FORMAT}")
    for program in spec["programs"]:
        try:
            run_program(wp, program, args.spec_dir)
        except SpecError as e:
            raise SpecError(f"{program['name']}: {e}") from None
    return 0


if __name__ == "__main__":
    try:
        sys.exit(main(sys.argv[1:]))
    except SpecError as e:
        print(f"run_kernel.py: {e}", file=sys.stderr)
        sys.exit(2)
