//! A checkpoint's actor as an ONNX model (opset 17, IR version 8): the observation normalizer
//! then the MLP, float32 initializers, input `obs [batch, D]` and output `actions [batch, A]`
//! (the mean action) with a named dynamic batch axis, and the deployment contract in
//! `metadata_props` ([`contract`]). No GPU: the weights are the checkpoint's.
//! A goal checkpoint exports the same way (its contract's blocks the goal observation's; in a
//! latent action space the head, prior and decoder composed); a latent controller exports as
//! two models ([`latent`]).
//!
//! The graph: `Sub(obs, mean)`, `Mul(·, 1 / sqrt(var + 1e-8))`, `Clip(·, -clip, clip)`, then per
//! layer `Gemm(x, W, b)` with `Elu` between layers. The normalizer stays three nodes rather than
//! being folded into the first layer's weights: the clip between them is not linear.

pub mod contract;
pub mod graph;
pub mod latent;
pub mod proto;

use prost::Message as _;

use crate::env::layout::{JointLayout, ObservationBlock, ObservationCounts, observation_blocks};
use crate::env::{GOAL_OBSERVATION, ObsConfig, goal_observation_config};
use crate::latent::DECODER_DIGEST;
use crate::motion::Character;
use crate::nn::{LayerShape, mlp_layout};
use crate::ppo::checkpoint::evaluated_actor;
use crate::run::Checkpoint;
use crate::run::checkpoint::tensor_names;
use crate::train::goal_latent::{head_shapes, load_goal_decoder};
use crate::train::{PolicyShapes, TrainConfig, TrainError};

use super::{ExportError, Format};
use contract::{PolicyContract, VARIANCE_EPSILON};
use graph::{GraphBuilder, value_info};
use proto::*;

/// The ONNX operator set the model uses.
pub const OPSET: i64 = 17;
/// The IR version that goes with opset 17 (ONNX 1.12).
pub const IR_VERSION: i64 = 8;
/// Names of the graph's input and output.
pub const INPUT: &str = "obs";
pub const OUTPUT: &str = "actions";
/// The dynamic batch axis.
pub const BATCH: &str = "batch";

/// A policy ready to write: the model and its contract.
#[derive(Clone, Debug)]
pub struct PolicyExport {
    pub model: ModelProto,
    pub contract: PolicyContract,
}

impl PolicyExport {
    /// The `.onnx` bytes.
    pub fn to_bytes(&self) -> Vec<u8> {
        self.model.encode_to_vec()
    }

    /// The JSON sidecar's text.
    pub fn contract_json(&self) -> Result<String, ExportError> {
        serde_json::to_string_pretty(&self.contract).map_err(|e| encode_error(e.to_string()))
    }
}

fn encode_error(problem: String) -> ExportError {
    ExportError::Encode {
        format: Format::Onnx,
        problem,
    }
}

/// The observation normalizer as the GPU applies it (kernels_py/env/observe.py,
/// `observation_normalize`): mean and `1 / sqrt(M2 / count + 1e-8)` from the merged count,
/// or mean 0 and variance 1 before any statistics.
pub fn normalizer(count: &[f64], mean: &[f64], m2: &[f64]) -> (Vec<f64>, Vec<f64>) {
    let merged = count.get(1).copied().unwrap_or(0.0);
    if merged > 0.0 {
        let inv_std = m2
            .iter()
            .map(|m| 1.0 / (m / merged + VARIANCE_EPSILON).sqrt())
            .collect();
        (mean.to_vec(), inv_std)
    } else {
        let inv_std = 1.0 / (1.0 + VARIANCE_EPSILON).sqrt();
        (vec![0.0; mean.len()], vec![inv_std; mean.len()])
    }
}

/// The actor's layers in the checkpoint's flat parameters (`GaussianPolicy`'s layout).
pub fn actor_layers(config: &TrainConfig, shapes: &PolicyShapes) -> Vec<LayerShape> {
    mlp_layout(
        shapes.observation_size,
        &config.policy.actor_hidden,
        shapes.action_size,
    )
}

