//! Every env kernel against an f64 CPU reference (issue 4: relative error <= 1e-4 on random
//! inputs), one reference and two executions:
//!
//! - the cases and references live here: each kernel family's module builds [`Check`]s (a
//!   [`program::Program`] of buffers and launches with seeded random inputs of realistic range:
//!   the humanoid's joint layout, a real reference table; the reward, the observation and the
//!   evaluation also on a second character, the G1, whose sizes, tracked bodies and row layout
//!   differ: [`Fixture::g1`]) and judges the outputs with a [`compare::Report`];
//! - execution A (`tests/env_kernels_cpu.rs`, runs in CI): Warp's CPU device through
//!   `kernels_py/checks/run_kernel.py` ([`cpu`]);
//! - execution B (`tests/gpu_env_kernels.rs`, feature `gpu`): the generated launchers on a GPU.
//!
//! Outputs the kernel must write are poisoned (NaN, or [`POISON_I32`]) before each run, so an
//! unwritten element fails; what it must not write is compared bit for bit.
#![allow(dead_code)]

pub mod compare;
pub mod control;
pub mod cpu;
pub mod episode;
pub mod evaluate;
pub mod gemm_epilogue;
pub mod goal;
pub mod kinematics;
pub mod normalize;
pub mod observe;
pub mod phase_merge;
pub mod physics;
pub mod policy;
pub mod program;
pub mod quat;
pub mod reset;
pub mod rng;
pub mod statistics;
pub mod tracking;

use instantmimic::env::layout::JointLayout;
use instantmimic::motion::find::resolve_motion;
use instantmimic::motion::table::{
    HEADER_CYCLE_DISPLACEMENT, HEADER_DURATION, HEADER_LEN, HEADER_NUM_ROWS, HEADER_ROW_DT,
    HEADER_ROW_STRIDE, HEADER_WRAP, ROW_ROUNDING, TableLayout,
};
use instantmimic::motion::{
    Character, LoopMode, MotionLibrary, MotionLibraryBuilder, ReferenceMotion, SyntheticMotion,
    TableSegment,
};

use compare::Report;
use physics::Shape;
use program::{Outputs, Program};
use quat::{qexp, wxyz};
use rng::Sampler;

/// Integer poison: no kernel writes this value.
pub const POISON_I32: i32 = -0x5A5A_5A5A;
/// The control timestep of the default config (4 substeps of 1/120 s).
pub const CONTROL_DT: f64 = 1.0 / 30.0;

/// Judges a program's outputs (given the program, with its inputs).
pub type Verify = Box<dyn Fn(&Program, &Outputs) -> Report>;

/// A program and how to judge its outputs.
pub struct Check {
    pub program: Program,
    pub verify: Verify,
}

impl Check {
    pub fn new(program: Program, verify: impl Fn(&Program, &Outputs) -> Report + 'static) -> Check {
        Check {
            program,
            verify: Box::new(verify),
        }
    }
}

/// Runs `checks` with `execute` (one call for all programs), prints every measure and the
/// largest relative error, and panics listing every failed check.
pub fn run_checks(
    kernel: &str,
    checks: Vec<Check>,
    execute: impl FnOnce(&[Program]) -> Vec<Outputs>,
) {
    let programs: Vec<Program> = checks.iter().map(|c| c.program.clone()).collect();
    let outputs = execute(&programs);
    assert_eq!(outputs.len(), checks.len(), "one output per program");
    let reports: Vec<Report> = checks
        .iter()
        .zip(&outputs)
        .map(|(c, o)| (c.verify)(&c.program, o))
        .collect();
    compare::conclude(kernel, &reports);
}

