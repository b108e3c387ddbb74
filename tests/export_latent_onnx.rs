//! `instantmimic export --format onnx` of a latent controller's and a goal policy's checkpoint,
//! with no GPU (docs/latent.md and docs/goal.md, "ONNX export"): checkpoints written by the
//! modules' own writers from seeded parameters, exported, run in onnxruntime and compared with
//! an f64 forward pass of the checkpoint's parameters (within 1e-5, as tests/export_onnx.rs).
//! A latent goal checkpoint whose decoder file is missing or changed is refused in one line.
//!
//! onnxruntime comes from the build-step Python (`INSTANTMIMIC_BUILD_PYTHON`, set by
//! tests/run.sh); without it the onnxruntime part prints a note.

mod onnx_support;
mod skip_support;

use onnx_support::{export, python};

use std::path::Path;
use std::process::{Command, Output};

use instantmimic::export::onnx::latent::{LATENT_KEY, LatentContract};
use instantmimic::export::onnx::normalizer;
use instantmimic::latent::DECODER_DIGEST;
use instantmimic::latent::checkpoint::insert_latent_networks;
use instantmimic::latent::networks::mlp_forward_f64;
use instantmimic::motion::Character;
use instantmimic::nn::{LayerShape, initial_parameters, mlp_layout};
use instantmimic::ppo::checkpoint::ppo_tensor_names;
use instantmimic::run::checkpoint::tensor_names;
use instantmimic::run::{Checkpoint, CheckpointMeta};
use instantmimic::train::goal_latent::{head_shapes, load_goal_decoder};
use instantmimic::train::latent_setup::latent_shapes;
use instantmimic::train::{ActionMode, PolicyShapes, TrainConfig};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use rand_distr::{Distribution, StandardNormal};
use serde_json::Value;

const COUNT: f64 = 5000.0;

fn repo() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

fn humanoid() -> Character {
    Character::humanoid().expect("humanoid")
}

/// The committed latent controller's configuration with absolute PD targets (what a goal
/// task's decoder needs).
fn latent_config() -> TrainConfig {
    let mut config =
        TrainConfig::load(&repo().join("configs/latent/library.toml")).expect("valid config");
    config.env.action_mode = ActionMode::Absolute;
    config
}

/// Parameters of `layers` with an output gain of 1 and random biases (the trainer starts biases
/// at 0, which would hide a misplaced bias).
fn seeded(layers: &[LayerShape], rng: &mut StdRng) -> Vec<f32> {
    let mut params = initial_parameters(layers, 2f64.sqrt(), 1.0, rng);
    for layer in layers {
        for b in &mut params[layer.bias_offset()..layer.end()] {
            *b = rng.random_range(-0.2..0.2);
        }
    }
    params
}

/// Random observation statistics `[count, mean, m2]` of `d` values.
fn statistics(d: usize, rng: &mut StdRng) -> [Vec<f64>; 3] {
    let mean = (0..d)
        .map(|_| 2.0 * rng.sample::<f64, _>(StandardNormal))
        .collect();
    let m2 = (0..d)
        .map(|_| COUNT * rng.random_range(-5.0f64..1.5).exp())
        .collect();
    [vec![COUNT, COUNT], mean, m2]
}

/// A latent controller's checkpoint at `path` from `seed`; returns its parameters
/// (encoder, decoder, prior) and statistics.
fn write_latent(path: &Path, seed: u64) -> ([Vec<f32>; 3], [Vec<f64>; 3]) {
    let config = latent_config();
    let policy = PolicyShapes::new(&config, &humanoid()).expect("shapes");
    let shapes = latent_shapes(&config, &policy).expect("latent shapes");
    let mut rng = StdRng::seed_from_u64(seed);
    let networks = [
        seeded(&shapes.encoder, &mut rng),
        seeded(&shapes.decoder, &mut rng),
        seeded(&shapes.prior, &mut rng),
    ];
    let stats = statistics(shapes.observation_size, &mut rng);
    let mut c = Checkpoint::new(CheckpointMeta::new(&config, 30, 9.0, 500).expect("meta"));
    insert_latent_networks(&mut c, &shapes, networks.clone(), stats.clone()).expect("inserted");
    c.save(path).expect("saved");
    (networks, stats)
}

fn stderr_last_line(out: &Output) -> String {
    String::from_utf8_lossy(&out.stderr)
        .lines()
        .last()
        .unwrap_or_default()
        .to_string()
}

