//! The latent controller on the GPU (docs/latent.md). Run on a machine with an NVIDIA GPU:
//! `cargo test --release --features gpu --test gpu_latent -- --nocapture --test-threads 1`
//!
//! - One distillation update (1 epoch x 1 minibatch, on both GEMM paths): its gradients of the
//!   encoder, the decoder and the prior agree with central finite differences of the float64
//!   host loss (`latent::networks::distillation_loss_f64`) at the parameters it started from,
//!   on the rows and noise it drew; its reported loss equals the host loss.
//! - The update captured into a graph and replayed on a fixed batch whose teacher is a smooth
//!   function of the observation lowers the distillation loss to under half its first value.
//! - A short run through the binary: a library tracker trained for 2 iterations is the teacher
//!   of a latent controller trained for 4, which evaluates every clip, writes finite metrics
//!   and checkpoints, and whose checkpoint loads as a frozen decoder that fits its task.
#![cfg(feature = "gpu")]

mod small_run_support;

use std::sync::Arc;

use instantmimic::cuda::Gpu;
use instantmimic::kernels::{DeviceArray, EnvKernels};
use instantmimic::latent::networks::distillation_loss_f64;
use instantmimic::latent::{
    DistillationBatch, DistillationUpdate, LatentConfig, LatentShapes, LatentStudent,
};
use instantmimic::nn::{GemmSetting, PolicyGemm};
use instantmimic::train::latent_setup::load_frozen_decoder;
use rand::SeedableRng;
use rand::rngs::StdRng;
use rand_distr::{Distribution, StandardNormal};
use small_run_support::{binary, check_success, metrics};

fn gpu() -> (Gpu, Arc<EnvKernels>) {
    let gpu = Gpu::open(0).expect("a GPU");
    let kernels = Arc::new(EnvKernels::load(&gpu).expect("env kernels"));
    (gpu, kernels)
}

fn normal(rng: &mut StdRng, n: usize, scale: f64) -> Vec<f32> {
    (0..n)
        .map(|_| {
            let g: f64 = StandardNormal.sample(rng);
            (g * scale) as f32
        })
        .collect()
}

fn small_config(epochs: u32, minibatches: u32) -> LatentConfig {
    LatentConfig {
        latent_size: 3,
        kl_weight: 0.3,
        encoder_hidden: vec![16],
        decoder_hidden: vec![16, 8],
        prior_hidden: vec![12],
        learning_rate: 1e-3,
        epochs,
        minibatches,
        max_grad_norm: 1.0e6,
        teacher: String::new(),
    }
}

/// The GEMM paths this machine has: Warp tiles, and cuBLAS when libcublas opens.
fn gemm_paths(gpu: &Gpu) -> Vec<PolicyGemm> {
    let mut paths = vec![PolicyGemm::warp_tiles()];
    match PolicyGemm::open(gpu, GemmSetting::Cublas) {
        Ok(cublas) => paths.push(cublas),
        Err(e) => println!("cuBLAS path not checked: {e}"),
    }
    paths
}

fn relative_error(x: &[f64], reference: &[f64]) -> f64 {
    let scale = reference.iter().fold(0.0f64, |m, r| m.max(r.abs()));
    let diff = x
        .iter()
        .zip(reference)
        .fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
    if scale > 0.0 { diff / scale } else { diff }
}

