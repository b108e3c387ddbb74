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
pub mod normalize;
pub mod observe;
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
use instantmimic::motion::{Character, LoopMode, ReferenceMotion, ReferenceTable, SyntheticMotion};

use compare::Report;
use program::{Outputs, Program};

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

/// A reference table with its name.
pub struct Clip {
    pub name: String,
    pub table: ReferenceTable,
}

impl Clip {
    pub fn wraps(&self) -> bool {
        self.table.loop_mode() == LoopMode::Wrap
    }

    /// The table as the kernels read it.
    pub fn data(&self) -> Vec<f32> {
        self.table.data().to_vec()
    }
}

/// What every case is built from: the humanoid, its joint layout and two reference tables.
pub struct Fixture {
    pub character: Character,
    pub layout: JointLayout,
    /// The built-in backflip (a wrapped clip, so that positions shift per cycle).
    pub main: Clip,
    /// A synthetic clamped clip (episode end at the clip's end, clamped start times).
    pub clamped: Clip,
}

impl Fixture {
    pub fn load() -> Fixture {
        let character = Character::humanoid().expect("the embedded humanoid loads");
        let layout = JointLayout::for_character(&character).expect("the humanoid's joint layout");
        let table = |motion: &ReferenceMotion| {
            ReferenceTable::build(motion, CONTROL_DT).expect("the reference table builds")
        };
        let backflip = resolve_motion("backflip", None)
            .and_then(|resolved| resolved.load(&character))
            .expect("the built-in backflip loads");
        let main = Clip {
            name: "backflip".to_owned(),
            table: table(&backflip),
        };
        let clamped_motion = SyntheticMotion {
            frames: 46,
            frame_dt: 1.0 / 60.0,
            loop_mode: LoopMode::Clamp,
            amplitude: 0.8,
            ..SyntheticMotion::default()
        }
        .reference_motion(&character)
        .expect("synthetic frames are valid");
        let clamped = Clip {
            name: "synthetic clamped walk".to_owned(),
            table: table(&clamped_motion),
        };
        Fixture {
            character,
            layout,
            main,
            clamped,
        }
    }

    pub fn clips(&self) -> [&Clip; 2] {
        [&self.main, &self.clamped]
    }
}

/// `n` f32 NaNs (the poison of float outputs).
pub fn nan_f32(n: usize) -> Vec<f32> {
    vec![f32::NAN; n]
}