/// The ONNX model and contract of `checkpoint`'s actor for `character`, with the physics
/// timestep of the plans it was trained with. A checkpoint whose tensors do not have the shapes
/// its stored configuration implies is refused, naming the tensor.
pub fn export_policy(
    checkpoint: &Checkpoint,
    character: &Character,
    physics_dt: f64,
) -> Result<PolicyExport, ExportError> {
    let config = checkpoint
        .meta
        .config::<crate::train::TrainConfig>(checkpoint.source())
        .map_err(TrainError::from)?;
    if config.latent.is_some() {
        return Err(ExportError::Unsupported(format!(
            "{}: a latent controller's checkpoint; export it with latent::export_latent_controller (two models)",
            checkpoint.source()
        )));
    }
    // A goal run in a latent action space drives the decoder its configuration names, which
    // must be the one it was trained with (the digest, as eval checks it).
    let decoder = load_goal_decoder(&config, character)?;
    let shapes = match &decoder {
        Some(d) => {
            d.check_checkpoint(checkpoint).map_err(TrainError::from)?;
            head_shapes(d, &config)
        }
        None if checkpoint.tensor(DECODER_DIGEST).is_some() => {
            return Err(ExportError::Unsupported(format!(
                "{}: records a latent decoder's digest, but its configuration names no goal.decoder",
                checkpoint.source()
            )));
        }
        None => PolicyShapes::new(&config, character)?,
    };
    shapes.check(checkpoint)?;
    let layout = JointLayout::for_character(character)
        .map_err(|e| ExportError::Unsupported(e.to_string()))?;
    let d = shapes.observation_size;
    let actor = checkpoint
        .get::<f32>(evaluated_actor(checkpoint), &[shapes.actor_params])
        .map_err(TrainError::from)?;
    let (mean, inv_std) = checkpoint_normalizer(checkpoint, d)?;

    let mut graph = GraphBuilder::default();
    let normalized = graph.normalize(INPUT, "obs", &mean, &inv_std, config.obs.clip);
    let layers = actor_layers(&config, &shapes);
    let what = match &decoder {
        None => {
            graph.mlp("actor", "actor", &layers, actor, &normalized, OUTPUT);
            if config.goal.is_some() {
                "goal policy (PD targets)"
            } else {
                "tracking policy"
            }
        }
        Some(d) => {
            latent::compose_latent_goal(&mut graph, d, &layers, actor, &normalized);
            "goal policy (latent head, prior and frozen decoder composed)"
        }
    };
    let mut contract =
        PolicyContract::new(&checkpoint.meta, &config, character, &layout, d, physics_dt);
    if config.goal.is_some() {
        contract.observation.blocks =
            goal_observation_blocks(&config.obs, layout.observation_counts());
    }
    let mut metadata = contract
        .metadata()
        .map_err(|e| encode_error(e.to_string()))?;
    if let Some(d) = &decoder {
        metadata.extend(latent::goal_decoder_metadata(d));
    }
    let model = graph.model(
        "actor",
        format!(
            "{} {what} (iteration {}, seed {}): observation -> mean action; see metadata_props",
            contract.motion, contract.checkpoint.iteration, contract.checkpoint.seed
        ),
        vec![value_info(
            INPUT,
            d,
            "raw observation (contract: observation.blocks)",
        )],
        vec![value_info(OUTPUT, layout.num_motors, "mean action")],
        metadata,
    );
    Ok(PolicyExport { model, contract })
}

/// The goal task's observation blocks: the character's own state (no reference blocks), then
/// the goal (docs/goal.md).
pub fn goal_observation_blocks(
    obs: &ObsConfig,
    counts: ObservationCounts,
) -> Vec<ObservationBlock> {
    // The reference blocks the goal task turns off are there with size 0; they are left out.
    let mut blocks: Vec<ObservationBlock> =
        observation_blocks(&goal_observation_config(obs), counts)
            .into_iter()
            .filter(|b| b.size > 0)
            .collect();
    let offset = blocks.last().map_or(0, |b| b.offset + b.size);
    blocks.push(ObservationBlock {
        name: "goal".to_string(),
        offset,
        size: GOAL_OBSERVATION,
        frame: "heading".to_string(),
        description: "the goal relative to the root in the root's heading frame (x, y), then its horizontal distance, in metres".to_string(),
    });
    blocks
}

/// The normalizer (mean, 1 / std) of a checkpoint's observation statistics of `d` values.
pub fn checkpoint_normalizer(
    checkpoint: &Checkpoint,
    d: usize,
) -> Result<(Vec<f64>, Vec<f64>), ExportError> {
    let count = checkpoint
        .get::<f64>(tensor_names::OBS_COUNT, &[2])
        .map_err(TrainError::from)?;
    let mean = checkpoint
        .get::<f64>(tensor_names::OBS_MEAN, &[d])
        .map_err(TrainError::from)?;
    let m2 = checkpoint
        .get::<f64>(tensor_names::OBS_M2, &[d])
        .map_err(TrainError::from)?;
    Ok(normalizer(count, mean, m2))
}
