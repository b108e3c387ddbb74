"""Compile our own env kernels (kernels_py/env/) to PTX and describe their ABI (no GPU needed).

    python kernels_py/env_build.py            # write ptx/env/*.ptx and ptx/env/manifest.json
    python kernels_py/env_build.py --check    # exit 1 if ptx/env differs from what this produces

`kernels_py/compile.py` runs the same step next to the MuJoCo Warp modules (and `--check`s it).

Every module `kernels_py/env/<name>.py` that defines `@wp.kernel`s becomes `ptx/env/<name>.ptx`,
compiled ahead of time for physics.PTX_ARCH with Warp's bundled NVRTC and canonicalized
(ptx_canon.py). Modules are compiled with `strip_hash=True`: kernel entry names are
`<kernel>_cuda_kernel_forward`, stable across edits, so the Rust launchers generated from the
manifest keep their names; the PTX itself is still checked byte for byte by `--check`. (Warp
forbids `strip_hash` for generic kernels with several overloads; env kernels are not generic.)

`ptx/env/manifest.json` describes every kernel: module, entry, launch dimensionality, block size,
shared memory, its launch contract (the rules of the module's `LAUNCH` dict for it), and
each parameter in order (kind, dtype, array ndim, byte offset, size and alignment, and `io`:
whether the kernel reads it, writes it or both, derived from the kernel's source and the
`@wp.func`s it calls), plus the layouts of Warp's `launch_bounds_t<N>` and `array_t<T>`. Sizes come from
Warp's own ctypes mirrors of its C++ structs and are checked against the `.param` declarations
NVRTC wrote into the PTX. `build.rs` turns the manifest into typed Rust launchers. The format is
documented in docs/kernels.md.
"""

from __future__ import annotations

import argparse
import ast
import ctypes
import importlib
import inspect
import json
import pathlib
import re
import sys
import tempfile
import textwrap

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
import physics  # noqa: E402
import ptx_canon  # noqa: E402

KERNELS_DIR = pathlib.Path(__file__).resolve().parent / "env"
PACKAGE = "env"
PTX_DIR = physics.REPO / "ptx"
OUT_SUBDIR = "env"
MANIFEST_NAME = "manifest.json"
# Bump when the manifest's meaning changes; build.rs refuses other formats. Format 2 added each
# kernel's launch contract (`launch`) and each parameter's direction (`io`).
MANIFEST_FORMAT = 2

# Scalar names as Warp spells them (types.py); bfloat16 has no Rust type here and is refused.
SCALARS = ("bool", "int8", "uint8", "int16", "uint16", "int32", "uint32", "int64", "uint64", "float16", "float32", "float64")


class EnvBuildError(RuntimeError):
    """A kernel the pipeline cannot describe or compile; the message names it and says why."""


def module_names() -> list[str]:
    """Kernel module files under kernels_py/env/, sorted (private `_*.py` files excluded)."""
    return sorted(p.stem for p in KERNELS_DIR.glob("*.py") if not p.name.startswith("_"))


def _ctype_layout(ctype) -> dict:
    return {"size": ctypes.sizeof(ctype), "align": ctypes.alignment(ctype)}


def _fields(ctype) -> dict:
    return {name: getattr(ctype, name).offset for name, *_ in ctype._fields_}


def warp_abi() -> dict:
    """Layouts of the structs Warp passes to every kernel, from Warp's ctypes mirrors of
    `launch_bounds_t<N>` (native/builtin.h) and `array_t<T>` (native/array.h)."""
    from warp._src import types as wt

    bounds = []
    for dim in range(1, wt.LAUNCH_MAX_DIMS + 1):
        ctype = wt._launch_bounds_classes[dim]
        bounds.append({"dim": dim, **_ctype_layout(ctype), "fields": _fields(ctype)})
    return {
        "array": {**_ctype_layout(wt.array_t), "max_dims": wt.ARRAY_MAX_DIMS, "fields": _fields(wt.array_t)},
        "launch_bounds": bounds,
    }


