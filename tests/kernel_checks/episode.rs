//! A whole evaluation episode on clips that do not loop (issue 15's crash: an evaluation reported
//! 63 steps for an episode of 64 marked complete): `reward_termination` with the evaluation's
//! parameters (failures off, `max_episode_steps` = the evaluation's length) and
//! `evaluation_accumulate` with the yardstick, step after step from the clip's start, the
//! physics state copied in at each step's reference time. Every env must complete after exactly
//! `evaluation_steps` steps (`clamped_clip_steps`: where the kernel's own clip-end truncation
//! fires), truncated at that step and not before, and `summarize` must accept the result.
//!
//! And a motion library's evaluation in one rollout: clips of different lengths (clamped ones
//! ending themselves, a looping one ending when it has scored its pass), env e playing clip
//! e mod C, the horizon the longest clip's; every env must complete after exactly its own
//! clip's steps (`clip_evaluation`, as the rollout plans them).

use instantmimic::env::layout::{JointLayout, without_failures};
use instantmimic::env::{EvalStart, EvaluationProtocol, clip_evaluation};
use instantmimic::kernels::{EVALUATION_ACCUMULATE, TrackingParams};
use instantmimic::motion::{Character, LoopMode, MotionLibraryBuilder, SyntheticMotion};
use instantmimic::run::{
    EnvEvaluation, clamped_clip_steps, evaluation_steps, summarize, yardstick,
};
use instantmimic::train::TrainConfig;

use super::compare::Report;
use super::physics::{PhysicsBatch, Shape};
use super::program::{Arg, Program, Scalar, StructArg};
use super::rng::Sampler;
use super::tracking::default_params;
use super::{Check, Clip, Fixture, POISON_I32};

const COMPLETED: i32 = 1;
/// Envs per single-clip case (all start at the clip's beginning, as a clamped clip's
/// evaluation does).
const ENVS: usize = 3;
/// Steps run past the expected end: the episode must not go on.
const EXTRA_STEPS: usize = 3;

/// The physics buffers, one block per step, copied into the kernels' buffers before each step:
/// name, shape of one env's block.
fn state_buffers(shape: &Shape) -> [(&'static str, Vec<usize>); 5] {
    let nbody = shape.nbody();
    [
        ("qpos", vec![shape.nq()]),
        ("qvel", vec![shape.nv()]),
        ("xpos", vec![nbody, 3]),
        ("xquat", vec![nbody, 4]),
        ("subtree_com", vec![nbody, 3]),
    ]
}

fn state_block<'a>(physics: &'a PhysicsBatch, name: &str) -> &'a [f32] {
    match name {
        "qpos" => &physics.qpos,
        "qvel" => &physics.qvel,
        "xpos" => &physics.xpos,
        "xquat" => &physics.xquat,
        _ => &physics.subtree_com,
    }
}

fn synthetic(
    character: &Character,
    frames: usize,
    fps: f64,
    loop_mode: LoopMode,
) -> instantmimic::motion::ReferenceMotion {
    SyntheticMotion {
        frames,
        frame_dt: 1.0 / fps,
        loop_mode,
        amplitude: 0.6,
        ..SyntheticMotion::default()
    }
    .reference_motion(character)
    .expect("synthetic frames are valid")
}

