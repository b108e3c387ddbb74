//! A test that needs an outside tool (the build-step Python, ptxas, Chromium, node's glTF
//! validator, a GPU-side reference) and does not find it says so and passes, since it cannot
//! check anything; with `INSTANTMIMIC_NO_SKIP=1` it fails instead. `tests/run.sh` (what CI
//! runs) sets it after installing every tool, so a check that silently stopped running fails CI.

#![allow(dead_code)] // each test binary uses a subset

/// Whether skipping is forbidden (`INSTANTMIMIC_NO_SKIP=1`).
pub fn skipping_forbidden() -> bool {
    std::env::var_os("INSTANTMIMIC_NO_SKIP").is_some_and(|v| v == "1")
}

/// Reports a skipped check, or fails the test when skipping is forbidden.
pub fn skip(reason: &str) {
    assert!(
        !skipping_forbidden(),
        "{reason}; INSTANTMIMIC_NO_SKIP=1 forbids skipping: provide it (tests/run.sh installs every tool) or unset INSTANTMIMIC_NO_SKIP"
    );
    println!("skipped: {reason}");
}
