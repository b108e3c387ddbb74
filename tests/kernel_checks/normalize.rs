//! The running observation normalization (kernels_py/env/observe.py: `observation_moments`,
//! `observation_moments_merge`, `observation_normalize`; docs/env.md, "Observation").
//!
//! References: batch sums in f64; several batches in sequence (moments, merge, the rollout's
//! copy of the merged count) against a two-pass f64 mean and variance over all rows; a merge
//! onto existing statistics against the two-pass moments of both data sets together; and
//! `clip((x - mean) / sqrt(var + 1e-8), -clip, clip)` with and without statistics.

use instantmimic::kernels::{
    OBSERVATION_MOMENTS, OBSERVATION_MOMENTS_MERGE, OBSERVATION_NORMALIZE,
};

use super::compare::{Report, wide};
use super::program::{Arg, Program, Scalar};
use super::rng::Sampler;
use super::{Check, Fixture, nan_f32};

/// Envs summed by one thread of `observation_moments` (observe.py `MOMENT_CHUNK`).
const MOMENT_CHUNK: usize = 64;
const VARIANCE_EPSILON: f64 = 1e-8;
/// Rows of the rollout storage in the cases, and the row written.
const STORAGE_ROWS: usize = 4;
const ROW: usize = 2;

/// Observation-like columns: per-column offsets and scales over several orders of magnitude,
/// some constant columns, and a few outliers far in the tails (clipped when normalized).
struct Columns {
    mean: Vec<f64>,
    scale: Vec<f64>,
}

impl Columns {
    fn new(dims: usize, rng: &mut Sampler) -> Columns {
        let mean = (0..dims).map(|_| rng.uniform(-5.0, 5.0)).collect();
        let scale = (0..dims)
            .map(|d| {
                if d % 29 == 3 {
                    0.0
                } else {
                    10f64.powf(rng.uniform(-2.0, 1.0))
                }
            })
            .collect();
        Columns { mean, scale }
    }

    fn rows(&self, n: usize, rng: &mut Sampler) -> Vec<f32> {
        let dims = self.mean.len();
        (0..n * dims)
            .map(|i| {
                let d = i % dims;
                let g = if rng.chance(0.01) {
                    9.0 * rng.normal().signum()
                } else {
                    rng.normal()
                };
                (self.mean[d] + self.scale[d] * g) as f32
            })
            .collect()
    }
}

/// Two-pass f64 mean and (population) variance per column of row-major `[.., dims]` data.
pub fn two_pass(batches: &[&[f32]], dims: usize) -> (Vec<f64>, Vec<f64>, f64) {
    let mut sum = vec![0.0; dims];
    let mut count = 0.0;
    for b in batches {
        for row in b.chunks_exact(dims) {
            for (s, &x) in sum.iter_mut().zip(row) {
                *s += f64::from(x);
            }
            count += 1.0;
        }
    }
    let mean: Vec<f64> = sum.iter().map(|s| s / count).collect();
    let mut var = vec![0.0; dims];
    for b in batches {
        for row in b.chunks_exact(dims) {
            for d in 0..dims {
                var[d] += (f64::from(row[d]) - mean[d]).powi(2);
            }
        }
    }
    (mean, var.iter().map(|v| v / count).collect(), count)
}

/// The normalized values of `obs` under mean and variance (None: no statistics yet).
pub fn normalized(
    obs: &[f32],
    dims: usize,
    stats: Option<(&[f64], &[f64])>,
    clip: f32,
) -> Vec<f64> {
    let clip = f64::from(clip);
    obs.iter()
        .enumerate()
        .map(|(i, &x)| {
            let d = i % dims;
            let (mu, var) = stats.map_or((0.0, 1.0), |(m, v)| (m[d], v[d]));
            ((f64::from(x) - mu) / (var + VARIANCE_EPSILON).sqrt()).clamp(-clip, clip)
        })
        .collect()
}

/// The largest relative error of a single column (columns with a non-zero reference): the
/// small-variance columns next to large means, where a sum-of-squares formula cancels.
fn worst_column(r: &mut Report, label: &str, got: &[f64], expected: &[f64]) {
    let worst = got
        .iter()
        .zip(expected)
        .filter(|(_, e)| **e != 0.0)
        .map(|(g, e)| ((g - e) / e).abs())
        .fold(0.0, f64::max);
    r.check(
        worst <= super::compare::TOLERANCE,
        format!("{label}: relative error {worst:.2e}"),
    );
}

