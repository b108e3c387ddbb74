//! Every env kernel on the GPU, through the generated launchers (`EnvKernels::<kernel>`),
//! against the same cases and f64 references as the Warp CPU run (tests/env_kernels_cpu.rs,
//! tests/kernel_checks/). Run on a machine with an NVIDIA GPU:
//! `cargo test --features gpu --test gpu_env_kernels -- --nocapture`
#![cfg(feature = "gpu")]

mod kernel_checks;
mod skip_support;

use std::collections::BTreeMap;

use instantmimic::cuda::{DeviceRange, Gpu, Stream};
use instantmimic::kernels::{
    DeviceArray, Element, EnvKernels, GoalParams, ObservationParams, ReferenceLayout, ResetParams,
    TrackingParams, Yardstick,
};
use kernel_checks::program::{Arg, HostData, Outputs, Program, Scalar, Step, StructArg};
use kernel_checks::{Check, Fixture, run_checks};

/// A program buffer on the device: flat, viewed with its shape at each launch.
enum DeviceBuffer {
    F32(DeviceArray<f32>),
    F64(DeviceArray<f64>),
    I32(DeviceArray<i32>),
}

impl DeviceBuffer {
    fn upload(gpu: &Gpu, data: &HostData) -> DeviceBuffer {
        let n = data.len();
        let result = match data {
            HostData::F32(v) => DeviceArray::from_slice(gpu, [n], v).map(DeviceBuffer::F32),
            HostData::F64(v) => DeviceArray::from_slice(gpu, [n], v).map(DeviceBuffer::F64),
            HostData::I32(v) => DeviceArray::from_slice(gpu, [n], v).map(DeviceBuffer::I32),
        };
        result.unwrap_or_else(|e| panic!("uploading {n} values: {e}"))
    }

    fn download(&self) -> HostData {
        let result = match self {
            DeviceBuffer::F32(a) => a.download().map(HostData::F32),
            DeviceBuffer::F64(a) => a.download().map(HostData::F64),
            DeviceBuffer::I32(a) => a.download().map(HostData::I32),
        };
        result.unwrap_or_else(|e| panic!("downloading: {e}"))
    }

    /// Elements `[at, at + count)`, as the stream's copies take them.
    fn elements(&self, at: usize, count: usize) -> DeviceRange {
        let (range, size) = match self {
            DeviceBuffer::F32(a) => (a.range(), 4),
            DeviceBuffer::F64(a) => (a.range(), 8),
            DeviceBuffer::I32(a) => (a.range(), 4),
        };
        range
            .and_then(|r| Ok(r.sub(at * size, count * size)?))
            .unwrap_or_else(|e| panic!("elements {at}..+{count}: {e}"))
    }
}

/// The flat array of a buffer of element type `Self`.
trait FlatArray: Element + Sized {
    fn flat(buffer: &DeviceBuffer) -> Option<&DeviceArray<Self>>;
}

impl FlatArray for f32 {
    fn flat(buffer: &DeviceBuffer) -> Option<&DeviceArray<f32>> {
        match buffer {
            DeviceBuffer::F32(a) => Some(a),
            _ => None,
        }
    }
}

impl FlatArray for f64 {
    fn flat(buffer: &DeviceBuffer) -> Option<&DeviceArray<f64>> {
        match buffer {
            DeviceBuffer::F64(a) => Some(a),
            _ => None,
        }
    }
}

impl FlatArray for i32 {
    fn flat(buffer: &DeviceBuffer) -> Option<&DeviceArray<i32>> {
        match buffer {
            DeviceBuffer::I32(a) => Some(a),
            _ => None,
        }
    }
}

/// The arguments of one launch, typed on demand (the program was validated against the ABI).
struct Args<'a> {
    program: &'a Program,
    args: &'a [Arg],
    buffers: &'a BTreeMap<String, DeviceBuffer>,
}