/// `model` run in onnxruntime on `feeds` (input name -> rows), or None (noted) without it.
fn run_onnx(model: &Path, feeds: &[(&str, &Vec<Vec<f32>>)], dir: &Path) -> Option<Value> {
    let Some(python) = python() else {
        skip_support::skip(
            "INSTANTMIMIC_BUILD_PYTHON is not set (tests/run.sh sets it): onnxruntime not run",
        );
        return None;
    };
    let feeds: serde_json::Map<String, Value> = feeds
        .iter()
        .map(|(k, v)| (k.to_string(), serde_json::json!(v)))
        .collect();
    let feeds_path = dir.join("feeds.json");
    std::fs::write(&feeds_path, Value::Object(feeds).to_string()).expect("write feeds");
    let out = Command::new(python)
        .arg(repo().join("tests/tools/run_onnx_feeds.py"))
        .arg(model)
        .arg(&feeds_path)
        .output()
        .expect("python runs");
    assert!(
        out.status.success(),
        "onnxruntime: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    Some(serde_json::from_slice(&out.stdout).expect("JSON from run_onnx_feeds.py"))
}

/// Observations around the statistics' mean, a few far out (clipped by the graph).
fn random_observations(stats: &[Vec<f64>; 3], rows: usize, rng: &mut StdRng) -> Vec<Vec<f32>> {
    let (mean, m2) = (&stats[1], &stats[2]);
    (0..rows)
        .map(|_| {
            (0..mean.len())
                .map(|i| {
                    let std = (m2[i] / COUNT).sqrt();
                    let g: f64 = StandardNormal.sample(rng);
                    let far = if rng.random_bool(0.02) { 8.0 } else { 1.0 };
                    (mean[i] + far * std * g) as f32
                })
                .collect()
        })
        .collect()
}

/// The observation normalized and clipped as the GPU does, in f64.
fn normalized(stats: &[Vec<f64>; 3], clip: f32, obs: &[f32]) -> Vec<f64> {
    let (mean, inv_std) = normalizer(&stats[0], &stats[1], &stats[2]);
    let clip = f64::from(clip);
    obs.iter()
        .zip(mean.iter().zip(&inv_std))
        .map(|(&o, (m, s))| ((f64::from(o) - m) * s).clamp(-clip, clip))
        .collect()
}

fn columns<T: Copy>(row: &[T], columns: &[i32]) -> Vec<T> {
    columns.iter().map(|&c| row[c as usize]).collect()
}

fn cat(a: &[f64], b: &[f64]) -> Vec<f64> {
    a.iter().chain(b).copied().collect()
}

/// The largest |onnx - f64| of output `name` against `expected` rows, and the largest |f64|.
fn compare(result: &Value, name: &str, expected: &[Vec<f64>]) -> (f64, f64) {
    let (mut worst, mut largest) = (0.0f64, 0.0f64);
    for (r, row) in expected.iter().enumerate() {
        let got = result["outputs"][name][r].as_array().expect("a row");
        assert_eq!(got.len(), row.len(), "{name} row {r}");
        for (g, e) in got.iter().zip(row) {
            worst = worst.max((g.as_f64().expect("a number") - e).abs());
            largest = largest.max(e.abs());
        }
    }
    eprintln!("{name}: max |onnx - f64| = {worst:.2e} over values up to {largest:.2}");
    (worst, largest)
}

fn assert_close(result: &Value, name: &str, expected: &[Vec<f64>]) {
    let (worst, largest) = compare(result, name, expected);
    assert!(largest > 0.1, "{name}: values too small to test: {largest}");
    assert!(
        worst < 1e-5,
        "{name}: onnxruntime differs from f64 by {worst}"
    );
}

#[test]
fn a_latent_controller_exports_as_decoder_and_encoder_models_matching_the_checkpoint() {
    let dir = tempfile::tempdir().expect("temporary directory");
    let checkpoint = dir.path().join("latent.safetensors");
    let ([encoder, decoder, prior], stats) = write_latent(&checkpoint, 17);
    let onnx = dir.path().join("latent.onnx");
    let out = export(&checkpoint, &onnx);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let encoder_onnx = dir.path().join("latent.encoder.onnx");
    assert!(
        encoder_onnx.exists(),
        "the encoder model is written beside it"
    );

    let config = latent_config();
    let policy = PolicyShapes::new(&config, &humanoid()).expect("shapes");
    let shapes = latent_shapes(&config, &policy).expect("latent shapes");
    let sidecar: LatentContract = serde_json::from_str(
        &std::fs::read_to_string(dir.path().join("latent.json")).expect("sidecar"),
    )
    .expect("sidecar JSON");
    assert_eq!(sidecar.proprio_columns, shapes.proprio_columns);
    assert_eq!(sidecar.latent_size, shapes.latent_size);
    assert_eq!(
        (
            sidecar.decoder_model.as_str(),
            sidecar.encoder_model.as_str()
        ),
        ("latent.onnx", "latent.encoder.onnx")
    );
    assert!(
        !sidecar
            .proprio_blocks
            .iter()
            .any(|b| b == "future_end_effectors")
    );
    assert_eq!(sidecar.policy.observation.size, shapes.observation_size);

    let mut rng = StdRng::seed_from_u64(3);
    let rows = random_observations(&stats, 12, &mut rng);
    let l = shapes.latent_size;
    let z: Vec<Vec<f32>> = (0..rows.len())
        .map(|_| {
            (0..l)
                .map(|_| rng.sample::<f32, _>(StandardNormal))
                .collect()
        })
        .collect();
    let proprio_raw: Vec<Vec<f32>> = rows
        .iter()
        .map(|r| columns(r, &shapes.proprio_columns))
        .collect();
    let clip = config.obs.clip;
    let (mut actions, mut prior_mu, mut prior_actions, mut encoder_mu, mut encoder_actions) =
        (vec![], vec![], vec![], vec![], vec![]);
    for (obs, z) in rows.iter().zip(&z) {
        let x = normalized(&stats, clip, obs);
        let p = columns(&x, &shapes.proprio_columns);
        let z: Vec<f64> = z.iter().map(|&v| f64::from(v)).collect();
        actions.push(mlp_forward_f64(&shapes.decoder, &decoder, &cat(&p, &z)));
        let mu = mlp_forward_f64(&shapes.prior, &prior, &p)[..l].to_vec();
        prior_actions.push(mlp_forward_f64(&shapes.decoder, &decoder, &cat(&p, &mu)));
        prior_mu.push(mu);
        let e = mlp_forward_f64(&shapes.encoder, &encoder, &x)[..l].to_vec();
        encoder_actions.push(mlp_forward_f64(&shapes.decoder, &decoder, &cat(&p, &e)));
        encoder_mu.push(e);
    }
    let Some(result) = run_onnx(&onnx, &[("proprio", &proprio_raw), ("z", &z)], dir.path()) else {
        return;
    };
    assert_eq!(
        result["inputs"],
        serde_json::json!([
            ["proprio", ["batch", shapes.proprio_size()]],
            ["z", ["batch", l]]
        ])
    );
    assert_close(&result, "actions", &actions);
    assert_close(&result, "prior_mu", &prior_mu);
    assert_close(&result, "prior_actions", &prior_actions);
    let embedded: LatentContract =
        serde_json::from_str(result["metadata"][LATENT_KEY].as_str().expect("latent key"))
            .expect("contract JSON");
    assert_eq!(embedded, sidecar);

    let result = run_onnx(&encoder_onnx, &[("obs", &rows)], dir.path()).expect("python");
    assert_eq!(
        result["inputs"],
        serde_json::json!([["obs", ["batch", shapes.observation_size]]])
    );
    assert_close(&result, "encoder_mu", &encoder_mu);
    assert_close(&result, "actions", &encoder_actions);
}

/// A goal run's checkpoint of `config` at `path`: the head of `shapes` from `seed`, the
/// critic, `stats`, and the decoder's `digest` when given.
fn write_goal(
    path: &Path,
    config: &TrainConfig,
    shapes: &PolicyShapes,
    stats: &[Vec<f64>; 3],
    digest: Option<[i32; 5]>,
    seed: u64,
) -> Vec<f32> {
    let mut rng = StdRng::seed_from_u64(seed);
    let d = shapes.observation_size;
    let layers = mlp_layout(d, &config.policy.actor_hidden, shapes.action_size);
    let mut actor = seeded(&layers, &mut rng);
    actor.extend(std::iter::repeat_n(-1.0f32, shapes.action_size));
    assert_eq!(actor.len(), shapes.actor_params);
    let mut c = Checkpoint::new(CheckpointMeta::new(config, 8, 2.0, 100).expect("meta"));
    c.insert(ppo_tensor_names::ACTOR, &[actor.len()], actor.clone())
        .expect("actor");
    c.insert(
        ppo_tensor_names::CRITIC,
        &[shapes.critic_params],
        vec![0.0f32; shapes.critic_params],
    )
    .expect("critic");
    for (name, v) in [
        (tensor_names::OBS_COUNT, &stats[0]),
        (tensor_names::OBS_MEAN, &stats[1]),
        (tensor_names::OBS_M2, &stats[2]),
    ] {
        c.insert(name, &[v.len()], v.clone()).expect("statistics");
    }
    if let Some(digest) = digest {
        c.insert(DECODER_DIGEST, &[5], digest.to_vec())
            .expect("digest");
    }
    c.save(path).expect("saved");
    actor
}

#[test]
fn a_latent_goal_policy_exports_as_one_graph_through_the_frozen_decoder() {
    let dir = tempfile::tempdir().expect("temporary directory");
    let latent_path = dir.path().join("latent.safetensors");
    let ([_, decoder, prior], _) = write_latent(&latent_path, 23);
    let mut config =
        TrainConfig::load(&repo().join("configs/goal/reach_latent.toml")).expect("valid config");
    let goal = config.goal.as_mut().expect("[goal]");
    goal.decoder = latent_path.display().to_string();
    goal.latent_action_scale = 0.5;
    let loaded = load_goal_decoder(&config, &humanoid())
        .expect("the decoder fits")
        .expect("a decoder");
    let head = head_shapes(&loaded, &config);
    let mut rng = StdRng::seed_from_u64(5);
    let stats = statistics(head.observation_size, &mut rng);
    let checkpoint = dir.path().join("iter_8.safetensors");
    let actor = write_goal(&checkpoint, &config, &head, &stats, Some(loaded.digest), 29);
    let onnx = dir.path().join("goal.onnx");
    let out = export(&checkpoint, &onnx);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );

    let rows = random_observations(&stats, 12, &mut rng);
    let l = loaded.frozen.latent_size;
    let head_layers = mlp_layout(head.observation_size, &config.policy.actor_hidden, l);
    let frozen = &loaded.frozen;
    let expected: Vec<Vec<f64>> = rows
        .iter()
        .map(|obs| {
            let x = normalized(&stats, config.obs.clip, obs);
            let a = mlp_forward_f64(&head_layers, &actor, &x);
            let p = columns(&x, &loaded.decoding.proprio_columns);
            let mu = mlp_forward_f64(&frozen.prior_layers, &prior, &p);
            let z: Vec<f64> = (0..l).map(|j| mu[j] + 0.5 * a[j]).collect();
            mlp_forward_f64(&frozen.decoder_layers, &decoder, &cat(&p, &z))
        })
        .collect();
    if let Some(result) = run_onnx(&onnx, &[("obs", &rows)], dir.path()) {
        assert_eq!(
            result["inputs"],
            serde_json::json!([["obs", ["batch", head.observation_size]]])
        );
        assert_close(&result, "actions", &expected);
        assert_eq!(
            result["metadata"]["instantmimic.goal.latent_action_scale"],
            "0.5"
        );
    }

    // A changed decoder file (another seed): refused, as eval refuses it.
    write_latent(&latent_path, 24);
    let out = export(&checkpoint, &onnx);
    let err = stderr_last_line(&out);
    assert!(
        !out.status.success()
            && err.contains("iter_8.safetensors: trained with the decoder of")
            && err.contains("(another decoder)"),
        "{err}"
    );
    // A missing decoder file: refused naming it.
    std::fs::remove_file(&latent_path).expect("removed");
    let out = export(&checkpoint, &onnx);
    let err = stderr_last_line(&out);
    assert!(
        !out.status.success() && err.contains("latent.safetensors"),
        "{err}"
    );
}