/// Records the normalization launch of `obs` into `normalized` and storage row [`ROW`].
fn push_normalize(p: &mut Program, obs: &str, n: usize, dims: usize, clip: f32) {
    let args = vec![
        Arg::Buffer(obs.to_owned()),
        Arg::Buffer("count".to_owned()),
        Arg::Buffer("mean".to_owned()),
        Arg::Buffer("m2".to_owned()),
        Arg::Scalar(Scalar::F32(clip)),
        Arg::Scalar(Scalar::I32(ROW as i32)),
        p.f32("normalized", &[n, dims], nan_f32(n * dims)),
        p.f32(
            "storage",
            &[STORAGE_ROWS, n, dims],
            nan_f32(STORAGE_ROWS * n * dims),
        ),
    ];
    p.launch(&OBSERVATION_NORMALIZE, n * dims, args);
}

/// Checks the normalized output and storage rows of `obs` against `expected`.
fn check_normalized(
    r: &mut Report,
    p: &Program,
    out: &super::program::Outputs,
    n: usize,
    dims: usize,
    expected: &[f64],
    clip: f32,
) {
    r.relative("normalized", &wide(out.f32("normalized")), expected);
    let storage = out.f32("storage");
    r.relative(
        "storage (row written)",
        &wide(&storage[ROW * n * dims..(ROW + 1) * n * dims]),
        expected,
    );
    let mut others = storage.to_vec();
    others.drain(ROW * n * dims..(ROW + 1) * n * dims);
    let mut poison = p.input_f32("storage").to_vec();
    poison.drain(ROW * n * dims..(ROW + 1) * n * dims);
    r.bitwise_f32("storage (other rows)", &others, &poison);
    let c = f64::from(clip);
    let (low, high) = (
        expected.iter().filter(|&&x| x == -c).count(),
        expected.iter().filter(|&&x| x == c).count(),
    );
    r.check(
        low > 0 && high > 0,
        format!("coverage: {low} values clipped at -{clip}, {high} at +{clip}"),
    );
}

/// Batches in sequence, then the normalization of the last one.
fn sequence_case(dims: usize, batch_sizes: &[usize], clip: f32, seed: u64) -> Check {
    let mut rng = Sampler::new(seed);
    let columns = Columns::new(dims, &mut rng);
    let batches: Vec<Vec<f32>> = batch_sizes
        .iter()
        .map(|&n| columns.rows(n, &mut rng))
        .collect();
    let mut p = Program::new(format!(
        "observation_moments + merge x {}, then normalize: {dims} dims, batches of {batch_sizes:?} rows, clip {clip}",
        batch_sizes.len()
    ));
    p.f64("batch_sum", &[dims], vec![0.0; dims]);
    p.f64("batch_sum_sq", &[dims], vec![0.0; dims]);
    p.f64("count", &[2], vec![0.0; 2]);
    p.f64("mean", &[dims], vec![0.0; dims]);
    p.f64("m2", &[dims], vec![0.0; dims]);
    for (b, (rows, &n)) in batches.iter().zip(batch_sizes).enumerate() {
        let obs = p.f32(&format!("obs_{b}"), &[n, dims], rows.clone());
        let sums = || {
            vec![
                Arg::Buffer("batch_sum".into()),
                Arg::Buffer("batch_sum_sq".into()),
            ]
        };
        let mut args = vec![obs];
        args.extend(sums());
        p.launch(&OBSERVATION_MOMENTS, n.div_ceil(MOMENT_CHUNK) * dims, args);
        let mut args = vec![Arg::Scalar(Scalar::F64(n as f64))];
        args.extend(sums());
        args.extend(["count", "mean", "m2"].map(|s| Arg::Buffer(s.to_owned())));
        p.launch(&OBSERVATION_MOMENTS_MERGE, dims, args);
        // The rollout's memcpy: the merged count becomes the running count.
        p.copy("count", 1, "count", 0, 1);
    }
    let last = batch_sizes.len() - 1;
    push_normalize(
        &mut p,
        &format!("obs_{last}"),
        batch_sizes[last],
        dims,
        clip,
    );

    let sizes = batch_sizes.to_vec();
    Check::new(p, move |p, out| {
        let mut r = Report::new(&p.name);
        let slices: Vec<&[f32]> = batches.iter().map(Vec::as_slice).collect();
        let (mean, var, count) = two_pass(&slices, dims);
        r.check(
            out.f64("count") == [count, count],
            format!("count {:?} = [{count}, {count}]", out.f64("count")),
        );
        r.relative("mean (after all batches)", out.f64("mean"), &mean);
        let got_var: Vec<f64> = out.f64("m2").iter().map(|m| m / count).collect();
        r.relative("variance (m2 / count)", &got_var, &var);
        worst_column(&mut r, "variance, worst column", &got_var, &var);
        r.check(
            out.f64("batch_sum")
                .iter()
                .chain(out.f64("batch_sum_sq"))
                .all(|&x| x == 0.0),
            "batch sums cleared by the merge",
        );
        // The kernel normalizes with the statistics it holds; compare with those (its contract)
        // and with the two-pass ones.
        let kernel_var: Vec<f64> = out
            .f64("m2")
            .iter()
            .map(|m| m / out.f64("count")[1])
            .collect();
        let n = sizes[sizes.len() - 1];
        let obs = &batches[batches.len() - 1];
        let expected = normalized(obs, dims, Some((out.f64("mean"), &kernel_var)), clip);
        check_normalized(&mut r, p, out, n, dims, &expected, clip);
        let two_pass_expected = normalized(obs, dims, Some((&mean, &var)), clip);
        r.relative(
            "normalized (two-pass statistics)",
            &wide(out.f32("normalized")),
            &two_pass_expected,
        );
        r
    })
}

