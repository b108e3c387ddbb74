//! Every env kernel on Warp's CPU device against its f64 reference (tests/kernel_checks/; the
//! same cases run on a GPU in tests/gpu_env_kernels.rs). Runs when `INSTANTMIMIC_BUILD_PYTHON`
//! names the build-step Python (tests/run.sh sets it); otherwise the kernel tests skip with a
//! note. `-- --nocapture` prints the error of every case and the largest per output.

mod kernel_checks;
mod skip_support;

use std::collections::BTreeSet;

use instantmimic::kernels::KERNELS;
use kernel_checks::program::Step;
use kernel_checks::{Check, Fixture, cpu, run_checks};

fn run_on_cpu(kernel: &str, checks: impl FnOnce(&Fixture) -> Vec<Check>) {
    run_on_cpu_with(Fixture::load, kernel, checks);
}

/// The checks of `checks` on the fixture `fixture` makes (the humanoid's, or another
/// character's).
fn run_on_cpu_with(
    fixture: impl FnOnce() -> Fixture,
    kernel: &str,
    checks: impl FnOnce(&Fixture) -> Vec<Check>,
) {
    let Some(python) = cpu::build_python() else {
        return;
    };
    let fixture = fixture();
    run_checks(kernel, checks(&fixture), |programs| {
        cpu::run(&python, kernel, programs)
    });
}

/// All check families, as the two executions run them.
fn all_checks(fixture: &Fixture) -> Vec<Check> {
    use kernel_checks::{
        control, episode, evaluate, gemm_epilogue, goal, kinematics, normalize, observe, policy,
        reset, statistics, tracking,
    };
    [
        control::checks(fixture),
        tracking::checks(fixture),
        reset::reset_checks(fixture),
        reset::statistics_checks(fixture),
        observe::checks(fixture),
        normalize::moments_checks(fixture),
        normalize::normalize_checks(fixture),
        policy::linear_checks(fixture),
        policy::sample_checks(fixture),
        gemm_epilogue::checks(fixture),
        evaluate::checks(fixture),
        episode::checks(fixture),
        statistics::checks(fixture),
        goal::checks(fixture),
        kinematics::checks(fixture),
    ]
    .into_iter()
    .flatten()
    .collect()
}

/// The PPO update's modules: their kernels are checked against float64 numpy on Warp's CPU
/// device by tests/ppo_kernels_cpu.rs (kernels_py/checks/ppo_*.py) and on the GPU by
/// tests/gpu_ppo.rs; the latent controller's likewise by tests/latent_kernels_cpu.rs
/// (kernels_py/checks/latent.py) and tests/gpu_latent.rs.
const PPO_MODULES: [&str; 9] = [
    "gae",
    "latent",
    "minibatch",
    "mirror",
    "mlp_backward",
    "optimizer",
    "ppo_loss",
    "ppo_statistics",
    "reduce",
];

/// Runs without Python: every case fits its kernel's generated ABI (the second character's
/// too), and every env kernel but the reference lookup (checked against
/// `ReferenceTable::lookup` by gpu_reference_table.rs) has a check.
#[test]
fn every_case_fits_its_kernel_and_every_kernel_is_checked() {
    let fixture = Fixture::load();
    let mut launched = BTreeSet::new();
    let second = kernel_checks::character_checks(&Fixture::g1());
    for check in all_checks(&fixture).into_iter().chain(second) {
        let p = &check.program;
        p.validate().unwrap_or_else(|e| panic!("{e}"));
        for step in &p.steps {
            if let Step::Launch { abi, .. } = step {
                launched.insert(abi.name);
            }
        }
    }
    let expected: BTreeSet<&str> = KERNELS
        .iter()
        .filter(|k| k.name != "lookup_reference" && !PPO_MODULES.contains(&k.module))
        .map(|k| k.name)
        .collect();
    assert_eq!(
        launched, expected,
        "kernels with a check vs kernels in the manifest"
    );
}

#[test]
fn pd_control_matches_the_f64_reference() {
    run_on_cpu("pd_control", kernel_checks::control::checks);
}

