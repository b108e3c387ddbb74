//! `instantmimic export --checkpoint <file> --format onnx`, with no GPU: a checkpoint made here
//! from a seeded initialization through the checkpoint writer, exported, decoded, and run in
//! onnxruntime on random observations against an f64 forward of the checkpoint (within 1e-5);
//! the contract in `metadata_props` equals the JSON sidecar. A checkpoint of another shape fails
//! with one line.
//!
//! onnxruntime comes from the build-step Python (`kernels_py/requirements.txt`, set up by
//! tests/run.sh as `INSTANTMIMIC_BUILD_PYTHON`); without it that part prints a note.

mod onnx_support;
mod skip_support;

use onnx_support::{export, path_str, python, run};

use std::path::Path;
use std::process::Command;

use instantmimic::export::onnx::contract::{CONTRACT_KEY, PolicyContract};
use instantmimic::export::onnx::proto::{DimensionValue, FLOAT, ModelProto};
use instantmimic::export::onnx::{IR_VERSION, OPSET, actor_layers, normalizer};
use instantmimic::motion::Character;
use instantmimic::nn::initial_parameters;
use instantmimic::ppo::checkpoint::ppo_tensor_names;
use instantmimic::run::checkpoint::tensor_names;
use instantmimic::run::{Checkpoint, CheckpointMeta};
use instantmimic::train::{PolicyShapes, TrainConfig};
use prost::Message as _;
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use rand_distr::{Distribution, StandardNormal};
use serde_json::Value;

fn humanoid() -> Character {
    Character::humanoid().expect("humanoid")
}

/// The backflip's committed configuration (root target on, action scale 0.875).
fn config() -> TrainConfig {
    let (_, config) = TrainConfig::committed("backflip").expect("a committed config");
    config.expect("valid config")
}

/// A checkpoint of `config`'s policy from a seeded initialization: the trainer's initializer
/// with an output gain of 1 (so that actions are O(1) and an error shows), random biases (the
/// trainer starts them at 0, which would hide a misplaced bias) and random normalizer moments.
fn seeded_checkpoint(config: &TrainConfig, seed: u64) -> Checkpoint {
    let character = Character::find(&config.character).expect("the configuration's character");
    let shapes = PolicyShapes::new(config, &character).expect("shapes");
    let mut rng = StdRng::seed_from_u64(seed);
    let layers = actor_layers(config, &shapes);
    let mut actor = initial_parameters(&layers, 2f64.sqrt(), 1.0, &mut rng);
    for layer in &layers {
        for b in &mut actor[layer.bias_offset()..layer.end()] {
            *b = rng.random_range(-0.2..0.2);
        }
    }
    actor.extend(std::iter::repeat_n(-1.5f32, shapes.action_size));
    let critic_layers =
        instantmimic::nn::mlp_layout(shapes.observation_size, &config.policy.critic_hidden, 1);
    let critic = initial_parameters(&critic_layers, 2f64.sqrt(), 1.0, &mut rng);
    let d = shapes.observation_size;
    let count = 5000.0;
    let mean: Vec<f64> = (0..d)
        .map(|_| 2.0 * rng.sample::<f64, _>(StandardNormal))
        .collect();
    let m2: Vec<f64> = (0..d)
        .map(|_| count * (rng.random_range(-5.0f64..1.5)).exp())
        .collect();
    let meta = CheckpointMeta::new(config, 42, 3.5, 1_000_000).expect("meta");
    let mut checkpoint = Checkpoint::new(meta);
    checkpoint
        .insert(ppo_tensor_names::ACTOR, &[actor.len()], actor)
        .expect("actor");
    checkpoint
        .insert(ppo_tensor_names::CRITIC, &[critic.len()], critic)
        .expect("critic");
    checkpoint
        .insert(tensor_names::OBS_COUNT, &[2], vec![count, count])
        .expect("count");
    checkpoint
        .insert(tensor_names::OBS_MEAN, &[d], mean)
        .expect("mean");
    checkpoint
        .insert(tensor_names::OBS_M2, &[d], m2)
        .expect("m2");
    checkpoint
}