#[test]
fn the_updates_gradients_match_finite_differences_of_the_float64_loss() {
    let (gpu, kernels) = gpu();
    let config = small_config(1, 1);
    let (d, a, t, n) = (10, 4, 2, 24);
    let shapes = LatentShapes::new(&config, d, vec![0, 1, 2, 5, 6], a).expect("shapes");
    for gemm in gemm_paths(&gpu) {
        let mut rng = StdRng::seed_from_u64(7);
        // Output gain 0.5: log sigmas away from 0, so the sample's gradient matters.
        let (e0, d0, p0) = shapes.initial_parameters(1.0, 0.5, 11);
        let student = LatentStudent::new(&gpu, &shapes, (&e0, &d0, &p0), None, gemm.clone(), n, 3)
            .expect("student");
        let update = DistillationUpdate::new(&gpu, kernels.clone(), &student, &config, t, n, 5)
            .expect("update");
        let obs =
            DeviceArray::from_slice(&gpu, [t + 1, n, d], &normal(&mut rng, (t + 1) * n * d, 1.0))
                .expect("observations");
        let teacher = DeviceArray::from_slice(&gpu, [t, n, a], &normal(&mut rng, t * n * a, 0.5))
            .expect("teacher");
        let batch = DistillationBatch {
            observations: &obs,
            teacher: &teacher,
        };
        update.record(gpu.stream(), &batch).expect("recorded");
        gpu.synchronize().expect("ran");
        let stats = update.read_statistics().expect("statistics");
        let (mb_obs, mb_teacher, noise) = update.last_minibatch();
        let (mb_obs, mb_teacher, noise) = (
            mb_obs.download().expect("rows"),
            mb_teacher.download().expect("teacher rows"),
            noise.download().expect("noise"),
        );
        let kl_weight = f64::from(config.kl_weight);
        let loss = |e: &[f32], dp: &[f32], p: &[f32]| {
            distillation_loss_f64(&shapes, (e, dp, p), &mb_obs, &mb_teacher, &noise, kl_weight).0
        };
        let host_loss = loss(&e0, &d0, &p0);
        println!(
            "{gemm:?}: loss GPU {:.6e}, host {host_loss:.6e}",
            stats.loss
        );
        assert!(
            (stats.loss - host_loss).abs() <= 1e-4 * host_loss.abs(),
            "{} vs {host_loss}",
            stats.loss
        );

        let (ge, gd, gp) = update.gradients();
        let grads = [
            ge.download().expect("encoder gradients"),
            gd.download().expect("decoder gradients"),
            gp.download().expect("prior gradients"),
        ];
        let h = 1e-3f32;
        for (net, grad) in grads.iter().enumerate() {
            let len = grad.len();
            let picks: Vec<usize> = (0..40).map(|i| i * len / 40).collect();
            let mut numeric = Vec::new();
            for &i in &picks {
                let mut params = [e0.clone(), d0.clone(), p0.clone()];
                let x = params[net][i];
                params[net][i] = x + h;
                let plus = loss(&params[0], &params[1], &params[2]);
                params[net][i] = x - h;
                let minus = loss(&params[0], &params[1], &params[2]);
                // The step actually taken in f32.
                let step = f64::from(x + h) - f64::from(x - h);
                numeric.push((plus - minus) / step);
            }
            let analytic: Vec<f64> = picks.iter().map(|&i| f64::from(grad[i])).collect();
            let err = relative_error(&analytic, &numeric);
            println!(
                "{gemm:?}: network {net} gradient vs finite differences: relative error {err:.2e}"
            );
            assert!(err <= 2e-3, "network {net}: relative error {err:.3e}");
        }
    }
}

#[test]
fn replays_of_the_captured_update_lower_the_loss_on_a_fixed_batch() {
    let (gpu, kernels) = gpu();
    let config = LatentConfig {
        latent_size: 8,
        encoder_hidden: vec![64, 32],
        decoder_hidden: vec![64, 32],
        prior_hidden: vec![32],
        ..small_config(4, 4)
    };
    let (d, a, t, n) = (20, 6, 4, 256);
    let shapes = LatentShapes::new(&config, d, (0..12).collect(), a).expect("shapes");
    let params = shapes.initial_parameters(std::f64::consts::SQRT_2, 0.01, 2);
    let student = LatentStudent::new(
        &gpu,
        &shapes,
        (&params.0, &params.1, &params.2),
        None,
        PolicyGemm::warp_tiles(),
        n,
        3,
    )
    .expect("student");
    let update =
        DistillationUpdate::new(&gpu, kernels, &student, &config, t, n, 5).expect("update");
    let mut rng = StdRng::seed_from_u64(3);
    let obs_values = normal(&mut rng, (t + 1) * n * d, 1.0);
    // A teacher that is a smooth function of the observation: tanh(obs W).
    let w = normal(&mut rng, d * a, 0.5);
    let teacher_values: Vec<f32> = (0..t * n)
        .flat_map(|r| {
            let row = &obs_values[r * d..][..d];
            (0..a)
                .map(|j| {
                    let z: f32 = row.iter().enumerate().map(|(i, x)| x * w[i * a + j]).sum();
                    z.tanh()
                })
                .collect::<Vec<f32>>()
        })
        .collect();
    let obs = DeviceArray::from_slice(&gpu, [t + 1, n, d], &obs_values).expect("observations");
    let teacher = DeviceArray::from_slice(&gpu, [t, n, a], &teacher_values).expect("teacher");
    let batch = DistillationBatch {
        observations: &obs,
        teacher: &teacher,
    };
    let stream = gpu.stream();
    let graph = stream
        .capture(|s| update.record(s, &batch))
        .expect("captured");
    graph.upload(stream).expect("uploaded");
    let mut first = None;
    let mut last = None;
    for replay in 0..30 {
        graph.launch(stream).expect("launched");
        let stats = update.read_statistics().expect("statistics");
        assert!(stats.loss.is_finite(), "replay {replay}: {stats:?}");
        first.get_or_insert(stats.first_epoch_loss);
        last = Some(stats.loss);
    }
    let (first, last) = (first.expect("ran"), last.expect("ran"));
    println!("distillation loss: first epoch {first:.4e}, after 30 replays {last:.4e}");
    assert!(last < 0.5 * first, "{first} -> {last}");
}

