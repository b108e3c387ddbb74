//! The latent controller's kernels on the CPU (no GPU needed): `kernels_py/checks/latent.py`
//! runs every kernel of `kernels_py/env/latent.py` on Warp's CPU device against float64
//! references (the loss gradients also against finite differences, and one whole minibatch
//! step of the update composed as `src/latent/distill.rs` records it). Runs when
//! `INSTANTMIMIC_BUILD_PYTHON` names a Python with `kernels_py/requirements.txt` installed;
//! otherwise it skips with a note.

mod python_checks;
mod skip_support;

#[test]
fn latent_kernels_match_float64_references_on_warps_cpu_device() {
    let Some(python) = python_checks::build_python() else {
        return;
    };
    match python_checks::run(&python, "kernels_py/checks/latent.py") {
        Ok(summary) => println!("kernels_py/checks/latent.py: {summary}"),
        Err(problems) => panic!("{problems}"),
    }
}
