//! The PPO update's kernels on the CPU (no GPU needed).
//!
//! - `kernels_py/checks/ppo_*.py` run every PPO kernel on Warp's CPU device (the same source as
//!   the shipped PTX) against numpy float64 references, the loss gradients also against finite
//!   differences, and exit non-zero on a failure. Runs when `INSTANTMIMIC_BUILD_PYTHON` names a
//!   Python with `kernels_py/requirements.txt` installed (tests/run.sh sets one up); otherwise it
//!   skips with a note.
//! - The constants the Rust side shares with the kernels (tile sizes, the loss-term and
//!   statistics layouts) are read from the Python sources and compared (always runs).

mod python_checks;
mod skip_support;

use std::path::Path;

use instantmimic::env::layout;
use instantmimic::nn::{linear_backward, reduce};
use instantmimic::ppo::PpoStatistics;
use instantmimic::ppo::{batch, loss};

const CHECKS: [&str; 6] = [
    "kernels_py/checks/ppo_gae.py",
    "kernels_py/checks/ppo_minibatch.py",
    "kernels_py/checks/ppo_mirror.py",
    "kernels_py/checks/ppo_loss.py",
    "kernels_py/checks/ppo_backward.py",
    "kernels_py/checks/ppo_optimizer.py",
];

#[test]
fn ppo_kernels_match_float64_references_on_warps_cpu_device() {
    let Some(python) = python_checks::build_python() else {
        return;
    };
    let mut failed = Vec::new();
    for script in CHECKS {
        match python_checks::run(&python, script) {
            Ok(summary) => println!("{script}: {summary}"),
            Err(problems) => failed.push(problems),
        }
    }
    assert!(failed.is_empty(), "{}", failed.join("\n\n"));
}

/// The value of `NAME = wp.constant(<int>)` in a kernel source.
fn python_constant(source: &str, file: &str, name: &str) -> usize {
    let prefix = format!("{name} = wp.constant(");
    let line = source
        .lines()
        .find(|l| l.starts_with(&prefix))
        .unwrap_or_else(|| panic!("{file} defines no {name}"));
    line[prefix.len()..]
        .trim_end_matches(')')
        .parse()
        .unwrap_or_else(|e| panic!("{file}: {line}: {e}"))
}

fn kernel_source(file: &str) -> String {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("kernels_py/env")
        .join(file);
    std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

#[test]
fn rust_and_kernels_agree_on_shared_constants() {
    let reduce_py = kernel_source("reduce.py");
    for (name, rust) in [
        ("TILE_THREADS", reduce::TILE_THREADS),
        ("SUM_CHUNK", reduce::SUM_CHUNK),
    ] {
        assert_eq!(
            python_constant(&reduce_py, "reduce.py", name),
            rust,
            "{name}"
        );
    }
    let backward_py = kernel_source("mlp_backward.py");
    for (name, rust) in [
        ("TILE_M", linear_backward::TILE),
        ("TILE_N", linear_backward::TILE),
        ("TILE_K", linear_backward::TILE_K),
        ("TILE_THREADS", reduce::TILE_THREADS),
    ] {
        assert_eq!(
            python_constant(&backward_py, "mlp_backward.py", name),
            rust,
            "{name}"
        );
    }
    let loss_py = kernel_source("ppo_loss.py");
    for (name, rust) in [
        ("LOSS_TERMS", loss::LOSS_TERMS),
        ("TERM_SURROGATE", loss::TERM_SURROGATE),
        ("TERM_VALUE", loss::TERM_VALUE),
        ("TERM_ENTROPY", loss::TERM_ENTROPY),
        ("TERM_KL", loss::TERM_KL),
        ("TERM_CLIP_FRACTION", loss::TERM_CLIP_FRACTION),
    ] {
        assert_eq!(
            python_constant(&loss_py, "ppo_loss.py", name),
            rust,
            "{name}"
        );
    }
    // PpoStatistics::from_values reads the fields in this order (its unit test checks it).
    let stats_py = kernel_source("ppo_statistics.py");
    let order = [
        "STAT_SURROGATE",
        "STAT_VALUE",
        "STAT_ENTROPY",
        "STAT_KL",
        "STAT_CLIP_FRACTION",
        "STAT_LEARNING_RATE",
        "STAT_GRAD_NORM",
        "STAT_ADVANTAGE_MEAN",
        "STAT_ADVANTAGE_STD",
        "STAT_UPDATES",
    ];
    for (i, name) in order.iter().enumerate() {
        assert_eq!(
            python_constant(&stats_py, "ppo_statistics.py", name),
            i,
            "{name}"
        );
    }
    assert_eq!(
        python_constant(&stats_py, "ppo_statistics.py", "NUM_STATS"),
        PpoStatistics::LEN
    );
    assert_eq!(
        python_constant(
            &kernel_source("gemm_epilogue.py"),
            "gemm_epilogue.py",
            "GRADIENT_ROWS"
        ),
        reduce::GRADIENT_ROWS
    );
    let minibatch_py = kernel_source("minibatch.py");
    assert_eq!(
        python_constant(&minibatch_py, "minibatch.py", "GATHER_COLUMNS"),
        batch::GATHER_COLUMNS
    );
    // Not PPO kernels, but the same kind of shared constant: the fused kinematics' longest
    // chain, and the lanes of `tracking_error_sums`. (`observe`'s threads per env follow the
    // tracked bodies, a run-time count: no constant to compare.)
    assert_eq!(
        python_constant(
            &kernel_source("kinematics.py"),
            "kinematics.py",
            "MAX_DEPTH"
        ),
        instantmimic::env::body_model::MAX_CHAIN_DEPTH
    );
    let tracking_py = kernel_source("tracking.py");
    assert_eq!(
        python_constant(&tracking_py, "tracking.py", "TRACKING_LANES"),
        layout::TRACKING_LANES
    );
    assert_eq!(
        python_constant(&tracking_py, "tracking.py", "ERROR_DISTANCES") + 1,
        layout::ERROR_SUMS,
        "the last slot of a lane's error sums"
    );
}