/// What a case's envs track: a motion library's buffer, clip index and row layout, with its
/// name. A single clip is the library of one (its buffer is the clip's `ReferenceTable::data`,
/// value for value, and its one clip's header offset is 0), as the rollout uploads it; a
/// library's cases give each env a clip. The f64 lookups are `TableSegment`'s, which
/// `MotionLibrary::lookup` and `ReferenceTable::lookup` are.
#[derive(Clone)]
pub struct Clip {
    pub name: String,
    data: Vec<f32>,
    header_offsets: Vec<usize>,
    layout: TableLayout,
    quaternion_offsets: Vec<usize>,
    position_offsets: Vec<usize>,
}

impl Clip {
    /// `motion` as the library of one, resampled every `dt` seconds.
    pub fn single(name: &str, motion: &ReferenceMotion, dt: f64) -> Clip {
        let library = MotionLibrary::single(name, name, motion, dt).expect("the clip resamples");
        Clip::of_library(name, &library)
    }

    /// `library`'s table as it is uploaded.
    pub fn of_library(name: &str, library: &MotionLibrary) -> Clip {
        Clip {
            name: name.to_owned(),
            data: library.data().to_vec(),
            header_offsets: library.header_offsets(),
            layout: library.layout(),
            quaternion_offsets: library.quaternion_offsets().to_vec(),
            position_offsets: library.position_offsets().to_vec(),
        }
    }

    /// A library of synthetic tables for a character of `shape`, one after another: each a
    /// smooth, made-up motion (kernels only do arithmetic on a row, so its body frames need not
    /// be the kinematics of its qpos), resampled every `dt` seconds as `ReferenceTable::build`
    /// lays rows out.
    pub fn synthetic(name: &str, shape: &Shape, clips: &[SyntheticTable], dt: f64) -> Clip {
        let layout = shape.table;
        let mut quaternion_offsets: Vec<usize> =
            shape.quaternions.iter().map(|a| layout.qpos + a).collect();
        quaternion_offsets.extend((0..layout.nbody).map(|b| layout.body_quat + 4 * b));
        quaternion_offsets.push(layout.heading);
        let mut position_offsets = vec![layout.qpos];
        position_offsets.extend((0..layout.nbody).map(|b| layout.body_pos + 3 * b));
        position_offsets.push(layout.com_pos);
        let mut data = Vec::new();
        let mut header_offsets = Vec::new();
        for table in clips {
            header_offsets.push(data.len());
            data.extend(table.data(shape, dt));
        }
        Clip {
            name: name.to_owned(),
            data,
            header_offsets,
            layout,
            quaternion_offsets,
            position_offsets,
        }
    }

    /// Clips in the library.
    pub fn clips(&self) -> usize {
        self.header_offsets.len()
    }

    /// Clip `clip`'s own table (a view of the library's buffer).
    pub fn segment(&self, clip: usize) -> TableSegment<'_> {
        TableSegment::new(
            &self.data[self.header_offsets[clip]..],
            self.layout,
            &self.quaternion_offsets,
            &self.position_offsets,
        )
        .expect("a clip of the library")
    }

    pub fn wraps(&self, clip: usize) -> bool {
        self.segment(clip).loop_mode() == LoopMode::Wrap
    }

    /// Clip `clip`'s duration as its header holds it (f32, widened).
    pub fn duration(&self, clip: usize) -> f64 {
        self.segment(clip).duration()
    }

    /// Clip `clip`'s header (`HEADER_*` index it).
    pub fn header(&self, clip: usize) -> &[f32] {
        &self.segment(clip).data()[..HEADER_LEN]
    }

    /// The f64 reference row of clip `clip` at its time `t` (`MotionLibrary::lookup`, for the
    /// library of one `ReferenceTable::lookup`).
    pub fn lookup(&self, clip: usize, t: f64) -> Vec<f64> {
        self.segment(clip).lookup(t)
    }

    /// The table as the kernels read it.
    pub fn data(&self) -> Vec<f32> {
        self.data.clone()
    }

    /// Each clip's header offset, as the kernels read it (`clip_offsets`).
    pub fn offsets(&self) -> Vec<i32> {
        self.header_offsets
            .iter()
            .map(|&o| i32::try_from(o).expect("an int32 offset"))
            .collect()
    }

    /// The clip of each of `n` envs: 0 for the library of one, drawing nothing from `rng` (the
    /// single-clip cases' inputs stay what they were before libraries); uniform over a
    /// library's clips, every clip at least once where `n` allows.
    pub fn clip_ids(&self, n: usize, rng: &mut Sampler) -> Vec<i32> {
        let clips = self.clips();
        if clips == 1 {
            return vec![0; n];
        }
        (0..n)
            .map(|e| {
                if e < clips {
                    e as i32
                } else {
                    rng.index(0, clips) as i32
                }
            })
            .collect()
    }
}