#[test]
fn a_short_distillation_run_evaluates_checkpoints_and_its_decoder_loads() {
    let dir = tempfile::tempdir().expect("temp dir");
    let mut config = small_run_support::small_library_config(&["walk", "punch", "spinkick"]);
    config.run.max_iterations = 2;
    config.run.checkpoint_interval = 2;
    let tracker_toml = dir.path().join("tracker.toml");
    std::fs::write(&tracker_toml, config.to_toml().expect("toml")).expect("write config");
    let tracker_run = dir.path().join("tracker");
    let out = binary()
        .args(["train", "--progress", "lines", "--config"])
        .arg(&tracker_toml)
        .arg("--out")
        .arg(&tracker_run)
        .output()
        .expect("train runs");
    check_success(&out, "train the tracker");
    let teacher = tracker_run.join("checkpoints/iter_00000002.safetensors");
    assert!(teacher.is_file(), "{}", teacher.display());

    config.latent = Some(LatentConfig {
        minibatches: 2,
        epochs: 2,
        ..LatentConfig::default()
    });
    config.run.max_iterations = 4;
    config.validate("test").expect("a latent config");
    let latent_toml = dir.path().join("latent.toml");
    std::fs::write(&latent_toml, config.to_toml().expect("toml")).expect("write config");
    let latent_run = dir.path().join("latent");
    let out = binary()
        .args(["train", "--progress", "lines", "--config"])
        .arg(&latent_toml)
        .arg("--teacher")
        .arg(&teacher)
        .arg("--out")
        .arg(&latent_run)
        .output()
        .expect("train runs");
    check_success(&out, "distill the latent controller");
    let stdout = String::from_utf8_lossy(&out.stdout);
    println!("{stdout}");
    let records = metrics(&latent_run);
    assert_eq!(records.len(), 4);
    for r in &records {
        let loss = r["policy_loss"]
            .as_f64()
            .expect("a finite distillation loss");
        assert!(loss.is_finite() && loss >= 0.0, "{r}");
    }
    let clips = records[1]["evaluation"]["library"]["clips"]
        .as_array()
        .expect("per-clip results");
    assert_eq!(clips.len(), 3);
    assert!(latent_run.join("clips.tsv").is_file());
    let checkpoint = latent_run.join("checkpoints/iter_00000004.safetensors");
    let frozen = load_frozen_decoder(&checkpoint).expect("a latent checkpoint");
    assert_eq!(frozen.latent_size, 64);
    assert_eq!(frozen.action_size, 28);
    let columns = frozen.proprio_columns.clone();
    frozen
        .check_fits(frozen.observation_size, &columns, 28)
        .expect("fits its own task");
    assert!(frozen.decoder.iter().all(|x| x.is_finite()));
    // The tracker's checkpoint is no latent controller.
    assert!(load_frozen_decoder(&teacher).is_err());
}