/// The f64 forward of the checkpoint's actor: the normalizer as the GPU applies it, then the
/// MLP with ELU between layers.
fn forward_f64(checkpoint: &Checkpoint, config: &TrainConfig, obs: &[f32]) -> Vec<f64> {
    let character = Character::find(&config.character).expect("the configuration's character");
    let shapes = PolicyShapes::new(config, &character).expect("shapes");
    let d = shapes.observation_size;
    let get = |name: &str, n: usize| checkpoint.get::<f64>(name, &[n]).expect("tensor").to_vec();
    let (mean, inv_std) = normalizer(
        &get(tensor_names::OBS_COUNT, 2),
        &get(tensor_names::OBS_MEAN, d),
        &get(tensor_names::OBS_M2, d),
    );
    let clip = f64::from(config.obs.clip);
    let mut x: Vec<f64> = obs
        .iter()
        .zip(mean.iter().zip(&inv_std))
        .map(|(&o, (m, s))| ((f64::from(o) - m) * s).clamp(-clip, clip))
        .collect();
    let params = checkpoint
        .get::<f32>(ppo_tensor_names::ACTOR, &[shapes.actor_params])
        .expect("actor");
    let layers = actor_layers(config, &shapes);
    for (l, layer) in layers.iter().enumerate() {
        let mut y: Vec<f64> = params[layer.bias_offset()..layer.end()]
            .iter()
            .map(|&b| f64::from(b))
            .collect();
        for (i, xi) in x.iter().enumerate() {
            let row = &params[layer.offset + i * layer.outputs..][..layer.outputs];
            for (yj, &w) in y.iter_mut().zip(row) {
                *yj += xi * f64::from(w);
            }
        }
        if l + 1 < layers.len() {
            y.iter_mut()
                .for_each(|v| *v = if *v > 0.0 { *v } else { v.exp() - 1.0 });
        }
        x = y;
    }
    x
}

/// Observations around the normalizer's mean, a few far out (clipped by the graph).
fn random_observations(checkpoint: &Checkpoint, rows: usize, seed: u64) -> Vec<Vec<f32>> {
    let mean = checkpoint.tensor(tensor_names::OBS_MEAN).expect("mean");
    let d = mean.shape[0];
    let mean = checkpoint
        .get::<f64>(tensor_names::OBS_MEAN, &[d])
        .expect("mean");
    let m2 = checkpoint
        .get::<f64>(tensor_names::OBS_M2, &[d])
        .expect("m2");
    let mut rng = StdRng::seed_from_u64(seed);
    (0..rows)
        .map(|_| {
            (0..d)
                .map(|i| {
                    let std = (m2[i] / 5000.0).sqrt();
                    let g: f64 = StandardNormal.sample(&mut rng);
                    let far = if rng.random_bool(0.02) { 8.0 } else { 1.0 };
                    (mean[i] + far * std * g) as f32
                })
                .collect()
        })
        .collect()
}

