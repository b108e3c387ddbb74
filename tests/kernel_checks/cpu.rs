//! Execution A: programs run by Warp on the CPU, through `kernels_py/checks/run_kernel.py`
//! (the kernel source as it is, compiled by Warp's LLVM backend instead of NVRTC).
//!
//! All programs of one check go to one Python process (Warp starts in ~0.3 s; compiled CPU
//! modules are cached under the cargo target directory, so later runs skip the compile).

use std::path::{Path, PathBuf};
use std::process::Command;

use serde_json::{Value, json};

use super::program::{Arg, HostData, Outputs, Program, Step};

/// The build-step Python (tests/run.sh sets it), or `None` with a printed note: the CPU checks
/// then skip, like tests/build_step_regenerates.rs.
pub fn build_python() -> Option<PathBuf> {
    match std::env::var_os("INSTANTMIMIC_BUILD_PYTHON") {
        Some(p) => Some(PathBuf::from(p)),
        None => {
            crate::skip_support::skip(
                "INSTANTMIMIC_BUILD_PYTHON is not set: no Warp CPU run (tests/run.sh sets it)",
            );
            None
        }
    }
}

fn step_json(step: &Step) -> Value {
    match step {
        Step::Launch { abi, dim, args } => {
            let args: Vec<Value> = abi
                .params
                .iter()
                .zip(args)
                .map(|(param, arg)| match arg {
                    Arg::Buffer(name) => json!({"name": param.name, "buffer": name}),
                    Arg::Scalar(s) => json!({
                        "name": param.name,
                        "scalar": {"dtype": s.dtype_name(), "value": s.json_value()},
                    }),
                    Arg::Struct(s) => {
                        let fields: serde_json::Map<String, Value> = s
                            .fields()
                            .into_iter()
                            .map(|(name, v)| {
                                (
                                    name.to_owned(),
                                    json!({"dtype": v.dtype_name(), "value": v.json_value()}),
                                )
                            })
                            .collect();
                        json!({"name": param.name, "struct": fields})
                    }
                })
                .collect();
            json!({"launch": {
                "module": abi.module,
                "kernel": abi.name,
                "dim": dim,
                "block_dim": abi.block_dim,
                "args": args,
            }})
        }
        Step::Copy {
            src,
            src_offset,
            dst,
            dst_offset,
            count,
        } => json!({"copy": {
            "src": src, "src_offset": src_offset, "dst": dst, "dst_offset": dst_offset, "count": count,
        }}),
    }
}

/// Writes `programs` under `dir` (emptied first): `spec.json` and one directory per program.
fn write_spec(dir: &Path, programs: &[Program]) {
    if dir.exists() {
        std::fs::remove_dir_all(dir).unwrap_or_else(|e| panic!("clearing {}: {e}", dir.display()));
    }
    let mut entries = Vec::new();
    for (i, program) in programs.iter().enumerate() {
        let sub = format!("p{i:03}");
        let pdir = dir.join(&sub);
        std::fs::create_dir_all(&pdir)
            .unwrap_or_else(|e| panic!("creating {}: {e}", pdir.display()));
        let mut buffers = Vec::new();
        for b in &program.buffers {
            let path = pdir.join(format!("{}.bin", b.name));
            std::fs::write(&path, b.data.to_le_bytes())
                .unwrap_or_else(|e| panic!("writing {}: {e}", path.display()));
            buffers.push(json!({"name": b.name, "dtype": b.data.dtype_name(), "shape": b.shape}));
        }
        let steps: Vec<Value> = program.steps.iter().map(step_json).collect();
        entries.push(json!({"name": program.name, "dir": sub, "buffers": buffers, "steps": steps}));
    }
    let spec = json!({"format": 1, "programs": entries});
    let text = serde_json::to_string_pretty(&spec).expect("the spec serializes");
    std::fs::write(dir.join("spec.json"), text).expect("writing spec.json");
}

/// Runs `programs` on Warp's CPU device with `python`; `name` names the scratch directory under
/// the cargo target directory. Panics with the runner's message if it fails.
pub fn run(python: &Path, name: &str, programs: &[Program]) -> Vec<Outputs> {
    for p in programs {
        p.validate().unwrap_or_else(|e| panic!("invalid case: {e}"));
    }
    let scratch = Path::new(env!("CARGO_TARGET_TMPDIR")).join("env_kernels_cpu");
    let safe: String = name
        .chars()
        .map(|c| if c.is_ascii_alphanumeric() { c } else { '_' })
        .collect();
    let dir = scratch.join(safe);
    write_spec(&dir, programs);
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let out = Command::new(python)
        .arg(root.join("kernels_py/checks/run_kernel.py"))
        .arg(&dir)
        .arg("--cache")
        .arg(scratch.join("warp-kernel-cache"))
        .current_dir(root)
        .output()
        .unwrap_or_else(|e| panic!("running {}: {e}", python.display()));
    assert!(
        out.status.success(),
        "run_kernel.py failed ({}):\n{}\n{}",
        out.status,
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    programs
        .iter()
        .enumerate()
        .map(|(i, program)| {
            let pdir = dir.join(format!("p{i:03}"));
            let mut outputs = Outputs::default();
            for b in &program.buffers {
                let path = pdir.join(format!("{}.out.bin", b.name));
                let bytes = std::fs::read(&path)
                    .unwrap_or_else(|e| panic!("reading {}: {e}", path.display()));
                let data = HostData::from_le_bytes(&b.data, &bytes).unwrap_or_else(|| {
                    panic!(
                        "{}: {} bytes for {} values",
                        path.display(),
                        bytes.len(),
                        b.data.len()
                    )
                });
                outputs.buffers.insert(b.name.clone(), data);
            }
            outputs
        })
        .collect()
}
