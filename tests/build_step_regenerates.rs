//! The generated files under version control regenerate from `kernels_py/` byte for byte: the
//! PTX of MuJoCo Warp's modules and of our own kernels (`compile.py --check`, for the default
//! physics and for the deterministic variant in `ptx/deterministic/`), the character
//! facts (`export_character.py --check`) and the kinematics fixture
//! (`golden_kinematics.py --check`). Runs when `INSTANTMIMIC_BUILD_PYTHON` names a Python with
//! `kernels_py/requirements.txt` installed (tests/run.sh sets one up); otherwise it skips.

mod skip_support;

use std::path::Path;
use std::process::Command;

#[test]
fn generated_files_regenerate_byte_for_byte() {
    let Some(python) = std::env::var_os("INSTANTMIMIC_BUILD_PYTHON") else {
        skip_support::skip("INSTANTMIMIC_BUILD_PYTHON is not set (tests/run.sh sets it)");
        return;
    };
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    // The deterministic physics variant (ptx/deterministic/) has its own plans and PTX.
    let deterministic: &[&str] = &[
        "--only",
        "mjwarp",
        "--manifest",
        "ptx/deterministic/plans/manifest.json",
        "--out",
        "ptx/deterministic",
    ];
    for (script, args) in [
        ("kernels_py/compile.py", &[][..]),
        ("kernels_py/compile.py", deterministic),
        ("kernels_py/export_character.py", &[]),
        ("kernels_py/golden_kinematics.py", &[]),
    ] {
        let out = Command::new(&python)
            .arg(root.join(script))
            .args(args)
            .arg("--check")
            .current_dir(root)
            .output()
            .unwrap_or_else(|e| panic!("running {script}: {e}"));
        let stderr = String::from_utf8_lossy(&out.stderr);
        let problems: Vec<&str> = stderr
            .lines()
            .filter(|l| !l.starts_with("Module ") && !l.contains("CUDA driver"))
            .collect();
        assert!(
            out.status.success(),
            "{script} {args:?} --check failed:\n{}\n{}",
            String::from_utf8_lossy(&out.stdout),
            problems.join("\n")
        );
        println!("{script} {args:?} --check: ok");
    }
}