/// `onnx` run by onnxruntime (tests/tools/run_onnx.py) on `rows`: its JSON report.
fn run_onnxruntime(python: &Path, onnx: &Path, rows: &[Vec<f32>], dir: &Path) -> Value {
    let rows_path = dir.join("obs.json");
    std::fs::write(&rows_path, serde_json::to_string(rows).expect("json")).expect("write");
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/tools/run_onnx.py");
    let out = Command::new(python)
        .arg(script)
        .arg(onnx)
        .arg(&rows_path)
        .output()
        .expect("python runs");
    assert!(
        out.status.success(),
        "onnxruntime: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).expect("JSON from run_onnx.py")
}

#[test]
fn the_onnx_policy_matches_the_checkpoint_and_carries_its_contract() {
    let dir = tempfile::tempdir().expect("temporary directory");
    let config = config();
    let checkpoint = seeded_checkpoint(&config, 7);
    let checkpoint_path = dir.path().join("iter_00000042.safetensors");
    checkpoint
        .save(&checkpoint_path)
        .expect("the checkpoint writer");
    let onnx = dir.path().join("policy.onnx");
    let out = export(&checkpoint_path, &onnx);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let shapes = PolicyShapes::new(&config, &humanoid()).expect("shapes");
    assert_eq!(
        shapes.observation_size, 362,
        "the backflip's observation has the root target"
    );

    // The model as written.
    let model =
        ModelProto::decode(std::fs::read(&onnx).expect("onnx").as_slice()).expect("protobuf");
    assert_eq!(
        (model.ir_version, model.opset_import[0].version),
        (IR_VERSION, OPSET)
    );
    let graph = model.graph.as_ref().expect("graph");
    let input = &graph.input[0];
    let dims = &input
        .r#type
        .as_ref()
        .and_then(|t| t.tensor_type.as_ref())
        .and_then(|t| t.shape.as_ref())
        .expect("shape")
        .dim;
    assert_eq!(
        dims[0].value,
        Some(DimensionValue::DimParam("batch".into()))
    );
    assert_eq!(dims[1].value, Some(DimensionValue::DimValue(362)));
    assert!(graph.initializer.iter().all(|t| t.data_type == FLOAT));
    let ops: Vec<&str> = graph.node.iter().map(|n| n.op_type.as_str()).collect();
    assert_eq!(
        ops,
        [
            "Sub", "Mul", "Clip", "Gemm", "Elu", "Gemm", "Elu", "Gemm", "Elu", "Gemm"
        ]
    );

    // The contract: metadata and sidecar agree, and say what the configuration says.
    let meta: std::collections::HashMap<&str, &str> = model
        .metadata_props
        .iter()
        .map(|e| (e.key.as_str(), e.value.as_str()))
        .collect();
    let sidecar: PolicyContract = serde_json::from_str(
        &std::fs::read_to_string(dir.path().join("policy.json")).expect("sidecar"),
    )
    .expect("sidecar JSON");
    let embedded: PolicyContract = serde_json::from_str(meta[CONTRACT_KEY]).expect("contract");
    assert_eq!(embedded, sidecar);
    assert_eq!(sidecar.motion, "backflip");
    assert_eq!(
        (sidecar.action.mode.as_str(), sidecar.action.scale),
        ("residual", 0.875)
    );
    assert!(
        (sidecar.control_dt - 1.0 / 30.0).abs() < 1e-12
            && (sidecar.physics_dt - 1.0 / 120.0).abs() < 1e-12
    );
    let chest = &sidecar.joints[0];
    assert_eq!(
        (chest.name.as_str(), chest.kp, chest.kd, chest.actions),
        ("chest", 1000.0, 100.0, 3)
    );
    let blocks = &sidecar.observation.blocks;
    assert_eq!(
        blocks.last().map(|b| (b.name.as_str(), b.offset + b.size)),
        Some(("root_target", 362))
    );
    assert_eq!(meta["instantmimic.action_mode"], "residual");
    assert_eq!(meta["instantmimic.format_version"], "1");
    let joint_names: Vec<String> =
        serde_json::from_str(meta["instantmimic.joint_names"]).expect("names");
    assert_eq!(joint_names.len(), 12);

    // onnxruntime against the f64 forward.
    let Some(python) = python() else {
        skip_support::skip(
            "INSTANTMIMIC_BUILD_PYTHON is not set (tests/run.sh sets it): onnxruntime not run",
        );
        return;
    };
    let rows = random_observations(&checkpoint, 16, 11);
    let result = run_onnxruntime(&python, &onnx, &rows, dir.path());
    assert_eq!(
        result["input"],
        serde_json::json!(["obs", ["batch", 362], "tensor(float)"])
    );
    assert_eq!(
        result["output"],
        serde_json::json!(["actions", ["batch", 28], "tensor(float)"])
    );
    let mut worst = 0.0f64;
    let mut largest = 0.0f64;
    for (r, obs) in rows.iter().enumerate() {
        let expected = forward_f64(&checkpoint, &config, obs);
        for (a, e) in expected.iter().enumerate() {
            let got = result["actions"][r][a].as_f64().expect("a number");
            worst = worst.max((got - e).abs());
            largest = largest.max(e.abs());
        }
    }
    eprintln!(
        "onnxruntime {}: max |onnx - f64| = {worst:.2e} over actions up to {largest:.2}",
        result["onnxruntime"]
    );
    assert!(largest > 0.5, "actions too small to test: {largest}");
    assert!(
        worst < 1e-5,
        "onnxruntime differs from the f64 forward by {worst}"
    );
    assert_eq!(result["first_row"][0], result["actions"][0]);
    let ort_meta = result["metadata"].as_object().expect("metadata");
    for (key, value) in &meta {
        assert_eq!(
            ort_meta.get(*key).and_then(Value::as_str),
            Some(*value),
            "{key}"
        );
    }
}

/// The G1's default configuration, as `train --character g1` takes it.
fn g1_config() -> TrainConfig {
    let (_, config) = TrainConfig::character_default("g1", "clip.npz").expect("the G1's default");
    config.expect("valid config")
}

#[test]
fn a_g1_policy_exports_with_the_g1s_contract_and_matches_the_checkpoint() {
    let dir = tempfile::tempdir().expect("temporary directory");
    let config = g1_config();
    let character = Character::find("g1").expect("the G1");
    let checkpoint = seeded_checkpoint(&config, 5);
    let checkpoint_path = dir.path().join("iter_00000042.safetensors");
    checkpoint
        .save(&checkpoint_path)
        .expect("the checkpoint writer");
    let onnx = dir.path().join("policy.onnx");
    let out = export(&checkpoint_path, &onnx);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let shapes = PolicyShapes::new(&config, &character).expect("shapes");
    let sidecar: PolicyContract = serde_json::from_str(
        &std::fs::read_to_string(dir.path().join("policy.json")).expect("sidecar"),
    )
    .expect("sidecar JSON");
    // The contract states the robot's joints with the description's gains, one action each.
    assert_eq!(sidecar.joints.len(), character.control().len());
    for (joint, control) in sidecar.joints.iter().zip(character.control()) {
        assert_eq!(joint.name, character.joints()[control.joint].name);
        assert_eq!(
            (joint.kp, joint.kd, joint.actions),
            (control.kp, control.kd, 1)
        );
    }
    assert!(
        (sidecar.control_dt - 0.02).abs() < 1e-12 && (sidecar.physics_dt - 0.005).abs() < 1e-12
    );
    let Some(python) = python() else {
        skip_support::skip(
            "INSTANTMIMIC_BUILD_PYTHON is not set (tests/run.sh sets it): onnxruntime not run",
        );
        return;
    };
    let rows = random_observations(&checkpoint, 16, 13);
    let result = run_onnxruntime(&python, &onnx, &rows, dir.path());
    assert_eq!(
        result["output"],
        serde_json::json!(["actions", ["batch", shapes.action_size], "tensor(float)"])
    );
    let mut worst = 0.0f64;
    for (r, obs) in rows.iter().enumerate() {
        for (a, e) in forward_f64(&checkpoint, &config, obs).iter().enumerate() {
            let got = result["actions"][r][a].as_f64().expect("a number");
            worst = worst.max((got - e).abs());
        }
    }
    eprintln!("G1: max |onnx - f64| = {worst:.2e}");
    assert!(
        worst < 1e-5,
        "onnxruntime differs from the f64 forward by {worst}"
    );
}

#[test]
fn a_checkpoint_of_another_shape_fails_with_one_line() {
    let dir = tempfile::tempdir().expect("temporary directory");
    let config = config();
    // The tensors of a policy without the root target, under the backflip's configuration.
    let mut smaller = config.clone();
    smaller.obs.root_target = false;
    let mut checkpoint = seeded_checkpoint(&smaller, 3);
    checkpoint.meta = CheckpointMeta::new(&config, 42, 3.5, 1_000_000).expect("meta");
    let path = dir.path().join("mismatch.safetensors");
    checkpoint.save(&path).expect("save");
    let out = export(&path, &dir.path().join("policy.onnx"));
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(err.lines().count(), 1, "{err}");
    assert!(
        err.contains("mismatch.safetensors") && err.contains(ppo_tensor_names::ACTOR),
        "{err}"
    );
    assert!(!dir.path().join("policy.onnx").exists());

    let out = run(&[
        "export",
        "--checkpoint",
        path_str(&path),
        "--format",
        "onnx",
        "--out",
        "/no/such/dir/p.onnx",
    ]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && err.lines().count() == 1 && err.contains("does not exist"),
        "{err}"
    );
}