/// A made-up motion for [`Clip::synthetic`]: `duration` seconds, wrapped or clamped, the root
/// moving forward at `speed` and turning at `turn` (rad/s), every value swinging with its own
/// phase (from `seed`).
#[derive(Clone, Copy, Debug)]
pub struct SyntheticTable {
    pub duration: f64,
    pub loop_mode: LoopMode,
    pub speed: f64,
    pub turn: f64,
    pub seed: u64,
}

impl SyntheticTable {
    /// Header and rows for a character of `shape`, a row every `dt` seconds and the last at the
    /// clip's end (docs/reference_table.md, "Rows").
    pub fn data(&self, shape: &Shape, dt: f64) -> Vec<f32> {
        let l = shape.table;
        let d = self.duration;
        let rows = (d / dt - ROW_ROUNDING).ceil().max(1.0) as usize + 1;
        let mut rng = Sampler::new(self.seed);
        // Per value: a phase; per body: where it sits from the root, and a swing axis.
        let phases: Vec<f64> = (0..l.stride)
            .map(|_| rng.uniform(0.0, std::f64::consts::TAU))
            .collect();
        let offsets: Vec<[f64; 3]> = (0..l.nbody)
            .map(|b| {
                if b == 0 {
                    [0.0; 3]
                } else {
                    [
                        rng.uniform(-0.3, 0.3),
                        rng.uniform(-0.3, 0.3),
                        rng.uniform(-0.7, 0.5),
                    ]
                }
            })
            .collect();
        let axes: Vec<[f64; 3]> = (0..l.nbody + shape.quaternions.len())
            .map(|_| rng.normal3(1.0))
            .collect();
        let omega = std::f64::consts::TAU / d;
        let mut data = vec![0.0f32; HEADER_LEN + rows * l.stride];
        let wrap = self.loop_mode == LoopMode::Wrap;
        data[HEADER_NUM_ROWS] = rows as f32;
        data[HEADER_ROW_DT] = dt as f32;
        data[HEADER_DURATION] = d as f32;
        data[HEADER_WRAP] = if wrap { 1.0 } else { 0.0 };
        let heading_at = |t: f64| self.turn * t;
        let root_at = |t: f64| {
            let h = heading_at(t);
            let r = self.speed * t;
            [r * h.cos(), r * h.sin(), 0.75 + 0.04 * (omega * t).sin()]
        };
        if wrap {
            let end = root_at(d);
            data[HEADER_CYCLE_DISPLACEMENT] = end[0] as f32;
            data[HEADER_CYCLE_DISPLACEMENT + 1] = end[1] as f32;
        }
        data[HEADER_ROW_STRIDE] = l.stride as f32;
        for r in 0..rows {
            let t = if r + 1 == rows { d } else { r as f64 * dt };
            let swing = |i: usize, amplitude: f64| amplitude * (omega * t + phases[i]).sin();
            let yaw = qexp([0.0, 0.0, heading_at(t)]);
            let mut row = vec![0.0f64; l.stride];
            let root = root_at(t);
            row[l.qpos..l.qpos + 3].copy_from_slice(&root);
            for a in 3..shape.nq() {
                row[l.qpos + a] = swing(l.qpos + a, 0.5);
            }
            for (k, &a) in shape.quaternions.iter().enumerate() {
                let axis = axes[l.nbody + k];
                let tilt = qexp(axis.map(|x| 0.3 * x * (omega * t + phases[a]).sin()));
                let q = if k == 0 { yaw * tilt } else { tilt };
                row[l.qpos + a..l.qpos + a + 4].copy_from_slice(&wxyz(&q));
            }
            for k in 0..shape.nv() {
                row[l.qvel + k] = swing(l.qvel + k, 2.0);
            }
            for b in 0..l.nbody {
                let p = l.body_pos + 3 * b;
                for c in 0..3 {
                    row[p + c] = root[c] + offsets[b][c] + swing(p + c, 0.05);
                    row[l.body_linvel + 3 * b + c] = swing(l.body_linvel + 3 * b + c, 1.5);
                    row[l.body_angvel + 3 * b + c] = swing(l.body_angvel + 3 * b + c, 3.0);
                }
                let axis = axes[b];
                let q = yaw * qexp(axis.map(|x| 0.4 * x * (omega * t + phases[p]).sin()));
                row[l.body_quat + 4 * b..l.body_quat + 4 * b + 4].copy_from_slice(&wxyz(&q));
            }
            for c in 0..3 {
                row[l.com_pos + c] = root[c] + [0.0, 0.0, 0.05][c] + swing(l.com_pos + c, 0.02);
                row[l.com_vel + c] = swing(l.com_vel + c, 1.0);
            }
            row[l.heading..l.heading + 4].copy_from_slice(&wxyz(&yaw));
            let at = HEADER_LEN + r * l.stride;
            for (dst, v) in data[at..at + l.stride].iter_mut().zip(&row) {
                *dst = *v as f32;
            }
        }
        data
    }
}

