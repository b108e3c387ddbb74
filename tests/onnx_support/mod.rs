//! Shared by the ONNX export tests (`export_onnx.rs`, `export_latent_onnx.rs`): running
//! `instantmimic export --format onnx` and finding the build-step Python that checks the model
//! in onnxruntime.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// `instantmimic ARGS`.
pub fn run(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_instantmimic"))
        .args(args)
        .output()
        .expect("the binary runs")
}

pub fn path_str(path: &Path) -> &str {
    path.to_str().expect("utf-8 path")
}

/// `instantmimic export --checkpoint CHECKPOINT --format onnx --out OUT`.
pub fn export(checkpoint: &Path, out: &Path) -> Output {
    run(&[
        "export",
        "--checkpoint",
        path_str(checkpoint),
        "--format",
        "onnx",
        "--out",
        path_str(out),
    ])
}

/// The build-step Python (`INSTANTMIMIC_BUILD_PYTHON`, with onnxruntime), if set.
pub fn python() -> Option<PathBuf> {
    std::env::var_os("INSTANTMIMIC_BUILD_PYTHON")
        .filter(|p| !p.is_empty())
        .map(PathBuf::from)
}
