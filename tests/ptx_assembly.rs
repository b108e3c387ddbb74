//! Every shipped PTX file assembles with ptxas for every supported GPU, after the same
//! preparation the runtime applies (trailing NUL stripped, `.version` lowered to what the
//! driver accepts). Runs when `PTXAS` names a ptxas binary (CI installs PyPI's
//! `nvidia-cuda-nvcc`); otherwise it prints that it skipped.
//!
//! Each arch is checked at two PTX ISA versions: the one the oldest driver that can run that
//! arch accepts (the runtime lowers to it there) and 9.0 (driver 580, where we measure).

mod skip_support;

use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::Mutex;

use instantmimic::cuda::{MIN_DRIVER_VERSION, PtxIsa, prepare_ptx};

/// (ptxas -arch, the oldest driver that supports it, as cuDriverGetVersion reports it).
const ARCHS: [(&str, i32); 5] = [
    ("sm_80", MIN_DRIVER_VERSION),
    ("sm_86", MIN_DRIVER_VERSION),
    ("sm_89", MIN_DRIVER_VERSION),
    ("sm_90", MIN_DRIVER_VERSION),
    // Blackwell consumer GPUs (RTX 50xx) need CUDA 12.8 drivers.
    ("sm_120", 12080),
];
/// Driver 580 (CUDA 13.0), the one on our benchmark machine.
const MEASURED_DRIVER: i32 = 13000;

fn ptx_in(dir: &str) -> Vec<PathBuf> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let Ok(entries) = std::fs::read_dir(root.join(dir)) else {
        return Vec::new();
    };
    let mut files: Vec<PathBuf> = entries
        .flatten()
        .map(|e| e.path())
        .filter(|p| p.extension().is_some_and(|e| e == "ptx"))
        .collect();
    files.sort();
    files
}

/// The `mjwarp/` directories of the other characters' plan sets (`ptx/characters/<name>/`).
fn character_mjwarp_dirs() -> Vec<String> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("ptx/characters");
    let mut dirs: Vec<String> = std::fs::read_dir(&root)
        .map(|entries| {
            entries
                .filter_map(Result::ok)
                .map(|e| format!("ptx/characters/{}/mjwarp", e.file_name().to_string_lossy()))
                .collect()
        })
        .unwrap_or_default();
    dirs.sort();
    dirs
}

/// Every PTX file the repository ships, each module once: the deterministic physics variant
/// (ptx/deterministic/mjwarp) and the other characters' plan sets (ptx/characters/*/mjwarp)
/// share many modules with ptx/mjwarp, under the same names (a module's name carries its
/// content hash; `shared_modules_are_identical` checks the bytes).
fn shipped_ptx() -> Vec<PathBuf> {
    let mut files: Vec<PathBuf> = ["ptx/mjwarp", "ptx/env", "src/cuda"]
        .iter()
        .flat_map(|dir| ptx_in(dir))
        .collect();
    let mut names: std::collections::HashSet<_> = files
        .iter()
        .filter_map(|p| p.file_name().map(|n| n.to_owned()))
        .collect();
    let others =
        std::iter::once("ptx/deterministic/mjwarp".to_string()).chain(character_mjwarp_dirs());
    for dir in others {
        for path in ptx_in(&dir) {
            if path.file_name().is_some_and(|n| names.insert(n.to_owned())) {
                files.push(path);
            }
        }
    }
    files.sort();
    files
}

#[test]
fn shared_modules_are_identical() {
    let variants =
        std::iter::once("ptx/deterministic/mjwarp".to_string()).chain(character_mjwarp_dirs());
    for dir in variants {
        let variant = ptx_in(&dir);
        assert!(
            variant.len() > 40,
            "expected {dir} to hold a step's PTX, found {} files",
            variant.len()
        );
        let mut shared = 0;
        for file in variant {
            let default = Path::new(env!("CARGO_MANIFEST_DIR"))
                .join("ptx/mjwarp")
                .join(file.file_name().unwrap());
            if default.is_file() {
                shared += 1;
                assert!(
                    std::fs::read(&default).unwrap() == std::fs::read(&file).unwrap(),
                    "{} and {} have the same module name but differ",
                    file.display(),
                    default.display()
                );
            }
        }
        // Most of a step's modules do not depend on the model: a variant sharing none would
        // mean a different Warp or MuJoCo Warp build.
        assert!(
            shared > 30,
            "expected most modules of {dir} shared with ptx/mjwarp, found {shared}"
        );
    }
}

#[test]
fn every_shipped_ptx_assembles_for_every_supported_arch() {
    let Some(ptxas) = std::env::var_os("PTXAS").map(PathBuf::from) else {
        skip_support::skip("PTXAS is not set (CI sets it to PyPI nvidia-cuda-nvcc's ptxas)");
        return;
    };
    let files = shipped_ptx();
    assert!(
        files.len() > 40,
        "expected the MuJoCo Warp, env and conditional PTX, found {} files",
        files.len()
    );
    let scratch = tempfile::tempdir().unwrap();
    let mut jobs = Vec::new();
    for file in &files {
        for (arch, oldest) in ARCHS {
            let mut isas = vec![
                PtxIsa::for_driver(oldest),
                PtxIsa::for_driver(MEASURED_DRIVER),
            ];
            isas.dedup();
            for isa in isas {
                jobs.push((file.clone(), arch, isa));
            }
        }
    }
    let total = jobs.len();
    let queue = Mutex::new(jobs);
    let failures = Mutex::new(Vec::new());
    let workers = std::thread::available_parallelism().map_or(2, |n| n.get());
    std::thread::scope(|scope| {
        for worker in 0..workers {
            let (queue, failures, ptxas, scratch) = (&queue, &failures, &ptxas, scratch.path());
            scope.spawn(move || {
                let input = scratch.join(format!("in{worker}.ptx"));
                let output = scratch.join(format!("out{worker}.cubin"));
                loop {
                    let Some((file, arch, isa)) = queue.lock().unwrap().pop() else {
                        break;
                    };
                    let text = prepare_ptx(&std::fs::read(&file).unwrap(), isa)
                        .unwrap_or_else(|e| panic!("{}: {e}", file.display()));
                    std::fs::write(&input, text).unwrap();
                    let result = Command::new(ptxas)
                        .arg(format!("-arch={arch}"))
                        .arg(&input)
                        .arg("-o")
                        .arg(&output)
                        .output()
                        .unwrap_or_else(|e| panic!("running {}: {e}", ptxas.display()));
                    if !result.status.success() {
                        failures.lock().unwrap().push(format!(
                            "{} at .version {isa} for {arch}: {}",
                            file.display(),
                            String::from_utf8_lossy(&result.stderr).trim()
                        ));
                    }
                }
            });
        }
    });
    let failures = failures.into_inner().unwrap();
    assert!(
        failures.is_empty(),
        "{} of {total} assemblies failed:\n{}",
        failures.len(),
        failures.join("\n")
    );
    println!(
        "{} PTX files assembled for {} archs ({total} ptxas runs)",
        files.len(),
        ARCHS.len()
    );
}