/// What every case is built from: a character (the humanoid, or [`Fixture::g1`]), its shape and
/// joint layout and three references.
pub struct Fixture {
    pub character: Character,
    pub shape: Shape,
    pub layout: JointLayout,
    /// The built-in backflip (a wrapped clip, so that positions shift per cycle).
    pub main: Clip,
    /// A synthetic clamped clip (episode end at the clip's end, clamped start times).
    pub clamped: Clip,
    /// A library of several clips: wrapped and clamped, at different frame rates and lengths,
    /// with different per-cycle displacements (the backflip first, so that clip 0 is not the
    /// only one with a non-zero header offset).
    pub library: Clip,
}

/// The library fixture's clips besides the backflip: (frames, frames per second, loop mode,
/// forward speed, turn rate).
const LIBRARY_SYNTHETIC: [(usize, f64, LoopMode, f64, f64); 4] = [
    (46, 60.0, LoopMode::Clamp, 1.2, 0.0),
    (25, 24.0, LoopMode::Wrap, 1.5, 0.4),
    (121, 120.0, LoopMode::Clamp, 0.8, -0.3),
    (17, 16.0, LoopMode::Wrap, 2.0, 0.0),
];

impl Fixture {
    pub fn load() -> Fixture {
        let character = Character::humanoid().expect("the embedded humanoid loads");
        let layout = JointLayout::for_character(&character).expect("the humanoid's joint layout");
        let backflip = resolve_motion("backflip", None)
            .and_then(|resolved| resolved.load(&character))
            .expect("the built-in backflip loads");
        let main = Clip::single("backflip", &backflip, CONTROL_DT);
        let clamped_motion = SyntheticMotion {
            frames: 46,
            frame_dt: 1.0 / 60.0,
            loop_mode: LoopMode::Clamp,
            amplitude: 0.8,
            ..SyntheticMotion::default()
        }
        .reference_motion(&character)
        .expect("synthetic frames are valid");
        let clamped = Clip::single("synthetic clamped walk", &clamped_motion, CONTROL_DT);
        let mut builder = MotionLibraryBuilder::new("kernel check library", CONTROL_DT);
        builder
            .push("backflip", "built in", &backflip, 1.0)
            .expect("the backflip joins the library");
        for (i, (frames, fps, loop_mode, forward_speed, turn_rate)) in
            LIBRARY_SYNTHETIC.into_iter().enumerate()
        {
            let motion = SyntheticMotion {
                frames,
                frame_dt: 1.0 / fps,
                loop_mode,
                forward_speed,
                turn_rate,
                amplitude: 0.6,
            }
            .reference_motion(&character)
            .expect("synthetic frames are valid");
            let name = format!(
                "synthetic {} {frames} frames at {fps} fps",
                loop_mode.deepmimic_name()
            );
            builder
                .push(&name, "synthetic", &motion, 1.0 + i as f64)
                .expect("the clip joins the library");
        }
        let library = Clip::of_library(
            "a library of 5 clips",
            &builder.finish().expect("the library has clips"),
        );
        Fixture {
            shape: Shape::of(&character),
            character,
            layout,
            main,
            clamped,
            library,
        }
    }