impl Args<'_> {
    fn array<T: FlatArray, const N: usize>(&self, i: usize) -> DeviceArray<T, N> {
        let Arg::Buffer(name) = &self.args[i] else {
            panic!("argument {i} is not a buffer");
        };
        let shape: [usize; N] = self
            .program
            .buffer(name)
            .shape
            .as_slice()
            .try_into()
            .unwrap_or_else(|_| panic!("buffer {name} is not {N}-D"));
        let flat = T::flat(&self.buffers[name])
            .unwrap_or_else(|| panic!("buffer {name} has another element type"));
        flat.view(0, shape)
            .unwrap_or_else(|e| panic!("viewing {name}: {e}"))
    }

    fn scalar(&self, i: usize) -> Scalar {
        match &self.args[i] {
            Arg::Scalar(s) => *s,
            other => panic!("argument {i} is {other:?}, not a scalar"),
        }
    }

    fn f32(&self, i: usize) -> f32 {
        match self.scalar(i) {
            Scalar::F32(v) => v,
            s => panic!("argument {i} is {s:?}"),
        }
    }

    fn f64(&self, i: usize) -> f64 {
        match self.scalar(i) {
            Scalar::F64(v) => v,
            s => panic!("argument {i} is {s:?}"),
        }
    }

    fn i32(&self, i: usize) -> i32 {
        match self.scalar(i) {
            Scalar::I32(v) => v,
            s => panic!("argument {i} is {s:?}"),
        }
    }

    fn tracking(&self, i: usize) -> TrackingParams {
        match &self.args[i] {
            Arg::Struct(StructArg::Tracking(p)) => *p,
            other => panic!("argument {i} is {other:?}"),
        }
    }

    fn reset(&self, i: usize) -> ResetParams {
        match &self.args[i] {
            Arg::Struct(StructArg::Reset(p)) => *p,
            other => panic!("argument {i} is {other:?}"),
        }
    }

    fn observation(&self, i: usize) -> ObservationParams {
        match &self.args[i] {
            Arg::Struct(StructArg::Observation(p)) => *p,
            other => panic!("argument {i} is {other:?}"),
        }
    }

    fn goal(&self, i: usize) -> GoalParams {
        match &self.args[i] {
            Arg::Struct(StructArg::Goal(p)) => *p,
            other => panic!("argument {i} is {other:?}"),
        }
    }

    fn yardstick(&self, i: usize) -> Yardstick {
        match &self.args[i] {
            Arg::Struct(StructArg::Yardstick(p)) => *p,
            other => panic!("argument {i} is {other:?}"),
        }
    }

    fn table_layout(&self, i: usize) -> ReferenceLayout {
        match &self.args[i] {
            Arg::Struct(StructArg::TableLayout(l)) => *l,
            other => panic!("argument {i} is {other:?}"),
        }
    }
}