#[test]
fn reward_termination_matches_the_f64_reference() {
    run_on_cpu("reward_termination", kernel_checks::tracking::checks);
}

#[test]
fn an_evaluation_episode_on_a_clamped_clip_ends_where_the_evaluation_expects() {
    run_on_cpu(
        "reward_termination + evaluation_accumulate",
        kernel_checks::episode::checks,
    );
}

#[test]
fn reset_masked_matches_the_f64_reference() {
    run_on_cpu("reset_masked", kernel_checks::reset::reset_checks);
}

#[test]
fn phase_statistics_update_matches_the_f64_reference() {
    run_on_cpu(
        "phase_statistics_update",
        kernel_checks::reset::statistics_checks,
    );
}

#[test]
fn observe_matches_the_f64_reference_block_by_block() {
    run_on_cpu("observe", kernel_checks::observe::checks);
}

#[test]
fn observation_moments_and_merge_match_two_pass_f64_statistics() {
    run_on_cpu(
        "observation_moments",
        kernel_checks::normalize::moments_checks,
    );
}

#[test]
fn observation_normalize_matches_the_f64_reference() {
    run_on_cpu(
        "observation_normalize",
        kernel_checks::normalize::normalize_checks,
    );
}

#[test]
fn linear_layers_match_the_f64_reference() {
    run_on_cpu("linear_elu / linear", kernel_checks::policy::linear_checks);
}

#[test]
fn gaussian_sample_matches_the_f64_reference() {
    run_on_cpu("gaussian_sample", kernel_checks::policy::sample_checks);
}

#[test]
fn gemm_epilogues_match_the_f64_reference() {
    run_on_cpu(
        "bias_elu / bias_add / elu_input_gradient",
        kernel_checks::gemm_epilogue::checks,
    );
}

#[test]
fn evaluation_accumulate_matches_the_f64_reference() {
    run_on_cpu("evaluation_accumulate", kernel_checks::evaluate::checks);
}

#[test]
fn rollout_statistics_match_the_f64_reference() {
    run_on_cpu("episode_statistics", kernel_checks::statistics::checks);
}

#[test]
fn goal_reward_termination_matches_the_f64_reference() {
    run_on_cpu(
        "goal_reward_termination",
        kernel_checks::goal::reward_checks,
    );
}

#[test]
fn goal_reset_matches_the_f64_reference() {
    run_on_cpu("goal_reset", kernel_checks::goal::reset_checks);
}

#[test]
fn goal_observe_matches_the_f64_reference() {
    run_on_cpu("goal_observe", kernel_checks::goal::observe_checks);
}

#[test]
fn body_kinematics_matches_the_f64_reference() {
    run_on_cpu("body_kinematics", kernel_checks::kinematics::checks);
}

/// The G1: 29 hinges, no ball joint, 30 bodies of which 14 tracked, another row layout and PD
/// table; the same PTX as the humanoid's.
#[test]
fn every_character_kernel_matches_the_f64_reference_on_the_g1() {
    run_on_cpu_with(
        Fixture::g1,
        "the G1: pd_targets, pd_control, body_kinematics, reward_termination, observe, evaluation_accumulate, reset_masked",
        kernel_checks::character_checks,
    );
}

/// The G1 with its tracked bodies in another order (the root still first): the kernels follow
/// the array, not body ids.
#[test]
fn the_reward_observation_and_evaluation_follow_the_tracked_bodies_order() {
    let reordered = || {
        let mut fixture = Fixture::g1();
        fixture.layout.tracked_bodies[1..].reverse();
        fixture
    };
    run_on_cpu_with(
        reordered,
        "the G1, tracked bodies reordered: reward_termination, observe, evaluation_accumulate",
        |fx| {
            use kernel_checks::{evaluate, observe, tracking};
            [
                tracking::checks(fx),
                observe::checks(fx),
                evaluate::checks(fx),
            ]
            .into_iter()
            .flatten()
            .collect()
        },
    );
}
