"""Env kernels of the training loop, one file per concept (like MuJoCo Warp's `_src/`).

Each module here that defines `@wp.kernel`s is compiled ahead of time to `ptx/env/<module>.ptx` by
`kernels_py/env_build.py`, which also describes every kernel's ABI in `ptx/env/manifest.json`;
`build.rs` turns that manifest into typed Rust launchers (`src/kernels/launchers.rs`). Modules with only
`@wp.func`s (shared device functions) produce no PTX: the kernels that call them carry their code.
See `docs/kernels.md`.
"""