#[test]
fn a_pd_target_goal_policy_exports_like_a_trackers_actor_with_the_goal_observation() {
    let dir = tempfile::tempdir().expect("temporary directory");
    let config = TrainConfig::load(&repo().join("configs/goal/reach.toml")).expect("valid config");
    let shapes = PolicyShapes::new(&config, &humanoid()).expect("shapes");
    let mut rng = StdRng::seed_from_u64(9);
    let stats = statistics(shapes.observation_size, &mut rng);
    let checkpoint = dir.path().join("iter_8.safetensors");
    let actor = write_goal(&checkpoint, &config, &shapes, &stats, None, 31);
    let onnx = dir.path().join("reach.onnx");
    let out = export(&checkpoint, &onnx);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let sidecar: Value = serde_json::from_str(
        &std::fs::read_to_string(dir.path().join("reach.json")).expect("sidecar"),
    )
    .expect("sidecar JSON");
    let blocks = sidecar["observation"]["blocks"].as_array().expect("blocks");
    let last = blocks.last().expect("a block");
    assert_eq!(last["name"], "goal");
    assert_eq!(
        last["offset"].as_u64().unwrap_or(0) + last["size"].as_u64().unwrap_or(0),
        shapes.observation_size as u64
    );
    assert!(!blocks.iter().any(|b| b["name"] == "future_end_effectors"));

    let layers = mlp_layout(
        shapes.observation_size,
        &config.policy.actor_hidden,
        shapes.action_size,
    );
    let rows = random_observations(&stats, 12, &mut rng);
    let expected: Vec<Vec<f64>> = rows
        .iter()
        .map(|obs| mlp_forward_f64(&layers, &actor, &normalized(&stats, config.obs.clip, obs)))
        .collect();
    if let Some(result) = run_onnx(&onnx, &[("obs", &rows)], dir.path()) {
        assert_close(&result, "actions", &expected);
    }
}