/// One launch through the kernel's generated launcher.
fn launch(kernels: &EnvKernels, s: &Stream, kernel: &str, dim: usize, a: &Args) {
    let result = match kernel {
        "pd_control" => kernels.pd_control(
            s,
            dim,
            &a.array(0),
            &a.array(1),
            &a.array(2),
            &a.array(3),
            &a.array(4),
            &a.array(5),
            &a.array(6),
            &a.array(7),
            &a.array(8),
            &a.array(9),
        ),
        "pd_targets" => kernels.pd_targets(
            s,
            dim,
            &a.array(0),
            &a.array(1),
            &a.array(2),
            &a.array(3),
            &a.array(4),
            &a.array(5),
            &a.array(6),
            &a.array(7),
            &a.array(8),
            &a.array(9),
            a.f32(10),
            a.i32(11),
            a.f32(12),
            &a.array(13),
        ),
        "tracking_error_sums" => kernels.tracking_error_sums(
            s,
            dim,
            &a.array(0),
            &a.array(1),
            &a.array(2),
            &a.array(3),
            &a.array(4),
            &a.table_layout(5),
            &a.array(6),
            &a.array(7),
            &a.array(8),
            &a.array(9),
            &a.array(10),
            &a.tracking(11),
            &a.array(12),
            &a.array(13),
            &a.array(14),
        ),
        "reward_termination" => kernels.reward_termination(
            s,
            dim,
            &a.array(0),
            &a.array(1),
            &a.array(2),
            &a.array(3),
            &a.array(4),
            &a.table_layout(5),
            &a.array(6),
            &a.array(7),
            &a.array(8),
            &a.array(9),
            &a.tracking(10),
            a.i32(11),
            &a.array(12),
            &a.array(13),
            &a.array(14),
            &a.array(15),
            &a.array(16),
            &a.array(17),
            &a.array(18),
            &a.array(19),
            &a.array(20),
            &a.array(21),
            &a.array(22),
        ),
        "reset_masked" => kernels.reset_masked(
            s,
            dim,
            &a.array(0),
            &a.array(1),
            &a.table_layout(2),
            &a.array(3),
            a.i32(4),
            &a.array(5),
            &a.array(6),
            &a.array(7),
            &a.array(8),
            &a.array(9),
            a.i32(10),
            &a.reset(11),
            &a.array(12),
            &a.array(13),
            &a.array(14),
            &a.array(15),
            &a.array(16),
            &a.array(17),
            &a.array(18),
            &a.array(19),
        ),
        "phase_statistics_update" => kernels.phase_statistics_update(
            s,
            dim,
            a.f32(0),
            a.f32(1),
            a.f32(2),
            a.f32(3),
            &a.array(4),
            &a.array(5),
            &a.array(6),
            &a.array(7),
            &a.array(8),
        ),
        "observe" => kernels.observe(
            s,
            dim,
            &a.array(0),
            &a.array(1),
            &a.array(2),
            &a.array(3),
            &a.array(4),
            &a.array(5),
            &a.array(6),
            &a.table_layout(7),
            &a.array(8),
            &a.array(9),
            &a.array(10),
            &a.array(11),
            &a.array(12),
            &a.array(13),
            &a.observation(14),
            &a.array(15),
        ),
        "observation_moments" => {
            kernels.observation_moments(s, dim, &a.array(0), &a.array(1), &a.array(2))
        }
        "observation_moments_merge" => kernels.observation_moments_merge(
            s,
            dim,
            a.f64(0),
            &a.array(1),
            &a.array(2),
            &a.array(3),
            &a.array(4),
            &a.array(5),
        ),
        "observation_normalize" => kernels.observation_normalize(
            s,
            dim,
            &a.array(0),
            &a.array(1),
            &a.array(2),
            &a.array(3),
            a.f32(4),
            a.i32(5),
            &a.array(6),
            &a.array(7),
        ),
        "linear_elu" => {
            kernels.linear_elu(s, dim, &a.array(0), &a.array(1), &a.array(2), &a.array(3))
        }
        "linear" => kernels.linear(s, dim, &a.array(0), &a.array(1), &a.array(2), &a.array(3)),
        "bias_elu" => kernels.bias_elu(s, dim, &a.array(0), &a.array(1)),
        "bias_add" => kernels.bias_add(s, dim, &a.array(0), &a.array(1)),
        "elu_input_gradient" => {
            kernels.elu_input_gradient(s, dim, &a.array(0), a.i32(1), &a.array(2), &a.array(3))
        }
        "gaussian_sample" => kernels.gaussian_sample(
            s,
            dim,
            &a.array(0),
            &a.array(1),
            &a.array(2),
            &a.array(3),
            a.i32(4),
            a.i32(5),
            a.i32(6),
            a.i32(7),
            &a.array(8),
            &a.array(9),
            &a.array(10),
            &a.array(11),
            &a.array(12),
        ),
        "evaluation_accumulate" => kernels.evaluation_accumulate(
            s,
            dim,
            &a.array(0),
            &a.array(1),
            &a.array(2),
            &a.array(3),
            &a.table_layout(4),
            &a.array(5),
            &a.array(6),
            &a.array(7),
            a.i32(8),
            &a.array(9),
            &a.array(10),
            a.i32(11),
            &a.array(12),
            &a.array(13),
            &a.array(14),
            &a.yardstick(15),
            &a.array(16),
            &a.array(17),
            &a.array(18),
            &a.array(19),
            &a.array(20),
        ),
        "episode_statistics" => kernels.episode_statistics(
            s,
            dim,
            a.i32(0),
            &a.array(1),
            &a.array(2),
            &a.array(3),
            &a.array(4),
            &a.array(5),
            &a.array(6),
            &a.array(7),
            &a.array(8),
        ),
        "rollout_statistics" => {
            kernels.rollout_statistics(s, dim, a.i32(0), &a.array(1), &a.array(2))
        }
        "goal_reward_termination" => kernels.goal_reward_termination(
            s,
            dim,
            &a.array(0),
            &a.goal(1),
            a.i32(2),
            &a.array(3),
            &a.array(4),
            &a.array(5),
            &a.array(6),
            &a.array(7),
            &a.array(8),
            &a.array(9),
            &a.array(10),
            &a.array(11),
            &a.array(12),
        ),
        "goal_reset" => kernels.goal_reset(
            s,
            dim,
            &a.array(0),
            &a.goal(1),
            a.i32(2),
            &a.array(3),
            &a.array(4),
            &a.array(5),
            &a.array(6),
            &a.array(7),
            &a.array(8),
        ),
        "body_frames" => kernels.body_frames(
            s,
            dim,
            &a.array(0),
            &a.array(1),
            a.i32(2),
            &a.array(3),
            &a.array(4),
            &a.array(5),
            &a.array(6),
            &a.array(7),
        ),
        "body_velocities" => kernels.body_velocities(
            s,
            dim,
            &a.array(0),
            &a.array(1),
            a.i32(2),
            &a.array(3),
            &a.array(4),
            &a.array(5),
            a.f32(6),
            &a.array(7),
            &a.array(8),
            &a.array(9),
            &a.array(10),
        ),
        "goal_observe" => {
            kernels.goal_observe(s, dim, &a.array(0), &a.array(1), a.i32(2), &a.array(3))
        }
        other => panic!("no GPU dispatch for kernel {other}"),
    };
    result.unwrap_or_else(|e| panic!("launching {kernel}: {e}"));
}