/// The episode program: `envs` envs of a character of `shape` from t = 0, env e on clip
/// `clip_id[e]`, for `rows` steps of `dt` with `max_steps` the episode limit and `clip_steps`
/// each clip's episode length.
#[allow(clippy::too_many_arguments)]
fn program(
    name: String,
    clip: &Clip,
    clip_id: &[i32],
    layout: &JointLayout,
    shape: &Shape,
    dt: f64,
    max_steps: usize,
    clip_steps: &[i32],
    rows: usize,
    seed: u64,
) -> Program {
    let envs = clip_id.len();
    let params = TrackingParams {
        dt: dt as f32,
        max_episode_steps: max_steps as i32,
        ..without_failures(&default_params())
    };
    // Step k compares with the reference at (k + 1) dt (f32 clock, as the kernel's): the state
    // is put there, a little off so that the errors are not zero; past a clamped clip's end it
    // stays at the end.
    let mut rng = Sampler::new(seed);
    let mut states: Vec<PhysicsBatch> = Vec::with_capacity(rows);
    let mut clock = 0.0f32;
    for _ in 0..rows {
        clock += dt as f32;
        let mut physics = PhysicsBatch::new(shape, envs);
        for (e, &c) in clip_id.iter().enumerate() {
            let c = c as usize;
            let t = if clip.wraps(c) {
                f64::from(clock)
            } else {
                f64::from(clock).min(clip.duration(c))
            };
            physics.set_near_reference(e, (clip, c), t, 0.3, &mut rng);
        }
        states.push(physics);
    }

    let mut p = Program::new(name);
    let buffers = state_buffers(shape);
    for (name, block) in &buffers {
        let width: usize = block.iter().product();
        let all: Vec<f32> = states
            .iter()
            .flat_map(|s| state_block(s, name).to_vec())
            .collect();
        p.f32(&format!("{name}_by_step"), &[rows, envs * width], all);
        let dims: Vec<usize> = std::iter::once(envs).chain(block.iter().copied()).collect();
        p.f32(name, &dims, vec![f32::NAN; envs * width]);
    }
    let j = layout.num_joints();
    let ee = layout.end_effectors.clone();
    let tracked = layout.tracked_bodies.clone();
    p.f32("table", &[clip.data().len()], clip.data());
    p.i32("clip_offsets", &[clip.clips()], clip.offsets());
    p.i32("joint_kind", &[j], layout.kind.clone());
    p.i32("joint_qpos", &[j], layout.qpos.clone());
    p.i32("end_effectors", &[ee.len()], ee);
    p.i32("tracked_bodies", &[tracked.len()], tracked);
    p.i32("clip_id", &[envs], clip_id.to_vec());
    p.f32("ref_time", &[envs], vec![0.0; envs]);
    p.i32("episode_step", &[envs], vec![0; envs]);
    p.f32("rewards", &[rows, envs], vec![f32::NAN; rows * envs]);
    p.i32("terminated", &[rows, envs], vec![POISON_I32; rows * envs]);
    p.i32("truncated", &[rows, envs], vec![POISON_I32; rows * envs]);
    p.i32("done", &[envs], vec![POISON_I32; envs]);
    p.i32("failure", &[envs], vec![POISON_I32; envs]);
    p.f32("errors", &[envs, 5], vec![f32::NAN; envs * 5]);
    super::tracking::add_error_sums(&mut p, envs);
    p.f32(
        "phase_visits",
        &[clip.clips(), 4],
        vec![0.0; clip.clips() * 4],
    );
    p.f32(
        "phase_failures",
        &[clip.clips(), 4],
        vec![0.0; clip.clips() * 4],
    );
    p.i32("clip_steps", &[clip_steps.len()], clip_steps.to_vec());
    p.i32("status", &[envs], vec![0; envs]);
    p.i32("steps", &[envs], vec![0; envs]);
    p.f32("sums", &[envs, 5], vec![0.0; envs * 5]);
    p.i32("robotics_terminated", &[envs], vec![0; envs]);
    let anchor = Arg::Scalar(Scalar::I32(layout.anchor));
    let buffer = |name: &str| Arg::Buffer(name.to_owned());
    let row = shape.reference_layout();
    for k in 0..rows {
        for (name, block) in &buffers {
            let count = envs * block.iter().product::<usize>();
            p.copy(&format!("{name}_by_step"), k * count, name, 0, count);
        }
        let step = Arg::Scalar(Scalar::I32(k as i32));
        super::tracking::launch_reward(&mut p, envs, row, params, k as i32);
        let scoring_args = ["qpos", "xpos", "xquat", "table"]
            .map(buffer)
            .into_iter()
            .chain([Arg::Struct(StructArg::TableLayout(row))])
            .chain(["clip_offsets", "end_effectors", "tracked_bodies"].map(buffer))
            .chain([anchor.clone()])
            .chain(["clip_id", "ref_time"].map(buffer))
            .chain([step])
            .chain(["rewards", "terminated", "truncated"].map(buffer))
            .chain([Arg::Struct(StructArg::Yardstick(yardstick()))])
            .chain(
                [
                    "clip_steps",
                    "status",
                    "steps",
                    "sums",
                    "robotics_terminated",
                ]
                .map(buffer),
            )
            .collect();
        p.launch(&EVALUATION_ACCUMULATE, envs, scoring_args);
    }
    p
}

/// Env `e`'s episode as the training report reads it.
fn episode(out: &super::program::Outputs, e: usize) -> EnvEvaluation {
    let sums = out.f32("sums");
    EnvEvaluation {
        completed: out.i32("status")[e] == COMPLETED,
        robotics_terminated: out.i32("robotics_terminated")[e] != 0,
        steps: out.i32("steps")[e].max(0) as u32,
        pose_error_sum: f64::from(sums[e * 5]),
        global_position_error_sum: f64::from(sums[e * 5 + 1]),
        ee_position_error_sum: f64::from(sums[e * 5 + 2]),
        ee_orientation_error_sum: f64::from(sums[e * 5 + 3]),
    }
}