/// One moments launch onto non-zero sums (the kernel adds), then one merge onto existing
/// statistics (those of `prior_rows` earlier rows).
fn merge_case(dims: usize, prior_rows: usize, n: usize, seed: u64) -> Check {
    let mut rng = Sampler::new(seed);
    let columns = Columns::new(dims, &mut rng);
    let prior = columns.rows(prior_rows, &mut rng);
    let batch = columns.rows(n, &mut rng);
    let (prior_mean, prior_var, prior_count) = two_pass(&[&prior], dims);
    let prior_m2: Vec<f64> = prior_var.iter().map(|v| v * prior_count).collect();
    let offsets: Vec<f64> = (0..dims).map(|_| rng.uniform(-100.0, 100.0)).collect();
    let offsets_sq: Vec<f64> = (0..dims).map(|_| rng.uniform(0.0, 1000.0)).collect();

    let mut p = Program::new(format!(
        "observation_moments onto non-zero sums, then merge onto {prior_rows} earlier rows: {dims} dims, {n} rows"
    ));
    let args = vec![
        p.f32("obs", &[n, dims], batch.clone()),
        p.f64("moment_sum", &[dims], offsets.clone()),
        p.f64("moment_sum_sq", &[dims], offsets_sq.clone()),
    ];
    p.launch(&OBSERVATION_MOMENTS, n.div_ceil(MOMENT_CHUNK) * dims, args);
    // The merge reads sums of exactly this batch (a separate pair of buffers).
    let sum = |k: usize| {
        batch
            .chunks_exact(dims)
            .map(|r| f64::from(r[k]))
            .sum::<f64>()
    };
    let sum_sq = |k: usize| {
        batch
            .chunks_exact(dims)
            .map(|r| f64::from(r[k]).powi(2))
            .sum::<f64>()
    };
    let sums: Vec<f64> = (0..dims).map(sum).collect();
    let sums_sq: Vec<f64> = (0..dims).map(sum_sq).collect();
    let args = vec![
        Arg::Scalar(Scalar::F64(n as f64)),
        p.f64("batch_sum", &[dims], sums.clone()),
        p.f64("batch_sum_sq", &[dims], sums_sq.clone()),
        p.f64("count", &[2], vec![prior_count, -1.0]),
        p.f64("mean", &[dims], prior_mean),
        p.f64("m2", &[dims], prior_m2),
    ];
    p.launch(&OBSERVATION_MOMENTS_MERGE, dims, args);
    Check::new(p, move |p, out| {
        let mut r = Report::new(&p.name);
        let plus = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x + y).collect::<Vec<_>>();
        r.relative(
            "batch_sum (added)",
            out.f64("moment_sum"),
            &plus(&offsets, &sums),
        );
        r.relative(
            "batch_sum_sq (added)",
            out.f64("moment_sum_sq"),
            &plus(&offsets_sq, &sums_sq),
        );
        let (mean, var, count) = two_pass(&[&prior, &batch], dims);
        r.check(
            out.f64("count") == [prior_count, count],
            format!("count {:?} = [{prior_count}, {count}]", out.f64("count")),
        );
        r.relative("mean (merged)", out.f64("mean"), &mean);
        let got_var: Vec<f64> = out.f64("m2").iter().map(|m| m / count).collect();
        r.relative("variance (merged)", &got_var, &var);
        worst_column(&mut r, "variance (merged), worst column", &got_var, &var);
        r.check(
            out.f64("batch_sum")
                .iter()
                .chain(out.f64("batch_sum_sq"))
                .all(|&x| x == 0.0),
            "batch sums cleared by the merge",
        );
        r
    })
}

