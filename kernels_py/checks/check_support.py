"""Shared helpers of the `ppo_*.py` checks: Warp on its CPU device, error measures, a verdict.

Each check runs our kernels (the same source env_build.py compiles to PTX) on Warp's CPU device
on random inputs and compares them with numpy float64 references. The error of an array is
normwise, `max |x - ref| / max |ref|` (an elementwise ratio is meaningless where the reference
crosses zero); LIMIT is the project's tolerance. A check prints one line per comparison and exits
non-zero if any fails, so tests/ppo_kernels_cpu.rs can run it.
"""

from __future__ import annotations

import pathlib
import sys

KERNELS_PY = pathlib.Path(__file__).resolve().parent.parent
sys.path.insert(0, str(KERNELS_PY))

import numpy as np  # noqa: E402

import physics  # noqa: E402

LIMIT = 1e-4

wp = physics.configure_warp()
wp.init()
DEVICE = "cpu"


def relative_error(x, ref) -> float:
    """Normwise relative error of `x` against the float64 reference `ref`."""
    x = np.asarray(x, dtype=np.float64)
    ref = np.asarray(ref, dtype=np.float64)
    if x.shape != ref.shape:
        raise ValueError(f"shape {x.shape} against reference shape {ref.shape}")
    scale = np.max(np.abs(ref)) if ref.size else 0.0
    diff = np.max(np.abs(x - ref)) if ref.size else 0.0
    if not np.all(np.isfinite(x)):
        return float("inf")
    return float(diff / scale) if scale > 0.0 else float(diff)


def array(values, dtype=None):
    """A Warp CPU array of `values` (float32 unless `dtype` says otherwise)."""
    values = np.asarray(values)
    if dtype is None:
        dtype = wp.float32 if values.dtype.kind == "f" else wp.int32
    np_type = {wp.float32: np.float32, wp.float64: np.float64, wp.int32: np.int32}[dtype]
    return wp.array(np.ascontiguousarray(values, dtype=np_type), dtype=dtype, device=DEVICE)


def f32(values):
    """`values` rounded to float32 and held in float64: inputs whose reference sees exactly
    what the kernel reads."""
    return np.asarray(values, dtype=np.float32).astype(np.float64)


def zeros(shape, dtype=None):
    return wp.zeros(shape, dtype=dtype or wp.float32, device=DEVICE)


class Verdict:
    """Collects comparisons; `finish()` prints a summary and returns the exit status."""

    def __init__(self, name: str):
        self.name = name
        self.failures: list[str] = []
        self.count = 0

    def error(self, what: str, x, ref, limit: float = LIMIT) -> float:
        err = relative_error(x, ref)
        self.count += 1
        ok = err <= limit
        print(f"{self.name}: {what}: relative error {err:.3e} (limit {limit:.0e}) {'ok' if ok else 'FAIL'}")
        if not ok:
            self.failures.append(f"{what}: {err:.3e}")
        return err

    def check(self, what: str, condition: bool, detail: str = "") -> bool:
        self.count += 1
        print(f"{self.name}: {what}{': ' + detail if detail else ''} {'ok' if condition else 'FAIL'}")
        if not condition:
            self.failures.append(what + (f" ({detail})" if detail else ""))
        return condition

    def finish(self) -> int:
        if self.failures:
            print(f"{self.name}: {len(self.failures)} of {self.count} checks FAILED: {'; '.join(self.failures)}", file=sys.stderr)
            return 1
        print(f"{self.name}: all {self.count} checks passed")
        return 0