/// A case: a synthetic clamped clip of `frames` frames at `fps`, evaluated at control step `dt`
/// (the library of one).
fn case(fx: &Fixture, frames: usize, fps: f64, dt: f64) -> Check {
    let motion = synthetic(&fx.character, frames, fps, LoopMode::Clamp);
    let clip = Clip::single(
        &format!("clamped synthetic, {frames} frames at {fps} fps"),
        &motion,
        dt,
    );
    let duration = clip.duration(0);
    let config = TrainConfig::with_motion("synthetic");
    let steps = evaluation_steps(&config.run, duration, dt, LoopMode::Clamp) as usize;
    let rows = steps + EXTRA_STEPS;
    let p = program(
        format!(
            "an evaluation episode: {}, dt {dt:.6} s, {steps} steps",
            clip.name
        ),
        &clip,
        &[0; ENVS],
        &fx.layout,
        &fx.shape,
        dt,
        steps,
        // What the rollout passes: the episode's steps, where the truncation falls too.
        &[steps as i32],
        rows,
        frames as u64 * 1000 + fps as u64,
    );

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
        let episodes: Vec<EnvEvaluation> = (0..ENVS).map(|e| episode(out, e)).collect();
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

/// A library's evaluation in one rollout at control step `dt`: three clamped clips of
/// different lengths and rates and a looping one, two envs per clip (env e on clip e mod 4).
fn library_case(fx: &Fixture, dt: f64) -> Check {
    let clips = [
        (17, 16.0, LoopMode::Clamp),
        (65, 30.0, LoopMode::Clamp),
        (31, 24.0, LoopMode::Wrap),
        (91, 60.0, LoopMode::Clamp),
    ];
    let mut builder = MotionLibraryBuilder::new("episode library", dt);
    for (i, &(frames, fps, mode)) in clips.iter().enumerate() {
        let motion = synthetic(&fx.character, frames, fps, mode);
        builder
            .push(&format!("clip {i}"), "synthetic", &motion, 1.0)
            .expect("the clip joins the library");
    }
    let clip = Clip::of_library(
        "a library of 3 clamped clips and a looping one",
        &builder.finish().expect("the library has clips"),
    );
    let protocol = EvaluationProtocol {
        envs: 8,
        steps: None,
        start: EvalStart::Spread,
        window_s: None,
    };
    let plan: Vec<i32> = (0..clip.clips())
        .map(|c| {
            let segment = clip.segment(c);
            clip_evaluation(&protocol, segment.duration(), dt, segment.loop_mode()).steps as i32
        })
        .collect();
    let horizon = plan.iter().copied().max().unwrap_or(1) as usize;
    let clip_id: Vec<i32> = (0..8).map(|e| (e % clips.len()) as i32).collect();
    let envs = clip_id.len();
    let p = program(
        format!(
            "an evaluation episode: {}, dt {dt:.6} s, clip steps {plan:?}",
            clip.name
        ),
        &clip,
        &clip_id,
        &fx.layout,
        &fx.shape,
        dt,
        horizon,
        &plan,
        horizon + EXTRA_STEPS,
        (1.0 / dt) as u64,
    );
    Check::new(p, move |p, out| {
        let mut r = Report::new(&p.name);
        r.exact("status", out.i32("status"), &vec![COMPLETED; envs]);
        let own: Vec<i32> = clip_id.iter().map(|&c| plan[c as usize]).collect();
        r.exact("scored steps: each env its clip's", out.i32("steps"), &own);
        r.check(
            own.iter().collect::<std::collections::BTreeSet<_>>().len() == clips.len(),
            format!("the clips' episodes differ in length: {plan:?}"),
        );
        for (c, &steps) in plan.iter().enumerate() {
            let episodes: Vec<EnvEvaluation> = (0..envs)
                .filter(|&e| clip_id[e] as usize == c)
                .map(|e| episode(out, e))
                .collect();
            match summarize(&episodes, steps as u32, 0.9) {
                Ok(s) => r.check(
                    s.completed == episodes.len() as u32,
                    format!("clip {c}: {} of {} complete", s.completed, episodes.len()),
                ),
                Err(e) => r.check(false, format!("clip {c}: summarize refuses: {e}")),
            }
        }
        r
    })
}

/// Clamped clips at the frame rates DeepMimic's clips use, at 30 and 60 Hz control; a library
/// of clips of different lengths at both rates.
pub fn checks(fx: &Fixture) -> Vec<Check> {
    let mut checks = Vec::new();
    for (frames, fps) in [(17, 16.0), (49, 24.0), (65, 30.0), (61, 60.0), (121, 120.0)] {
        for dt in [1.0 / 30.0, 1.0 / 60.0] {
            checks.push(case(fx, frames, fps, dt));
        }
    }
    for dt in [1.0 / 30.0, 1.0 / 60.0] {
        checks.push(library_case(fx, dt));
    }
    checks
}
