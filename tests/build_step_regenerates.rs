//! The generated files under version control regenerate from `kernels_py/` byte for byte: the
//! PTX of MuJoCo Warp's modules and of our own kernels (`compile.py --check`, for the default
//! physics, for the deterministic variant in `ptx/deterministic/` and for the G1's plans in
//! `ptx/characters/g1/`), the character
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
    // The deterministic physics variant (ptx/deterministic/) and each other character's plan
    // set (ptx/characters/<name>/) have their own plans and PTX.
    let mut plan_sets = vec!["ptx/deterministic".to_string()];
    if let Ok(entries) = std::fs::read_dir(root.join("ptx/characters")) {
        let mut characters: Vec<String> = entries
            .filter_map(Result::ok)
            .map(|e| format!("ptx/characters/{}", e.file_name().to_string_lossy()))
            .collect();
        characters.sort();
        plan_sets.extend(characters);
    }
    let mut runs: Vec<(&str, Vec<String>)> = vec![("kernels_py/compile.py", Vec::new())];
    for dir in &plan_sets {
        let mut args: Vec<String> = ["--only", "mjwarp", "--manifest"]
            .map(String::from)
            .to_vec();
        args.extend([
            format!("{dir}/plans/manifest.json"),
            "--out".into(),
            dir.clone(),
        ]);
        runs.push(("kernels_py/compile.py", args));
    }
    runs.push(("kernels_py/export_character.py", Vec::new()));
    runs.push(("kernels_py/golden_kinematics.py", Vec::new()));
    for (script, args) in runs {
        let out = Command::new(&python)
            .arg(root.join(script))
            .args(&args)
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