def _scalar_name(t, where: str) -> str:
    name = getattr(t, "__name__", repr(t))
    if name not in SCALARS:
        raise EnvBuildError(f"{where}: scalar type {name} is not supported (supported: {', '.join(SCALARS)})")
    return name


def _dtype(t, where: str) -> dict:
    """A Warp value type: a scalar, or a fixed-size vector/matrix/quaternion/transform of one."""
    import warp as wp
    from warp._src import types as wt

    if hasattr(t, "_wp_scalar_type_") and hasattr(t, "_shape_"):
        return {"warp": t.__name__, "scalar": _scalar_name(t._wp_scalar_type_, where), "shape": list(t._shape_)}
    if t is wp.bool or t in wt.scalar_types:
        return {"warp": t.__name__, "scalar": _scalar_name(t, where), "shape": []}
    raise EnvBuildError(f"{where}: type {t!r} is not a Warp scalar, vector or matrix type")


def _value_layout(t) -> dict:
    import warp as wp

    if t is wp.bool:
        return _ctype_layout(ctypes.c_bool)
    if hasattr(t, "_wp_scalar_type_") and hasattr(t, "_shape_"):
        return _ctype_layout(t)  # vector/matrix classes are ctypes arrays
    return _ctype_layout(t._type_)


def describe_type(t, where: str, structs: dict) -> dict:
    """Kind, dtype and layout of one parameter or struct field type; registers structs."""
    from warp._src import codegen
    from warp._src import types as wt

    if type(t) is wt.array:
        return {"kind": "array", "dtype": _dtype(t.dtype, where), "ndim": t.ndim, **_ctype_layout(wt.array_t)}
    if isinstance(t, wt.Array):
        raise EnvBuildError(f"{where}: {type(t).__name__} parameters are not supported (use wp.array)")
    if isinstance(t, codegen.Struct):
        _register_struct(t, structs)
        return {"kind": "struct", "struct": t.key, **_ctype_layout(t.ctype)}
    dtype = _dtype(t, where)
    return {"kind": "vector" if dtype["shape"] else "scalar", "dtype": dtype, **_value_layout(t)}


def _register_struct(s, structs: dict):
    fields = []
    for name, var in s.vars.items():
        field = {"name": name, **describe_type(var.type, f"struct {s.key}, field {name}", structs)}
        field["offset"] = getattr(s.ctype, name).offset
        fields.append(field)
    entry = {"fields": fields, **_ctype_layout(s.ctype)}
    known = structs.get(s.key)
    if known is not None and known != entry:
        raise EnvBuildError(f"two different Warp structs are named {s.key}: rename one")
    structs[s.key] = entry


def _align_up(offset: int, align: int) -> int:
    return (offset + align - 1) // align * align


# A parameter declaration in a PTX entry: `.param .align 8 .b8 name[56]` or `.param .f32 name`.
_PTX_PARAM = re.compile(r"\.param\s+(?:\.align\s+(\d+)\s+)?\.([a-z]+)(\d+)\s+[\w$]+(?:\[(\d+)\])?")


def ptx_entry_params(ptx: str, entry: str) -> list[tuple[int, int]]:
    """(size, align) of each parameter of `.entry <entry>(...)` as NVRTC declared it."""
    match = re.search(r"\.entry\s+" + re.escape(entry) + r"\s*\(([^)]*)\)", ptx)
    if match is None:
        raise EnvBuildError(f"entry {entry} not found in the PTX")
    params = []
    for decl in match.group(1).split(","):
        decl = decl.strip()
        if not decl:
            continue
        m = _PTX_PARAM.fullmatch(decl)
        if m is None:
            raise EnvBuildError(f"entry {entry}: cannot read parameter declaration {decl!r}")
        align, _, bits, count = m.groups()
        element = int(bits) // 8
        size = element * int(count) if count else element
        params.append((size, int(align) if align else element))
    return params


# Warp builtins that take arrays, by what they do to their first argument: read it, write it, or
# read-modify-write it (atomics accumulate into what is there). Any other builtin given an array
# parameter stops the build until it is added here.
ARRAY_READS = frozenset({"tile_load"})
ARRAY_WRITES = frozenset({"tile_store"})
ARRAY_UPDATES = frozenset(
    {"atomic_add", "atomic_sub", "atomic_min", "atomic_max", "atomic_exch", "atomic_cas", "atomic_and", "atomic_or",
     "atomic_xor", "tile_atomic_add"}
)


