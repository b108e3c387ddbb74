//! The deterministic physics variant's kernels (kernels_py/determinism.py and
//! deterministic_solver.py) on Warp's CPU device: the contact sort on shuffled contacts, and a
//! humanoid step with the variant against MuJoCo Warp's own (kernels_py/checks/determinism.py).
//! Its GPU side, bit-for-bit against MuJoCo Warp, is tests/gpu_physics.rs with the variant's
//! reference (tests/device/determinism.sh). Runs when `INSTANTMIMIC_BUILD_PYTHON` is set
//! (tests/run.sh sets it); otherwise it skips.

use std::path::Path;
use std::process::Command;

#[test]
fn deterministic_physics_kernels_on_warps_cpu_device() {
    let Some(python) = std::env::var_os("INSTANTMIMIC_BUILD_PYTHON") else {
        println!("INSTANTMIMIC_BUILD_PYTHON is not set: skipping (tests/run.sh sets it)");
        return;
    };
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let script = "kernels_py/checks/determinism.py";
    let out = Command::new(&python)
        .arg(root.join(script))
        .current_dir(root)
        .output()
        .unwrap_or_else(|e| panic!("running {script}: {e}"));
    let stdout = String::from_utf8_lossy(&out.stdout);
    println!("{stdout}");
    let stderr = String::from_utf8_lossy(&out.stderr);
    let errors: Vec<&str> = stderr
        .lines()
        .filter(|l| !l.starts_with("Module ") && !l.contains("CUDA driver"))
        .collect();
    assert!(
        out.status.success(),
        "{script} failed:\n{}\n{}",
        stdout
            .lines()
            .filter(|l| l.ends_with("FAIL"))
            .collect::<Vec<_>>()
            .join("\n"),
        errors.join("\n")
    );
}
