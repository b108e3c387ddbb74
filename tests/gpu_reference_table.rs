//! The GPU reference-table lookup (`kernels_py/env/reference.py`, launched through the
//! generated `EnvKernels::lookup_reference`) against its CPU twin `ReferenceTable::lookup`, for
//! single clips (the library of one) and for a motion library with a clip per time
//! (`MotionLibrary::lookup`). Run on a machine with an NVIDIA GPU:
//! `cargo test --features gpu --test gpu_reference_table -- --nocapture`
//!
//! Every value of ~10 000 looked-up rows per clip must agree with the CPU in f64 within
//! `1e-6 * max(1, |cpu|)`: 1e-6 absolute for values up to 1 (quaternions, most positions and
//! joint angles), 1e-6 relative above, where the GPU's `f32` output alone rounds by up to
//! 6e-8 relative and an absolute 1e-6 is finer than one `f32` step from 16 on (velocities,
//! positions several cycles out). Quaternions are compared up to sign. Wrapped clips are
//! sampled over several cycles but not within 1e-5 s of a cycle boundary, where the pose jumps
//! and the two sides may round t / D to different cycles (`docs/reference_table.md`).
#![cfg(feature = "gpu")]

use instantmimic::cuda::Gpu;
use instantmimic::env::DeviceReferenceTable;
use instantmimic::kernels::{DeviceArray, DeviceArray2, EnvKernels};
use instantmimic::motion::built_in::BUILT_IN_CLIPS;
use instantmimic::motion::find::MotionSource;
use instantmimic::motion::table::{HEADER_LEN, HUMANOID_LAYOUT};
use instantmimic::motion::{
    Character, LoopMode, MotionLibrary, MotionLibraryBuilder, ReferenceMotion, ReferenceTable,
    SyntheticMotion, TableLayout, TableSegment,
};

const CONTROL_DT: f64 = 1.0 / 30.0;
const LOOKUPS: usize = 10_000;
/// Agreement: |gpu - cpu| <= TOLERANCE * max(1, |cpu|).
const TOLERANCE: f64 = 1e-6;
/// Wrapped clips: no sample closer than this to a cycle boundary (s).
const SEAM_MARGIN: f64 = 1e-5;

/// splitmix64: deterministic samples without a dependency.
struct Samples(u64);