/// Normalization before any statistics: count[1] = 0 means mean 0, variance 1 (whatever the
/// other buffers hold).
fn no_statistics_case(n: usize, dims: usize, clip: f32, seed: u64) -> Check {
    let mut rng = Sampler::new(seed);
    let obs: Vec<f32> = (0..n * dims)
        .map(|_| (2.0 * clip as f64 * rng.normal()) as f32)
        .collect();
    let mut p = Program::new(format!(
        "observation_normalize without statistics: {n} x {dims}, clip {clip}"
    ));
    p.f32("obs", &[n, dims], obs.clone());
    p.f64("count", &[2], vec![123.0, 0.0]);
    p.f64(
        "mean",
        &[dims],
        (0..dims).map(|_| rng.uniform(-9.0, 9.0)).collect(),
    );
    p.f64(
        "m2",
        &[dims],
        (0..dims).map(|_| rng.uniform(0.0, 9.0)).collect(),
    );
    push_normalize(&mut p, "obs", n, dims, clip);
    Check::new(p, move |p, out| {
        let mut r = Report::new(&p.name);
        let expected = normalized(&obs, dims, None, clip);
        check_normalized(&mut r, p, out, n, dims, &expected, clip);
        r
    })
}

/// Replicas on several GPUs (src/env/normalizer.rs): every step, each replica's moments of
/// its own batch are summed over the replicas (NCCL's all-reduce; here every replica's
/// `observation_moments` adds into one pair of sums, which is the same sum) and merged once
/// with the count of every replica's rows. Against the two-pass statistics of every
/// replica's rows of every step together: the statistics one GPU with all the envs would hold.
fn replicas_case(dims: usize, replicas: usize, n: usize, steps: usize, seed: u64) -> Check {
    let mut rng = Sampler::new(seed);
    let columns = Columns::new(dims, &mut rng);
    // Each replica draws from its own shifted columns: the replicas see different data.
    let batches: Vec<Vec<Vec<f32>>> = (0..steps)
        .map(|_| {
            (0..replicas)
                .map(|r| {
                    columns
                        .rows(n, &mut rng)
                        .into_iter()
                        .map(|x| x + 0.5 * r as f32)
                        .collect()
                })
                .collect()
        })
        .collect();
    let mut p = Program::new(format!(
        "{replicas} replicas x {steps} steps of {n} rows: moments summed over the replicas, one merge of {} rows per step ({dims} dims)",
        n * replicas
    ));
    p.f64("batch_sum", &[dims], vec![0.0; dims]);
    p.f64("batch_sum_sq", &[dims], vec![0.0; dims]);
    p.f64("count", &[2], vec![0.0; 2]);
    p.f64("mean", &[dims], vec![0.0; dims]);
    p.f64("m2", &[dims], vec![0.0; dims]);
    for (step, rows) in batches.iter().enumerate() {
        for (replica, batch) in rows.iter().enumerate() {
            let obs = p.f32(&format!("obs_{step}_{replica}"), &[n, dims], batch.clone());
            let args = vec![
                obs,
                Arg::Buffer("batch_sum".into()),
                Arg::Buffer("batch_sum_sq".into()),
            ];
            p.launch(&OBSERVATION_MOMENTS, n.div_ceil(MOMENT_CHUNK) * dims, args);
        }
        let mut args = vec![Arg::Scalar(Scalar::F64((n * replicas) as f64))];
        args.extend(
            ["batch_sum", "batch_sum_sq", "count", "mean", "m2"].map(|s| Arg::Buffer(s.into())),
        );
        p.launch(&OBSERVATION_MOMENTS_MERGE, dims, args);
        p.copy("count", 1, "count", 0, 1);
    }
    Check::new(p, move |p, out| {
        let mut r = Report::new(&p.name);
        let all: Vec<&[f32]> = batches.iter().flatten().map(Vec::as_slice).collect();
        let (mean, var, count) = two_pass(&all, dims);
        r.check(
            out.f64("count") == [count, count],
            format!("count {:?} = [{count}, {count}]", out.f64("count")),
        );
        r.relative("mean (every replica's rows)", out.f64("mean"), &mean);
        let got_var: Vec<f64> = out.f64("m2").iter().map(|m| m / count).collect();
        r.relative("variance (every replica's rows)", &got_var, &var);
        worst_column(&mut r, "variance, worst column", &got_var, &var);
        r
    })
}

pub fn moments_checks(_fx: &Fixture) -> Vec<Check> {
    vec![
        sequence_case(353, &[100, 257, 64, 1, 130], 5.0, 61),
        sequence_case(45, &[64, 64], 3.0, 62),
        merge_case(362, 5000, 200, 63),
        merge_case(7, 1, 65, 64),
        replicas_case(353, 4, 96, 3, 68),
        replicas_case(20, 2, 64, 5, 69),
    ]
}

pub fn normalize_checks(_fx: &Fixture) -> Vec<Check> {
    vec![
        no_statistics_case(70, 353, 5.0, 65),
        no_statistics_case(3, 11, 0.5, 66),
        sequence_case(90, &[33], 2.0, 67),
    ]
}