def _function_ast(func) -> ast.FunctionDef:
    tree = ast.parse(textwrap.dedent(inspect.getsource(func)))
    node = tree.body[0]
    if not isinstance(node, ast.FunctionDef):
        raise EnvBuildError(f"{func.__qualname__}: cannot read its source as a function")
    return node


def array_accesses(func, arrays: list[str], where: str, depth: int = 0) -> dict[str, set[str]]:
    """What the Python function `func` (a kernel's or a `@wp.func`'s) does with its parameters
    named in `arrays`: {"read", "write"} subsets, from its source. Element loads and stores,
    augmented assignments, the builtins above, and `@wp.func` calls (followed into the callee)
    are understood; any other use of an array parameter (aliasing, an unknown builtin) is an
    error, so that `io` is never guessed."""
    from warp._src import context

    if depth > 32:
        raise EnvBuildError(f"{where}: @wp.func calls nest too deep to follow")
    node = _function_ast(func)
    uses: dict[str, set[str]] = {name: set() for name in arrays}
    handled: set[int] = set()

    def array_name(expr) -> str | None:
        return expr.id if isinstance(expr, ast.Name) and expr.id in uses else None

    for sub in ast.walk(node):
        if isinstance(sub, ast.Attribute) and array_name(sub.value) and sub.attr in ("shape", "ndim", "dtype"):
            handled.add(id(sub.value))
        elif isinstance(sub, ast.Subscript) and (name := array_name(sub.value)):
            handled.add(id(sub.value))
            uses[name].add("write" if isinstance(sub.ctx, ast.Store) else "read")
        elif isinstance(sub, ast.AugAssign) and isinstance(sub.target, ast.Subscript):
            if name := array_name(sub.target.value):
                uses[name].add("read")
        elif isinstance(sub, ast.Call):
            call_args = list(sub.args) + [k.value for k in sub.keywords]
            passed = [a for a in call_args if array_name(a)]
            if not passed:
                continue
            target = sub.func
            if isinstance(target, ast.Attribute) and isinstance(target.value, ast.Name) and target.value.id == "wp":
                builtin = target.attr
                first = sub.args[0] if sub.args else None
                if builtin in ARRAY_READS | ARRAY_WRITES | ARRAY_UPDATES and first is not None and array_name(first):
                    if builtin not in ARRAY_WRITES:
                        uses[first.id].add("read")
                    if builtin not in ARRAY_READS:
                        uses[first.id].add("write")
                    handled.add(id(first))
                    if len(passed) == 1:
                        continue
                raise EnvBuildError(
                    f"{where}: wp.{builtin} takes array parameter(s) {[a.id for a in passed]} at line "
                    f"{sub.lineno} of {func.__qualname__}; add it to ARRAY_READS / ARRAY_WRITES / ARRAY_UPDATES in "
                    "kernels_py/env_build.py"
                )
            callee = func.__globals__.get(target.id) if isinstance(target, ast.Name) else None
            if not isinstance(callee, context.Function) or getattr(callee, "func", None) is None:
                raise EnvBuildError(
                    f"{where}: {ast.unparse(target)} takes array parameter(s) {[a.id for a in passed]} at line "
                    f"{sub.lineno} of {func.__qualname__}, and is neither a @wp.func nor a builtin env_build.py knows"
                )
            callee_params = [a.arg for a in _function_ast(callee.func).args.args]
            bound = dict(zip(callee_params, sub.args))
            bound.update({k.arg: k.value for k in sub.keywords})
            mapping = {param: arg.id for param, arg in bound.items() if array_name(arg)}
            inner = array_accesses(callee.func, list(mapping), where, depth + 1)
            for param, caller_name in mapping.items():
                uses[caller_name] |= inner[param]
            handled.update(id(a) for a in passed)
    for sub in ast.walk(node):
        if isinstance(sub, ast.Name) and sub.id in uses and id(sub) not in handled:
            raise EnvBuildError(
                f"{where}: array parameter {sub.id} is used at line {sub.lineno} of {func.__qualname__} in a way "
                "env_build.py cannot follow (aliased, or passed to something unknown), so its `io` cannot be derived"
            )
    return uses


