//! A whole evaluation episode on clips that do not loop (issue 15's crash: an evaluation reported
//! 63 steps for an episode of 64 marked complete): `reward_termination` with the evaluation's
//! parameters (failures off, `max_episode_steps` = the evaluation's length) and
//! `evaluation_accumulate` with the yardstick, step after step from the clip's start, the
//! physics state copied in at each step's reference time. Every env must complete after exactly
//! `evaluation_steps` steps (`clamped_clip_steps`: where the kernel's own clip-end truncation
//! fires), truncated at that step and not before, and `summarize` must accept the result.

use instantmimic::env::layout::{JointLayout, without_failures};
use instantmimic::kernels::{EVALUATION_ACCUMULATE, REWARD_TERMINATION, TrackingParams};
use instantmimic::motion::{Character, LoopMode, ReferenceTable, SyntheticMotion};
use instantmimic::train::{
    EnvEvaluation, TrainConfig, clamped_clip_steps, evaluation_steps, summarize, yardstick,
};

use super::compare::Report;
use super::physics::{NBODY, NQ, NV, PhysicsBatch};
use super::program::{Arg, Program, Scalar, StructArg};
use super::rng::Sampler;
use super::tracking::default_params;
use super::{Check, Clip, Fixture, POISON_I32};

const COMPLETED: i32 = 1;
/// Envs per case (all start at the clip's beginning, as a clamped clip's evaluation does).
const ENVS: usize = 3;
/// Steps run past the expected end: the episode must not go on.
const EXTRA_STEPS: usize = 3;

/// The physics buffers, one block per step, copied into the kernels' buffers before each step.
const STATE_BUFFERS: [(&str, usize); 5] = [
    ("qpos", NQ),
    ("qvel", NV),
    ("xpos", NBODY * 3),
    ("xquat", NBODY * 4),
    ("subtree_com", NBODY * 3),
];

fn state_block<'a>(physics: &'a PhysicsBatch, name: &str) -> &'a [f32] {
    match name {
        "qpos" => &physics.qpos,
        "qvel" => &physics.qvel,
        "xpos" => &physics.xpos,
        "xquat" => &physics.xquat,
        _ => &physics.subtree_com,
    }
}

