//! Every env kernel against an f64 CPU reference (issue 4: relative error <= 1e-4 on random
//! inputs), one reference and two executions:
//!
//! - the cases and references live here: each kernel family's module builds [`Check`]s (a
//!   [`program::Program`] of buffers and launches with seeded random inputs of realistic range:
//!   the humanoid's joint layout, a real reference table) and judges the outputs with a
//!   [`compare::Report`];
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
use instantmimic::motion::table::HEADER_LEN;
use instantmimic::motion::{
    Character, LoopMode, MotionLibrary, MotionLibraryBuilder, ReferenceMotion, SyntheticMotion,
    TableSegment,
};

use compare::Report;
use program::{Outputs, Program};
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

/// What a case's envs track: a motion library with its name. A single clip is the library of
/// one (its buffer is the clip's `ReferenceTable::data`, value for value, and its one clip's
/// header offset is 0), as the rollout uploads it; a library's cases give each env a clip.
#[derive(Clone)]
pub struct Clip {
    pub name: String,
    pub library: MotionLibrary,
}

impl Clip {
    /// `motion` as the library of one, resampled every `dt` seconds.
    pub fn single(name: &str, motion: &ReferenceMotion, dt: f64) -> Clip {
        Clip {
            name: name.to_owned(),
            library: MotionLibrary::single(name, name, motion, dt).expect("the clip resamples"),
        }
    }

    /// Clips in the library.
    pub fn clips(&self) -> usize {
        self.library.num_clips()
    }

    /// Clip `clip`'s own table (a view of the library's buffer).
    pub fn segment(&self, clip: usize) -> TableSegment<'_> {
        self.library.segment(clip).expect("a clip of the library")
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
        self.library.lookup(clip, t).expect("a clip of the library")
    }

    /// The table as the kernels read it.
    pub fn data(&self) -> Vec<f32> {
        self.library.data().to_vec()
    }

    /// Each clip's header offset, as the kernels read it (`clip_offsets`).
    pub fn offsets(&self) -> Vec<i32> {
        self.library
            .header_offsets()
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

/// What every case is built from: the humanoid, its joint layout and three references.
pub struct Fixture {
    pub character: Character,
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
        let library = Clip {
            name: "a library of 5 clips".to_owned(),
            library: builder.finish().expect("the library has clips"),
        };
        Fixture {
            character,
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

/// `n` f32 NaNs (the poison of float outputs).
pub fn nan_f32(n: usize) -> Vec<f32> {
    vec![f32::NAN; n]
}