impl Samples {
    fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }

    /// Uniform in [lo, hi).
    fn uniform(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// Lookup times for `table`: random ones plus row times, the ends, and non-finite times.
fn lookup_times(table: TableSegment<'_>, seed: u64) -> Vec<f32> {
    let d = table.duration();
    let mut times: Vec<f32> = vec![0.0, -0.0, f32::NAN, f32::INFINITY, f32::NEG_INFINITY];
    let wrap = table.loop_mode() == LoopMode::Wrap;
    let near_seam = |t: f32| {
        let t = f64::from(t);
        let k = (t / d).round();
        t != k * d && (t - k * d).abs() < SEAM_MARGIN
    };
    for r in 0..table.num_rows() {
        times.push(table.row_time(r) as f32);
    }
    if !wrap {
        times.extend([d as f32, -1.0, (d + 1.0) as f32]);
    }
    let mut samples = Samples(seed);
    while times.len() < LOOKUPS {
        let t = if wrap {
            // Cycles -2 to 4: negative times, and shifts of several displacements.
            samples.uniform(-2.0 * d, 4.0 * d) as f32
        } else {
            samples.uniform(-0.5, d + 0.5) as f32
        };
        if !(wrap && near_seam(t)) {
            times.push(t);
        }
    }
    times.retain(|&t| !(wrap && near_seam(t)));
    times
}

/// A readable name for row value `j` of `layout`.
fn slot_name(layout: &TableLayout, j: usize) -> String {
    const XYZ: [&str; 3] = ["x", "y", "z"];
    const WXYZ: [&str; 4] = ["w", "x", "y", "z"];
    let fields = [
        ("qpos", layout.qpos, layout.nq, 1),
        ("qvel", layout.qvel, layout.nv, 1),
        ("body_pos", layout.body_pos, layout.nbody, 3),
        ("body_quat", layout.body_quat, layout.nbody, 4),
        ("body_linvel", layout.body_linvel, layout.nbody, 3),
        ("body_angvel", layout.body_angvel, layout.nbody, 3),
        ("com_pos", layout.com_pos, 1, 3),
        ("com_vel", layout.com_vel, 1, 3),
        ("heading", layout.heading, 1, 4),
    ];
    for (name, start, count, width) in fields {
        if j >= start && j < start + count * width {
            let (item, component) = ((j - start) / width, (j - start) % width);
            return match width {
                1 => format!("{name}[{item}] (slot {j})"),
                3 if count == 1 => format!("{name}.{} (slot {j})", XYZ[component]),
                3 => format!("{name}[body {item}].{} (slot {j})", XYZ[component]),
                _ if count == 1 => format!("{name}.{} (slot {j})", WXYZ[component]),
                _ => format!("{name}[body {item}].{} (slot {j})", WXYZ[component]),
            };
        }
    }
    format!("slot {j}")
}

/// One value that disagrees (or the worst that agrees).
#[derive(Debug, Clone)]
struct Mismatch {
    time: f32,
    slot: usize,
    gpu: f32,
    cpu: f64,
    error: f64,
    tolerance: f64,
}

struct Comparison {
    max_abs: f64,
    /// The largest error / tolerance.
    worst: Option<Mismatch>,
    failures: Vec<Mismatch>,
    values: usize,
}

/// The GPU's rows against `cpu(i)`, the CPU's row of lookup i (at `times[i]`).
fn compare(
    cpu: impl Fn(usize) -> Vec<f64>,
    layout: TableLayout,
    quaternion_offsets: &[usize],
    times: &[f32],
    gpu: &[f32],
) -> Comparison {
    let stride = layout.stride;
    let mut result = Comparison {
        max_abs: 0.0,
        worst: None,
        failures: Vec::new(),
        values: 0,
    };
    for (i, &t) in times.iter().enumerate() {
        let cpu = cpu(i);
        let row = &gpu[i * stride..(i + 1) * stride];
        // Quaternions q and -q are the same rotation: take the CPU's sign closest to the GPU's.
        let mut sign = vec![1.0; stride];
        for &q in quaternion_offsets {
            let diff = |s: f64| {
                (0..4)
                    .map(|c| (f64::from(row[q + c]) - s * cpu[q + c]).abs())
                    .fold(0.0, f64::max)
            };
            if diff(-1.0) < diff(1.0) {
                sign[q..q + 4].fill(-1.0);
            }
        }
        for j in 0..stride {
            let expected = sign[j] * cpu[j];
            let error = (f64::from(row[j]) - expected).abs();
            let error = if error.is_nan() { f64::INFINITY } else { error };
            let tolerance = TOLERANCE * expected.abs().max(1.0);
            result.values += 1;
            result.max_abs = result.max_abs.max(error);
            let m = Mismatch {
                time: t,
                slot: j,
                gpu: row[j],
                cpu: expected,
                error,
                tolerance,
            };
            if result
                .worst
                .as_ref()
                .is_none_or(|w| error / tolerance > w.error / w.tolerance)
            {
                result.worst = Some(m.clone());
            }
            if error > tolerance {
                result.failures.push(m);
            }
        }
    }
    result
}

fn humanoid() -> Character {
    Character::humanoid().expect("the embedded humanoid loads")
}

fn synthetic_motion(motion: &SyntheticMotion) -> ReferenceMotion {
    motion
        .reference_motion(&humanoid())
        .expect("synthetic frames are valid")
}

fn synthetic_table(motion: &SyntheticMotion) -> ReferenceTable {
    ReferenceTable::build(&synthetic_motion(motion), CONTROL_DT).expect("table")
}

/// The clips to check: synthetic ones (wrapped and clamped, 30, 60 and 120 fps, turning) and
/// every built-in DeepMimic clip (15 to 60 fps).
fn motions() -> Vec<(String, ReferenceMotion)> {
    let mut out = vec![
        (
            "synthetic walk (wrap, 30 fps)".to_owned(),
            synthetic_motion(&SyntheticMotion::default()),
        ),
        (
            "synthetic turning run (wrap, 60 fps)".to_owned(),
            synthetic_motion(&SyntheticMotion {
                frames: 49,
                frame_dt: 1.0 / 60.0,
                forward_speed: 3.0,
                turn_rate: 0.8,
                amplitude: 1.0,
                ..SyntheticMotion::default()
            }),
        ),
        (
            "synthetic clamp (60 fps, 0.75 s)".to_owned(),
            synthetic_motion(&SyntheticMotion {
                frames: 46,
                frame_dt: 1.0 / 60.0,
                loop_mode: LoopMode::Clamp,
                amplitude: 0.8,
                ..SyntheticMotion::default()
            }),
        ),
        (
            "synthetic clamp (120 fps, 2 s)".to_owned(),
            synthetic_motion(&SyntheticMotion {
                frames: 241,
                frame_dt: 1.0 / 120.0,
                loop_mode: LoopMode::Clamp,
                turn_rate: -0.5,
                ..SyntheticMotion::default()
            }),
        ),
    ];
    let character = humanoid();
    for clip in &BUILT_IN_CLIPS {
        let reference = MotionSource::BuiltIn(clip)
            .load(&character)
            .expect("the clip loads");
        let mode = reference.clip().loop_mode();
        out.push((format!("{} ({mode:?})", clip.name), reference));
    }
    out
}

/// The tables to check, each clip alone.
fn tables() -> Vec<(String, ReferenceTable)> {
    motions()
        .into_iter()
        .map(|(name, motion)| {
            let table = ReferenceTable::build(&motion, CONTROL_DT).expect("table");
            (name, table)
        })
        .collect()
}

/// Every clip of [`motions`] in one library, in that order.
fn library() -> MotionLibrary {
    let mut builder = MotionLibraryBuilder::new("gpu_reference_table", CONTROL_DT);
    for (i, (name, motion)) in motions().iter().enumerate() {
        builder
            .push(name, "test", motion, 1.0 + i as f64)
            .expect("the clip joins the library");
    }
    builder.finish().expect("the library has clips")
}

/// Prints a comparison's line; returns the failure report, if any.
fn report(
    name: &str,
    rows: usize,
    times: usize,
    layout: TableLayout,
    c: &Comparison,
) -> Option<String> {
    let worst = c.worst.as_ref().map_or(String::new(), |w| {
        format!(
            "worst at t = {} s, {}: gpu {} cpu {:.9} (error {:.2e}, {:.0}% of tolerance)",
            w.time,
            slot_name(&layout, w.slot),
            w.gpu,
            w.cpu,
            w.error,
            100.0 * w.error / w.tolerance
        )
    });
    println!(
        "{name}: {rows} rows, {times} times, {} values, max abs error {:.2e}; {worst}",
        c.values, c.max_abs
    );
    if c.failures.is_empty() {
        return None;
    }
    let mut failures = c.failures.clone();
    failures.sort_by(|a, b| (b.error / b.tolerance).total_cmp(&(a.error / a.tolerance)));
    let lines: Vec<String> = failures
        .iter()
        .take(12)
        .map(|m| {
            format!(
                "  t = {:.9} s ({}): gpu {:.9} cpu {:.9} error {:.3e} > tolerance {:.1e}",
                m.time,
                slot_name(&layout, m.slot),
                m.gpu,
                m.cpu,
                m.error,
                m.tolerance
            )
        })
        .collect();
    Some(format!(
        "{name}: {} of {} values disagree beyond 1e-6 * max(1, |cpu|), the worst:\n{}",
        failures.len(),
        c.values,
        lines.join("\n")
    ))
}

#[test]
fn gpu_lookup_agrees_with_the_cpu_lookup_within_1e6() {
    let gpu = Gpu::open(0).expect("opening GPU 0");
    let kernels = EnvKernels::load(&gpu).expect("loading the env kernels");
    let stream = gpu.stream();
    let mut failures = Vec::new();
    for (seed, (name, table)) in tables().into_iter().enumerate() {
        assert_eq!(table.layout(), HUMANOID_LAYOUT);
        let device_table = DeviceReferenceTable::upload(&gpu, &table).expect("upload");
        let times = lookup_times(table.segment(), 0x5eed + seed as u64);
        let clips = vec![0; times.len()];
        let rows = gpu_rows(&gpu, &kernels, &device_table, &clips, &times);
        let c = compare(
            |i| table.lookup(f64::from(times[i])),
            table.layout(),
            table.quaternion_offsets(),
            &times,
            &rows,
        );
        failures.extend(report(
            &name,
            table.num_rows(),
            times.len(),
            table.layout(),
            &c,
        ));
    }
    stream.synchronize().expect("the lookups ran");
    assert!(
        failures.is_empty(),
        "GPU lookup vs ReferenceTable::lookup:\n{}",
        failures.join("\n")
    );
}

/// The GPU's rows of `clips[i]` at `times[i]` from `table` (waits for them).
fn gpu_rows(
    gpu: &Gpu,
    kernels: &EnvKernels,
    table: &DeviceReferenceTable,
    clips: &[i32],
    times: &[f32],
) -> Vec<f32> {
    let device_clips = DeviceArray::from_slice(gpu, [clips.len()], clips).expect("clips");
    let device_times = DeviceArray::from_slice(gpu, [times.len()], times).expect("times");
    let out: DeviceArray2<f32> =
        DeviceArray::zeros(gpu, [times.len(), table.stride()]).expect("out");
    table
        .lookup(kernels, gpu.stream(), &device_clips, &device_times, &out)
        .expect("launch");
    gpu.stream().synchronize().expect("the lookup kernel ran");
    out.download().expect("download")
}

#[test]
fn gpu_library_lookup_with_a_clip_per_time_agrees_with_the_cpu_within_1e6() {
    let gpu = Gpu::open(0).expect("opening GPU 0");
    let kernels = EnvKernels::load(&gpu).expect("loading the env kernels");
    let library = library();
    let device_table = DeviceReferenceTable::from_library(&gpu, &library).expect("upload");
    assert_eq!(device_table.num_clips(), library.num_clips());
    // Every clip's times, interleaved by a shuffle so that neighbouring threads read
    // different clips.
    let mut lookups: Vec<(i32, f32)> = Vec::new();
    for c in 0..library.num_clips() {
        let segment = library.segment(c).expect("a clip");
        let times = lookup_times(segment, 0xc11b + c as u64);
        lookups.extend(times.into_iter().take(2000).map(|t| (c as i32, t)));
    }
    let mut samples = Samples(0x51ab);
    for i in (1..lookups.len()).rev() {
        let j = (samples.next_u64() % (i as u64 + 1)) as usize;
        lookups.swap(i, j);
    }
    let clips: Vec<i32> = lookups.iter().map(|l| l.0).collect();
    let times: Vec<f32> = lookups.iter().map(|l| l.1).collect();
    let rows = gpu_rows(&gpu, &kernels, &device_table, &clips, &times);
    let c = compare(
        |i| {
            library
                .lookup(clips[i] as usize, f64::from(times[i]))
                .expect("a clip of the library")
        },
        library.layout(),
        library.quaternion_offsets(),
        &times,
        &rows,
    );
    let name = format!(
        "a library of {} clips, a clip per time",
        library.num_clips()
    );
    let failure = report(
        &name,
        library.totals().rows,
        times.len(),
        library.layout(),
        &c,
    );
    assert!(
        failure.is_none(),
        "GPU lookup vs MotionLibrary::lookup:\n{}",
        failure.unwrap_or_default()
    );

    // An id that is no clip of the library reads as NaN, not as another clip.
    let bad = gpu_rows(
        &gpu,
        &kernels,
        &device_table,
        &[-1, library.num_clips() as i32, 1 << 20],
        &[0.1, 0.1, 0.1],
    );
    assert!(
        bad.iter().all(|v| v.is_nan()),
        "a bad clip id gives NaN rows"
    );
}

#[test]
fn the_library_of_one_looks_up_exactly_what_the_single_clip_table_does() {
    let gpu = Gpu::open(0).expect("opening GPU 0");
    let kernels = EnvKernels::load(&gpu).expect("loading the env kernels");
    for (seed, (name, motion)) in motions().into_iter().enumerate() {
        let table = ReferenceTable::build(&motion, CONTROL_DT).expect("table");
        let single = MotionLibrary::single(&name, &name, &motion, CONTROL_DT).expect("library");
        let times = lookup_times(table.segment(), 0x0e1 + seed as u64);
        let clips = vec![0; times.len()];
        let from_table = DeviceReferenceTable::upload(&gpu, &table).expect("upload");
        let from_library = DeviceReferenceTable::from_library(&gpu, &single).expect("upload");
        let a = gpu_rows(&gpu, &kernels, &from_table, &clips, &times);
        let b = gpu_rows(&gpu, &kernels, &from_library, &clips, &times);
        let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert!(
            bits(&a) == bits(&b),
            "{name}: the library of one's rows differ from the table's"
        );
        println!(
            "{name}: the library of one's {} rows are the table's, bit for bit",
            times.len()
        );
    }
}

#[test]
fn a_table_with_fewer_than_two_rows_reads_as_nan_and_empty_launches_do_nothing() {
    let gpu = Gpu::open(0).expect("opening GPU 0");
    let kernels = EnvKernels::load(&gpu).expect("loading the env kernels");
    let stream = gpu.stream();
    let stride = HUMANOID_LAYOUT.stride;
    // A header claiming 3 rows over a buffer that holds one: the kernel must not read past it.
    let mut data = vec![0.5f32; HEADER_LEN + stride];
    data[..HEADER_LEN].copy_from_slice(&[
        3.0,
        1.0 / 30.0,
        2.0 / 30.0,
        1.0,
        0.0,
        0.0,
        0.0,
        stride as f32,
    ]);
    let table = DeviceArray::from_slice(&gpu, [data.len()], &data).unwrap();
    let offsets = DeviceArray::from_slice(&gpu, [1], &[3i32]).unwrap();
    let clip_offsets = DeviceArray::from_slice(&gpu, [1], &[0i32]).unwrap();
    let clips = DeviceArray::from_slice(&gpu, [2], &[0i32, 0]).unwrap();
    let times = DeviceArray::from_slice(&gpu, [2], &[0.0f32, 0.01]).unwrap();
    let out: DeviceArray2<f32> = DeviceArray::zeros(&gpu, [2, stride]).unwrap();
    kernels
        .lookup_reference(
            stream,
            2,
            &table,
            &clip_offsets,
            &offsets,
            &offsets,
            &clips,
            &times,
            &out,
        )
        .unwrap();
    stream.synchronize().unwrap();
    let rows = out.download().unwrap();
    assert!(
        rows.iter().all(|v| v.is_nan()),
        "an unusable table gives NaN rows"
    );

    // dim 0: nothing is launched, the output keeps its values.
    let before = out.download().unwrap();
    kernels
        .lookup_reference(
            stream,
            0,
            &table,
            &clip_offsets,
            &offsets,
            &offsets,
            &clips,
            &times,
            &out,
        )
        .unwrap();
    stream.synchronize().unwrap();
    assert_eq!(
        out.download()
            .unwrap()
            .iter()
            .map(|v| v.to_bits())
            .collect::<Vec<_>>(),
        before.iter().map(|v| v.to_bits()).collect::<Vec<_>>()
    );
}

#[test]
fn the_table_wrapper_refuses_an_output_of_the_wrong_shape() {
    let gpu = Gpu::open(0).expect("opening GPU 0");
    let kernels = EnvKernels::load(&gpu).expect("loading the env kernels");
    let table = synthetic_table(&SyntheticMotion::default());
    let device_table = DeviceReferenceTable::upload(&gpu, &table).unwrap();
    let times = DeviceArray::from_slice(&gpu, [3], &[0.0f32, 0.1, 0.2]).unwrap();
    let clips = DeviceArray::from_slice(&gpu, [3], &[0i32; 3]).unwrap();
    let out: DeviceArray2<f32> = DeviceArray::zeros(&gpu, [3, 100]).unwrap();
    let err = device_table
        .lookup(&kernels, gpu.stream(), &clips, &times, &out)
        .unwrap_err();
    assert!(err.to_string().contains("[3, 282]"), "{err}");
    let two = DeviceArray::from_slice(&gpu, [2], &[0i32; 2]).unwrap();
    let right: DeviceArray2<f32> = DeviceArray::zeros(&gpu, [3, 282]).unwrap();
    let err = device_table
        .lookup(&kernels, gpu.stream(), &two, &times, &right)
        .unwrap_err();
    assert!(err.to_string().contains("one clip id per time"), "{err}");
}
