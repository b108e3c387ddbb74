//! Build steps:
//! - embeds every file under `ptx/` (module PTX, plans, manifests) into the binary, except the
//!   deterministic physics variant in `ptx/deterministic/` (read from its directory)
//!   (`src/assets.rs`);
//! - generates the typed launchers of our own env kernels from `ptx/env/manifest.json`
//!   (`$OUT_DIR/env_kernels.rs`, included by `src/kernels/launchers.rs`), after checking the manifest
//!   against the `.param` declarations of the PTX it describes. See `docs/kernels.md`.

#[allow(dead_code)] // the library uses more of the manifest module than the build does
#[path = "src/kernels/manifest.rs"]
mod manifest;

#[allow(dead_code)] // the launchers evaluate contracts; the build only parses them
#[path = "src/kernels/contract.rs"]
mod contract;

#[path = "src/kernels/ptx_params.rs"]
mod ptx_params;

#[path = "build/env_codegen.rs"]
mod env_codegen;

use std::env;
use std::fmt::Write as _;
use std::fs;
use std::path::{Path, PathBuf};

use manifest::EnvManifest;

/// The env manifest, relative to `ptx/`.
const ENV_MANIFEST: &str = "env/manifest.json";

fn collect(dir: &Path, root: &Path, out: &mut Vec<(String, PathBuf)>) {
    let Ok(entries) = fs::read_dir(dir) else {
        return;
    };
    let mut entries: Vec<_> = entries.filter_map(Result::ok).collect();
    entries.sort_by_key(|e| e.file_name());
    for entry in entries {
        let path = entry.path();
        if path.is_dir() {
            // The deterministic physics variant is read from its directory (`--assets
            // ptx/deterministic`), not embedded: most of its PTX duplicates ptx/mjwarp.
            if dir == root && entry.file_name() == "deterministic" {
                continue;
            }
            collect(&path, root, out);
        } else if let Ok(rel) = path.strip_prefix(root) {
            let rel = rel.to_string_lossy().replace('\\', "/");
            if rel.ends_with(".ptx") || rel.ends_with(".json") || rel.ends_with(".wrp.zst") {
                out.push((rel, path));
            }
        }
    }
}

/// `$OUT_DIR/embedded_assets.rs`: every file under `ptx/`, by path relative to it.
fn embed_assets(root: &Path, out_dir: &Path) -> Result<(), String> {
    let mut files = Vec::new();
    collect(root, root, &mut files);
    let mut src = String::from(
        "/// Files under `ptx/`, by path relative to it.\npub static ASSETS: &[(&str, &[u8])] = &[\n",
    );
    for (rel, path) in &files {
        println!("cargo:rerun-if-changed={}", path.display());
        let _ = writeln!(
            src,
            "    ({rel:?}, include_bytes!({:?})),",
            path.display().to_string()
        );
    }
    src.push_str("];\n");
    let out = out_dir.join("embedded_assets.rs");
    fs::write(&out, src).map_err(|e| format!("writing {}: {e}", out.display()))
}

/// `$OUT_DIR/env_kernels.rs`: the env kernel launchers.
fn generate_env_kernels(root: &Path, out_dir: &Path) -> Result<(), String> {
    let path = root.join(ENV_MANIFEST);
    let text = fs::read_to_string(&path).map_err(|e| {
        format!(
            "reading {}: {e} (generate it with `python kernels_py/compile.py --only env`)",
            path.display()
        )
    })?;
    let manifest = EnvManifest::parse(&text).map_err(|e| e.to_string())?;
    for module in &manifest.modules {
        let ptx_path = root.join(&module.ptx);
        let ptx = fs::read(&ptx_path).map_err(|e| {
            format!(
                "reading {} (named by {ENV_MANIFEST}): {e}",
                ptx_path.display()
            )
        })?;
        let ptx = String::from_utf8_lossy(&ptx);
        for kernel in &module.kernels {
            kernel.check_ptx(&ptx).map_err(|e| e.to_string())?;
        }
    }
    let src = env_codegen::generate(&manifest).map_err(|e| e.to_string())?;
    let out = out_dir.join("env_kernels.rs");
    fs::write(&out, src).map_err(|e| format!("writing {}: {e}", out.display()))
}

fn run() -> Result<(), String> {
    let manifest_dir = env::var_os("CARGO_MANIFEST_DIR").ok_or("cargo sets CARGO_MANIFEST_DIR")?;
    let out_dir = PathBuf::from(env::var_os("OUT_DIR").ok_or("cargo sets OUT_DIR")?);
    let root = PathBuf::from(manifest_dir).join("ptx");
    println!("cargo:rerun-if-changed=ptx");
    println!("cargo:rerun-if-changed=build");
    println!("cargo:rerun-if-changed=src/kernels/manifest.rs");
    println!("cargo:rerun-if-changed=src/kernels/contract.rs");
    println!("cargo:rerun-if-changed=src/kernels/ptx_params.rs");
    embed_assets(&root, &out_dir)?;
    generate_env_kernels(&root, &out_dir)
}

fn main() {
    if let Err(e) = run() {
        eprintln!("error: {e}");
        std::process::exit(1);
    }
}