/// A case: a synthetic clamped clip of `frames` frames at `fps`, evaluated at control step `dt`.
fn case(character: &Character, layout: &JointLayout, frames: usize, fps: f64, dt: f64) -> Check {
    let motion = SyntheticMotion {
        frames,
        frame_dt: 1.0 / fps,
        loop_mode: LoopMode::Clamp,
        amplitude: 0.6,
        ..SyntheticMotion::default()
    }
    .reference_motion(character)
    .expect("synthetic frames are valid");
    let table = ReferenceTable::build(&motion, dt).expect("the reference table builds");
    let clip = Clip {
        name: format!("clamped synthetic, {frames} frames at {fps} fps"),
        table,
    };
    let duration = clip.table.duration();
    let config = TrainConfig::with_motion("synthetic");
    let steps = evaluation_steps(&config, duration, dt, LoopMode::Clamp) as usize;
    let rows = steps + EXTRA_STEPS;
    let params = TrackingParams {
        dt: dt as f32,
        max_episode_steps: steps as i32,
        ..without_failures(&default_params())
    };

    // Step k compares with the reference at (k + 1) dt (f32 clock, as the kernel's): the state
    // is put there, a little off so that the errors are not zero; past the clip's end it stays
    // at the end.
    let mut rng = Sampler::new(frames as u64 * 1000 + fps as u64);
    let mut states: Vec<PhysicsBatch> = Vec::with_capacity(rows);
    let mut clock = 0.0f32;
    for _ in 0..rows {
        clock += dt as f32;
        let t = f64::from(clock).min(duration);
        let mut physics = PhysicsBatch::new(ENVS);
        for e in 0..ENVS {
            physics.set_near_reference(e, &clip, t, 0.3, &mut rng);
        }
        states.push(physics);
    }

    let mut p = Program::new(format!(
        "an evaluation episode: {}, dt {dt:.6} s, {steps} steps",
        clip.name
    ));
    for (name, width) in STATE_BUFFERS {
        let all: Vec<f32> = states
            .iter()
            .flat_map(|s| state_block(s, name).to_vec())
            .collect();
        p.f32(&format!("{name}_by_step"), &[rows, ENVS * width], all);
    }
    let shape = |width: usize| match width {
        w if w == NQ || w == NV => vec![ENVS, w],
        w => vec![ENVS, NBODY, w / NBODY],
    };
    for (name, width) in STATE_BUFFERS {
        p.f32(name, &shape(width), vec![f32::NAN; ENVS * width]);
    }
    let j = layout.num_joints();
    let ee = layout.end_effectors.clone();
    p.f32("table", &[clip.table.data().len()], clip.data());
    p.i32("joint_kind", &[j], layout.kind.clone());
    p.i32("joint_qpos", &[j], layout.qpos.clone());
    p.i32("end_effectors", &[ee.len()], ee);
    p.f32("ref_time", &[ENVS], vec![0.0; ENVS]);
    p.i32("episode_step", &[ENVS], vec![0; ENVS]);
    p.f32("rewards", &[rows, ENVS], vec![f32::NAN; rows * ENVS]);
    p.i32("terminated", &[rows, ENVS], vec![POISON_I32; rows * ENVS]);
    p.i32("truncated", &[rows, ENVS], vec![POISON_I32; rows * ENVS]);
    p.i32("done", &[ENVS], vec![POISON_I32; ENVS]);
    p.i32("failure", &[ENVS], vec![POISON_I32; ENVS]);
    p.f32("errors", &[ENVS, 5], vec![f32::NAN; ENVS * 5]);
    p.f32("phase_visits", &[4], vec![0.0; 4]);
    p.f32("phase_failures", &[4], vec![0.0; 4]);
    p.i32("status", &[ENVS], vec![0; ENVS]);
    p.i32("steps", &[ENVS], vec![0; ENVS]);
    p.f32("sums", &[ENVS, 5], vec![0.0; ENVS * 5]);
    let buffer = |name: &str| Arg::Buffer(name.to_owned());
    for k in 0..rows {
        for (name, width) in STATE_BUFFERS {
            let count = ENVS * width;
            p.copy(&format!("{name}_by_step"), k * count, name, 0, count);
        }
        let step = Arg::Scalar(Scalar::I32(k as i32));
        let tracking_args = [
            "qpos",
            "qvel",
            "xpos",
            "xquat",
            "subtree_com",
            "table",
            "joint_kind",
            "joint_qpos",
            "end_effectors",
        ]
        .map(buffer)
        .into_iter()
        .chain([Arg::Struct(StructArg::Tracking(params)), step.clone()])
        .chain(
            [
                "ref_time",
                "episode_step",
                "rewards",
                "terminated",
                "truncated",
                "done",
                "failure",
                "errors",
                "phase_visits",
                "phase_failures",
            ]
            .map(buffer),
        )
        .collect();
        p.launch(&REWARD_TERMINATION, ENVS, tracking_args);
        let scoring_args = [
            "qpos",
            "xpos",
            "xquat",
            "table",
            "end_effectors",
            "ref_time",
        ]
        .map(buffer)
        .into_iter()
        .chain([step])
        .chain(["rewards", "terminated", "truncated"].map(buffer))
        .chain([Arg::Struct(StructArg::Yardstick(yardstick()))])
        .chain(["status", "steps", "sums"].map(buffer))
        .collect();
        p.launch(&EVALUATION_ACCUMULATE, ENVS, scoring_args);
    }

    Check::new(p, move |p, out| {
        let mut r = Report::new(&p.name);
        r.check(
            steps as u32 == clamped_clip_steps(duration, dt),
            format!("the evaluation's length {steps} is where the clip ends"),
        );
        r.check(
            steps as f64 * dt <= duration + 1e-5,
            format!("{steps} steps of {dt} s stay within the clip's {duration} s"),
        );
        r.exact("status", out.i32("status"), &[COMPLETED; ENVS]);
        r.exact("scored steps", out.i32("steps"), &[steps as i32; ENVS]);
        // Truncated at the last step and at no step before it; never terminated.
        let truncated = out.i32("truncated");
        let expected: Vec<i32> = (0..steps * ENVS)
            .map(|i| i32::from(i / ENVS + 1 == steps))
            .collect();
        r.exact(
            "truncated, steps 0..end",
            &truncated[..steps * ENVS],
            &expected,
        );
        r.exact(
            "terminated, steps 0..end",
            &out.i32("terminated")[..steps * ENVS],
            &vec![0; steps * ENVS],
        );
        let sums = out.f32("sums");
        let episodes: Vec<EnvEvaluation> = (0..ENVS)
            .map(|e| EnvEvaluation {
                completed: out.i32("status")[e] == COMPLETED,
                steps: out.i32("steps")[e].max(0) as u32,
                pose_error_sum: f64::from(sums[e * 5]),
                global_position_error_sum: f64::from(sums[e * 5 + 1]),
                ee_position_error_sum: f64::from(sums[e * 5 + 2]),
                ee_orientation_error_sum: f64::from(sums[e * 5 + 3]),
            })
            .collect();
        match summarize(&episodes, steps as u32, 0.9) {
            Ok(s) => r.check(
                s.completed == ENVS as u32 && s.success,
                format!(
                    "summarize: {} of {ENVS} complete, success {}",
                    s.completed, s.success
                ),
            ),
            Err(e) => r.check(false, format!("summarize refuses the episode: {e}")),
        }
        r
    })
}

/// Clamped clips at the frame rates DeepMimic's clips use, at 30 and 60 Hz control.
pub fn checks(fx: &Fixture) -> Vec<Check> {
    let mut checks = Vec::new();
    for (frames, fps) in [(17, 16.0), (49, 24.0), (65, 30.0), (61, 60.0), (121, 120.0)] {
        for dt in [1.0 / 30.0, 1.0 / 60.0] {
            checks.push(case(&fx.character, &fx.layout, frames, fps, dt));
        }
    }
    checks
}