def _io(accesses: set[str]) -> str:
    if accesses == {"read", "write"}:
        return "inout"
    return "out" if accesses == {"write"} else "in"


def describe_kernel(
    kernel, module_name: str, ptx: str, meta: dict, block_dim: int, structs: dict, launch_contracts: dict
) -> dict:
    from warp._src import codegen

    where = f"kernels_py/env/{module_name}.py, kernel {kernel.key}"
    if not kernel.grid_stride:
        raise EnvBuildError(f"{where}: the Rust launchers use a 1-D grid and need the grid-stride loop (grid_stride=True)")
    entry = codegen.cuda_kernel_forward_name(kernel)
    dim = kernel.adj.kernel_dim
    abi = warp_abi()
    bounds = abi["launch_bounds"][dim - 1]
    offset = bounds["size"]
    params = []
    for arg in kernel.adj.args:
        param = {"name": arg.label, **describe_type(arg.type, f"{where}, parameter {arg.label}", structs)}
        offset = _align_up(offset, param["align"])
        param["offset"] = offset
        offset += param["size"]
        params.append(param)

    declared = ptx_entry_params(ptx, entry)
    described = [(bounds["size"], bounds["align"])] + [(p["size"], p["align"]) for p in params]
    if declared != described:
        raise EnvBuildError(
            f"{where}: the PTX declares parameters (size, align) {declared}, the description says {described}: "
            "Warp's ABI changed; update env_build.py and the Rust side together"
        )
    arrays = [p["name"] for p in params if p["kind"] == "array"]
    accesses = array_accesses(kernel.func, arrays, where)
    for param in params:
        param["io"] = _io(accesses[param["name"]]) if param["kind"] == "array" else "in"
    launch = launch_contracts.get(kernel.key)
    if not launch or not all(isinstance(rule, str) and rule.strip() for rule in launch):
        raise EnvBuildError(
            f"{where}: no launch contract; add the kernel to the module's LAUNCH dict at the end of the file, "
            "with rules saying what its launch dimension must equal or not exceed (docs/kernels.md, "
            '"Launch contracts")'
        )
    doc = inspect.getdoc(kernel.func) or ""
    return {
        "name": kernel.key,
        "entry": entry,
        "dim": dim,
        "block_dim": block_dim,
        "smem_bytes": int(meta.get(f"{entry}_smem_bytes", 0)),
        "doc": doc,
        "params": params,
        "launch": list(launch),
    }


def compile_env_module(name: str, workdir: pathlib.Path, structs: dict) -> tuple[bytes, dict]:
    """PTX of kernels_py/env/<name>.py and its manifest entry, or (b"", None) without kernels."""
    import warp as wp

    py_module = importlib.import_module(f"{PACKAGE}.{name}")
    module = wp.get_module(f"{PACKAGE}.{name}")
    launch_contracts = getattr(py_module, "LAUNCH", {})
    if not module.kernels:
        return b"", None
    unknown = sorted(set(launch_contracts) - set(module.kernels))
    if unknown:
        raise EnvBuildError(f"kernels_py/env/{name}.py: LAUNCH names {unknown}, which are not kernels of the module")
    for kernel in module.kernels.values():
        where = f"kernels_py/env/{name}.py, kernel {kernel.key}"
        if kernel.is_generic:
            raise EnvBuildError(f"{where}: generic kernels are not supported (give every parameter a concrete type)")
        if kernel.options.get("entry_point_abi", "warp") != "warp":
            raise EnvBuildError(f"{where}: only Warp's default entry-point ABI is supported")
    if module.options.get("enable_backward"):
        raise EnvBuildError(
            f"kernels_py/env/{name}.py: set wp.set_module_options({{'enable_backward': False}}); "
            "backward kernels are not described by the manifest"
        )
    paths = wp.compile_aot_module(
        module, arch=physics.PTX_ARCH, use_ptx=True, module_dir=str(workdir), strip_hash=True
    )
    path = pathlib.Path(paths[-1])
    ptx = ptx_canon.canonicalize(path.read_bytes())
    meta_path = path.with_name(f"wp_{PACKAGE}.{name}.meta")
    meta = json.loads(meta_path.read_text()) if meta_path.is_file() else {}
    text = ptx.rstrip(b"\0").decode("utf-8")
    block_dim = int(module.options["block_dim"])
    kernels = [describe_kernel(k, name, text, meta, block_dim, structs, launch_contracts) for k in module.kernels.values()]
    entry = {
        "name": name,
        "source": f"kernels_py/env/{name}.py",
        "ptx": f"{OUT_SUBDIR}/{name}.ptx",
        "kernels": kernels,
    }
    return ptx, entry