    /// The G1 (29 hinges, 30 bodies of which 14 tracked, no ball joint) with synthetic tables of
    /// its row layout: the reward, the observation and the evaluation on a second character.
    pub fn g1() -> Fixture {
        let character = Character::built_in("g1")
            .expect("the G1 is built in")
            .expect("the embedded G1 loads");
        Fixture::synthetic(character)
    }

    /// `character` with synthetic references: a wrapped clip, a clamped one and a library of
    /// both kinds at other lengths.
    pub fn synthetic(character: Character) -> Fixture {
        let layout = JointLayout::for_character(&character).expect("the character's layout");
        let shape = Shape::of(&character);
        let table = |duration, loop_mode, speed, turn, seed| SyntheticTable {
            duration,
            loop_mode,
            speed,
            turn,
            seed,
        };
        let name = character.name().to_owned();
        let main_table = table(2.1, LoopMode::Wrap, 1.1, 0.2, 1);
        let clamped_table = table(0.75, LoopMode::Clamp, 0.8, 0.0, 2);
        let main = Clip::synthetic(
            &format!("{name}: synthetic wrapped"),
            &shape,
            &[main_table],
            CONTROL_DT,
        );
        let clamped = Clip::synthetic(
            &format!("{name}: synthetic clamped"),
            &shape,
            &[clamped_table],
            CONTROL_DT,
        );
        let library = Clip::synthetic(
            &format!("{name}: a library of 4 synthetic clips"),
            &shape,
            &[
                main_table,
                table(1.4, LoopMode::Clamp, 1.2, -0.3, 3),
                table(0.5, LoopMode::Wrap, 1.5, 0.4, 4),
                clamped_table,
            ],
            CONTROL_DT,
        );
        Fixture {
            character,
            shape,
            layout,
            main,
            clamped,
            library,
        }
    }

    /// The references cases pick by index: 0 the backflip, 1 the clamped clip (each the
    /// library of one), 2 the library.
    pub fn clips(&self) -> [&Clip; 3] {
        [&self.main, &self.clamped, &self.library]
    }
}

/// The checks of the kernels that read the character's sizes, joints, tracked bodies and row
/// layout (the PD targets and torques, the reward, the observation, the evaluation's scoring,
/// the reset, the body kinematics), for a second character ([`Fixture::g1`]).
pub fn character_checks(fx: &Fixture) -> Vec<Check> {
    [
        control::checks(fx),
        kinematics::checks(fx),
        tracking::checks(fx),
        observe::checks(fx),
        evaluate::checks(fx),
        reset::reset_checks(fx),
    ]
    .into_iter()
    .flatten()
    .collect()
}

/// `n` f32 NaNs (the poison of float outputs).
pub fn nan_f32(n: usize) -> Vec<f32> {
    vec![f32::NAN; n]
}