/// Execution B: every program on GPU 0, one after the other.
fn execute(programs: &[Program]) -> Vec<Outputs> {
    let gpu = Gpu::open(0).expect("opening GPU 0");
    let kernels = EnvKernels::load(&gpu).expect("loading the env kernels");
    let stream = gpu.stream();
    programs
        .iter()
        .map(|program| {
            program
                .validate()
                .unwrap_or_else(|e| panic!("invalid case: {e}"));
            let buffers: BTreeMap<String, DeviceBuffer> = program
                .buffers
                .iter()
                .map(|b| (b.name.clone(), DeviceBuffer::upload(&gpu, &b.data)))
                .collect();
            for step in &program.steps {
                match step {
                    Step::Launch { abi, dim, args } => {
                        let a = Args {
                            program,
                            args,
                            buffers: &buffers,
                        };
                        launch(&kernels, stream, abi.name, *dim, &a);
                    }
                    Step::Copy {
                        src,
                        src_offset,
                        dst,
                        dst_offset,
                        count,
                    } => {
                        stream
                            .copy(
                                &buffers[dst].elements(*dst_offset, *count),
                                &buffers[src].elements(*src_offset, *count),
                            )
                            .expect("copy between buffers");
                    }
                }
            }
            stream
                .synchronize()
                .unwrap_or_else(|e| panic!("{}: the kernels ran: {e}", program.name));
            Outputs {
                buffers: buffers
                    .iter()
                    .map(|(name, b)| (name.clone(), b.download()))
                    .collect(),
            }
        })
        .collect()
}