def generate() -> dict[str, bytes]:
    """Every file of ptx/env/, by path relative to ptx/. Warp must be configured (physics.configure_warp)
    and initialized."""
    import warp as wp

    files = {}
    modules = []
    structs: dict = {}
    with tempfile.TemporaryDirectory(prefix="instantmimic-env-aot-") as tmp:
        for name in module_names():
            ptx, entry = compile_env_module(name, pathlib.Path(tmp), structs)
            if entry is None:
                continue
            files[entry["ptx"]] = ptx
            modules.append(entry)
    seen = {}
    for module in modules:
        for kernel in module["kernels"]:
            if kernel["name"] in seen:
                raise EnvBuildError(
                    f"kernel {kernel['name']} is defined in both {seen[kernel['name']]} and {module['source']}: "
                    "the Rust launchers are named by kernel, so names must be unique"
                )
            seen[kernel["name"]] = module["source"]
    manifest = {
        "format": MANIFEST_FORMAT,
        "warp_version": wp.config.version,
        "ptx_arch": physics.PTX_ARCH,
        "abi": warp_abi(),
        "structs": dict(sorted(structs.items())),
        "modules": modules,
    }
    files[f"{OUT_SUBDIR}/{MANIFEST_NAME}"] = (json.dumps(manifest, indent=2) + "\n").encode("utf-8")
    return files


def sync(files: dict[str, bytes], out: pathlib.Path, check: bool) -> int:
    """Write `files` under `out` (removing stale ptx/env files), or with `check` compare; 0 if ok."""
    subdir = out / OUT_SUBDIR
    existing = {p.relative_to(out).as_posix() for p in subdir.glob("*") if p.is_file()}
    stale = sorted(existing - files.keys())
    if check:
        differ = [rel for rel, data in files.items() if not (out / rel).is_file() or (out / rel).read_bytes() != data]
        for rel in differ:
            print(f"differs: {rel}", file=sys.stderr)
        for rel in stale:
            print(f"not produced by kernels_py/env: {rel}", file=sys.stderr)
        if differ or stale:
            print(
                f"error: ptx/{OUT_SUBDIR} is not what kernels_py/env_build.py produces ({len(differ)} differ, "
                f"{len(stale)} stale); run it and commit the result",
                file=sys.stderr,
            )
            return 1
        print(f"ok: {len(files)} env kernel files reproduced byte for byte")
        return 0
    subdir.mkdir(parents=True, exist_ok=True)
    for rel in stale:
        (out / rel).unlink()
    for rel, data in sorted(files.items()):
        (out / rel).write_bytes(data)
    print(f"wrote {len(files)} env kernel files ({sum(map(len, files.values())) / 1e3:.0f} kB) to {subdir}")
    return 0


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", default=str(PTX_DIR), help="the ptx/ directory to write or check")
    parser.add_argument("--check", action="store_true", help="compare with --out instead of writing")
    args = parser.parse_args(argv)

    wp = physics.configure_warp()
    wp.config.kernel_cache_dir = tempfile.mkdtemp(prefix="instantmimic-warp-cache-")
    wp.init()
    try:
        files = generate()
    except EnvBuildError as e:
        print(f"error: {e}", file=sys.stderr)
        return 1
    return sync(files, pathlib.Path(args.out), args.check)


if __name__ == "__main__":
    sys.exit(main())
