//! The deterministic physics variant's kernels (kernels_py/determinism.py and
//! deterministic_solver.py) on Warp's CPU device: the contact sort on shuffled contacts, and a
//! humanoid step with the variant against MuJoCo Warp's own (kernels_py/checks/determinism.py).
//! Its GPU side, bit-for-bit against MuJoCo Warp, is tests/gpu_physics.rs with the variant's
//! reference (tests/device/determinism.sh). Runs when `INSTANTMIMIC_BUILD_PYTHON` is set
//! (tests/run.sh sets it); otherwise it skips.

mod python_checks;
mod skip_support;

#[test]
fn deterministic_physics_kernels_on_warps_cpu_device() {
    let Some(python) = python_checks::build_python() else {
        return;
    };
    match python_checks::run(&python, "kernels_py/checks/determinism.py") {
        Ok(summary) => println!("{summary}"),
        Err(problems) => panic!("{problems}"),
    }
}