fn run_on_gpu(kernel: &str, checks: impl FnOnce(&Fixture) -> Vec<Check>) {
    let fixture = Fixture::load();
    run_checks(kernel, checks(&fixture), execute);
}

#[test]
fn gpu_every_character_kernel_matches_the_f64_reference_on_the_g1() {
    let fixture = Fixture::g1();
    run_checks(
        "the G1: pd_targets, pd_control, body_kinematics, reward_termination, observe, evaluation_accumulate, reset_masked",
        kernel_checks::character_checks(&fixture),
        execute,
    );
}

#[test]
fn gpu_pd_control_matches_the_f64_reference() {
    run_on_gpu("pd_control", kernel_checks::control::checks);
}

#[test]
fn gpu_reward_termination_matches_the_f64_reference() {
    run_on_gpu("reward_termination", kernel_checks::tracking::checks);
}

#[test]
fn gpu_an_evaluation_episode_on_a_clamped_clip_ends_where_the_evaluation_expects() {
    run_on_gpu(
        "reward_termination + evaluation_accumulate",
        kernel_checks::episode::checks,
    );
}

#[test]
fn gpu_reset_masked_matches_the_f64_reference() {
    run_on_gpu("reset_masked", kernel_checks::reset::reset_checks);
}

#[test]
fn gpu_phase_statistics_update_matches_the_f64_reference() {
    run_on_gpu(
        "phase_statistics_update",
        kernel_checks::reset::statistics_checks,
    );
}

#[test]
fn gpu_observe_matches_the_f64_reference_block_by_block() {
    run_on_gpu("observe", kernel_checks::observe::checks);
}

#[test]
fn gpu_observation_moments_and_merge_match_two_pass_f64_statistics() {
    run_on_gpu(
        "observation_moments",
        kernel_checks::normalize::moments_checks,
    );
}

#[test]
fn gpu_observation_normalize_matches_the_f64_reference() {
    run_on_gpu(
        "observation_normalize",
        kernel_checks::normalize::normalize_checks,
    );
}

#[test]
fn gpu_linear_layers_match_the_f64_reference() {
    run_on_gpu("linear_elu / linear", kernel_checks::policy::linear_checks);
}

#[test]
fn gpu_gaussian_sample_matches_the_f64_reference() {
    run_on_gpu("gaussian_sample", kernel_checks::policy::sample_checks);
}

#[test]
fn gpu_gemm_epilogues_match_the_f64_reference() {
    run_on_gpu(
        "bias_elu / bias_add / elu_input_gradient",
        kernel_checks::gemm_epilogue::checks,
    );
}

#[test]
fn gpu_evaluation_accumulate_matches_the_f64_reference() {
    run_on_gpu("evaluation_accumulate", kernel_checks::evaluate::checks);
}

#[test]
fn gpu_rollout_statistics_match_the_f64_reference() {
    run_on_gpu("episode_statistics", kernel_checks::statistics::checks);
}

#[test]
fn gpu_goal_reward_termination_matches_the_f64_reference() {
    run_on_gpu(
        "goal_reward_termination",
        kernel_checks::goal::reward_checks,
    );
}

#[test]
fn gpu_goal_reset_matches_the_f64_reference() {
    run_on_gpu("goal_reset", kernel_checks::goal::reset_checks);
}

#[test]
fn gpu_goal_observe_matches_the_f64_reference() {
    run_on_gpu("goal_observe", kernel_checks::goal::observe_checks);
}

#[test]
fn gpu_body_kinematics_matches_the_f64_reference() {
    run_on_gpu("body_kinematics", kernel_checks::kinematics::checks);
}
