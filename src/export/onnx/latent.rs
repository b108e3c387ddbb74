//! A latent controller (docs/latent.md) and a goal policy in its latent action space
//! (docs/goal.md) as ONNX, built from the same pieces as the tracker's actor ([`GraphBuilder`]).
//!
//! A latent controller becomes two models, because the two ways to drive the decoder need
//! different inputs: the **decoder model** reads only the character's state (`proprio`, the
//! columns [`LatentContract::proprio_columns`] of the tracking observation) and `z`, and also
//! evaluates the prior (what a controller without a reference needs); the **encoder model**
//! reads the whole tracking observation (reference included) and gives the encoder's mean and
//! the decoder's action at it (the tracker the controller distilled). ONNX Runtime wants every
//! graph input fed, so one model with both would make a deployment without a reference invent
//! one.
//!
//! A latent goal policy is one graph: head -> `z = mu_prior + scale * a` -> decoder.

use serde::{Deserialize, Serialize};

use crate::env::layout::{JointLayout, observation_blocks};
use crate::latent::FrozenDecoder;
use crate::latent::GoalDecoder;
use crate::latent::checkpoint::latent_tensor_names;
use crate::latent::networks::REFERENCE_BLOCKS;
use crate::motion::Character;
use crate::nn::LayerShape;
use crate::run::Checkpoint;
use crate::train::latent_setup::{frozen_decoder_of, latent_shapes};
use crate::train::{PolicyShapes, TrainError};

use super::contract::PolicyContract;
use super::graph::{GraphBuilder, value_info};
use super::proto::ModelProto;
use super::{ExportError, INPUT, OUTPUT, encode_error, normalizer};

/// Names of the latent models' inputs and outputs (besides `obs` and `actions`).
pub const PROPRIO: &str = "proprio";
pub const LATENT: &str = "z";
pub const PRIOR_MU: &str = "prior_mu";
pub const PRIOR_ACTIONS: &str = "prior_actions";
pub const ENCODER_MU: &str = "encoder_mu";
/// The `metadata_props` key of the [`LatentContract`] JSON.
pub const LATENT_KEY: &str = "instantmimic.latent";
pub const LATENT_FORMAT_NAME: &str = "instantmimic-latent-controller";

/// What a deployment of a latent controller needs besides the weights: which observation
/// columns are the character's state, the latent size, and the tracker-style contract (joints,
/// PD control, the whole observation's blocks, which the encoder model reads).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LatentContract {
    pub format: String,
    /// The tracking observation's columns that form `proprio`, in order.
    pub proprio_columns: Vec<i32>,
    /// The observation blocks those columns come from (every block but the reference's).
    pub proprio_blocks: Vec<String>,
    pub latent_size: usize,
    pub decoder_model: String,
    pub encoder_model: String,
    pub policy: PolicyContract,
}

/// A latent controller's two models and their contract.
#[derive(Clone, Debug)]
pub struct LatentExport {
    pub decoder: ModelProto,
    pub encoder: ModelProto,
    pub contract: LatentContract,
}

fn end(layers: &[LayerShape]) -> usize {
    layers.last().map_or(0, LayerShape::end)
}

/// `prior_output [batch, 2L]` -> `prior_mu`, from `proprio_normalized`.
fn prior_mean(graph: &mut GraphBuilder, frozen: &FrozenDecoder, proprio: &str) {
    graph.mlp(
        "prior",
        "prior",
        &frozen.prior_layers,
        &frozen.prior,
        proprio,
        "prior_output",
    );
    graph.slice_columns("prior_output", 0, frozen.latent_size, PRIOR_MU);
}

/// The decoder on `[proprio | z]` into `output` (its weights shared by every use).
fn decode(graph: &mut GraphBuilder, frozen: &FrozenDecoder, proprio: &str, z: &str, output: &str) {
    let input = format!("{output}_decoder_input");
    graph.concat_columns(proprio, z, &input);
    graph.mlp(
        "decoder",
        &format!("{output}_decoder"),
        &frozen.decoder_layers,
        &frozen.decoder,
        &input,
        output,
    );
}

/// The latent goal policy after the normalizer: the head (`head_layers` of `head`) gives the
/// latent action, `z = mu_prior + scale * action`, the decoder gives `actions`.
pub fn compose_latent_goal(
    graph: &mut GraphBuilder,
    decoder: &GoalDecoder,
    head_layers: &[LayerShape],
    head: &[f32],
    normalized: &str,
) {
    let frozen = &decoder.frozen;
    graph.mlp(
        "head",
        "head",
        head_layers,
        head,
        normalized,
        "latent_action",
    );
    graph.gather_columns(
        normalized,
        &decoder.decoding.proprio_columns,
        "proprio_normalized",
    );
    prior_mean(graph, frozen, "proprio_normalized");
    graph.floats("latent_action_scale", &[], [decoder.scale]);
    graph.op(
        "Mul",
        &["latent_action", "latent_action_scale"],
        "latent_residual",
    );
    graph.op("Add", &[PRIOR_MU, "latent_residual"], LATENT);
    decode(graph, frozen, "proprio_normalized", LATENT, OUTPUT);
}

/// A latent goal policy's extra `metadata_props`: the decoder it drives.
pub fn goal_decoder_metadata(decoder: &GoalDecoder) -> Vec<(String, String)> {
    vec![
        (
            "instantmimic.goal.decoder".into(),
            decoder.frozen.source.clone(),
        ),
        (
            "instantmimic.goal.decoder_digest".into(),
            format!("{:?}", decoder.digest),
        ),
        (
            "instantmimic.goal.latent_action_scale".into(),
            decoder.scale.to_string(),
        ),
        (
            "instantmimic.latent_size".into(),
            decoder.frozen.latent_size.to_string(),
        ),
    ]
}

/// The two models of the latent controller `checkpoint` for `character`, named `decoder_model`
/// and `encoder_model` in the contract, with the plans' `physics_dt`. Refuses (one line naming
/// the file) a checkpoint that is not a latent controller's or whose parts do not fit.
pub fn export_latent_controller(
    checkpoint: &Checkpoint,
    character: &Character,
    physics_dt: f64,
    [decoder_model, encoder_model]: [&str; 2],
) -> Result<LatentExport, ExportError> {
    use latent_tensor_names as names;
    let source = checkpoint.source();
    let config = checkpoint
        .meta
        .config::<crate::train::TrainConfig>(source)
        .map_err(TrainError::from)?;
    let frozen = frozen_decoder_of(checkpoint, source)?;
    let policy = PolicyShapes::new(&config, character)?;
    let shapes = latent_shapes(&config, &policy)?;
    if shapes.proprio_columns != frozen.proprio_columns
        || shapes.observation_size != frozen.observation_size
        || shapes.action_size != frozen.action_size
    {
        return Err(ExportError::Unsupported(format!(
            "{source}: records {} character-state columns of {} observations and {} actions; its configuration gives {} of {} and {} (another version or character)",
            frozen.proprio_columns.len(),
            frozen.observation_size,
            frozen.action_size,
            shapes.proprio_columns.len(),
            shapes.observation_size,
            shapes.action_size
        )));
    }
    let encoder = checkpoint
        .get::<f32>(names::ENCODER, &[end(&shapes.encoder)])
        .map_err(TrainError::from)?;
    let (d, p, l, a) = (
        frozen.observation_size,
        frozen.proprio_columns.len(),
        frozen.latent_size,
        frozen.action_size,
    );
    let (mean, inv_std) = normalizer(&frozen.obs_count, &frozen.obs_mean, &frozen.obs_m2);
    let at_proprio = |v: &[f64]| -> Vec<f64> {
        frozen
            .proprio_columns
            .iter()
            .map(|&c| v[c as usize])
            .collect()
    };
    let clip = config.obs.clip;

    let layout = JointLayout::for_character(character)
        .map_err(|e| ExportError::Unsupported(e.to_string()))?;
    let mut policy_contract =
        PolicyContract::new(&checkpoint.meta, &config, character, &layout, d, physics_dt);
    policy_contract.output.description =
        "the decoder's action (the latent controller's mean action)".to_string();
    let proprio_blocks = observation_blocks(&config.obs, layout.observation_counts())
        .into_iter()
        .filter(|b| !REFERENCE_BLOCKS.contains(&b.name.as_str()))
        .map(|b| b.name)
        .collect();
    let contract = LatentContract {
        format: LATENT_FORMAT_NAME.to_string(),
        proprio_columns: frozen.proprio_columns.clone(),
        proprio_blocks,
        latent_size: l,
        decoder_model: decoder_model.to_string(),
        encoder_model: encoder_model.to_string(),
        policy: policy_contract,
    };
    let mut metadata = contract
        .policy
        .metadata()
        .map_err(|e| encode_error(e.to_string()))?;
    metadata.extend([
        (
            LATENT_KEY.to_string(),
            serde_json::to_string(&contract).map_err(|e| encode_error(e.to_string()))?,
        ),
        (
            "instantmimic.proprio_columns".to_string(),
            serde_json::to_string(&contract.proprio_columns)
                .map_err(|e| encode_error(e.to_string()))?,
        ),
        ("instantmimic.latent_size".to_string(), l.to_string()),
    ]);
    let facts = format!(
        "{} latent controller (iteration {}, seed {})",
        contract.policy.motion,
        contract.policy.checkpoint.iteration,
        contract.policy.checkpoint.seed
    );

    // The decoder model: proprio and z in; the decoder's action, the prior's mean and the
    // decoder's action at the prior's mean out.
    let mut graph = GraphBuilder::default();
    let proprio = graph.normalize(
        PROPRIO,
        PROPRIO,
        &at_proprio(&mean),
        &at_proprio(&inv_std),
        clip,
    );
    decode(&mut graph, &frozen, &proprio, LATENT, OUTPUT);
    prior_mean(&mut graph, &frozen, &proprio);
    decode(&mut graph, &frozen, &proprio, PRIOR_MU, PRIOR_ACTIONS);
    let mut decoder_metadata = metadata.clone();
    decoder_metadata.push(("instantmimic.model".into(), "decoder".into()));
    let decoder = graph.model(
        "latent_decoder",
        format!("{facts}: decoder and prior; proprio = the observation's columns instantmimic.proprio_columns, raw"),
        vec![
            value_info(PROPRIO, p, "raw character state: the observation's proprio_columns (metadata)"),
            value_info(LATENT, l, "latent z"),
        ],
        vec![
            value_info(OUTPUT, a, "the decoder's mean action at (proprio, z)"),
            value_info(PRIOR_MU, l, "the prior's mean of z given proprio"),
            value_info(PRIOR_ACTIONS, a, "the decoder's mean action at z = prior_mu"),
        ],
        decoder_metadata,
    );

    // The encoder model: the whole observation in; the encoder's mean and the decoder's
    // action there out.
    let mut graph = GraphBuilder::default();
    let normalized = graph.normalize(INPUT, "obs", &mean, &inv_std, clip);
    graph.mlp(
        "encoder",
        "encoder",
        &shapes.encoder,
        encoder,
        &normalized,
        "encoder_output",
    );
    graph.slice_columns("encoder_output", 0, l, ENCODER_MU);
    graph.gather_columns(&normalized, &frozen.proprio_columns, "proprio_normalized");
    decode(
        &mut graph,
        &frozen,
        "proprio_normalized",
        ENCODER_MU,
        OUTPUT,
    );
    metadata.push(("instantmimic.model".into(), "encoder".into()));
    let encoder = graph.model(
        "latent_encoder",
        format!("{facts}: encoder; observation -> encoder mean and the decoder's action there"),
        vec![value_info(
            INPUT,
            d,
            "raw tracking observation (contract: observation.blocks)",
        )],
        vec![
            value_info(ENCODER_MU, l, "the encoder's mean of z"),
            value_info(OUTPUT, a, "the decoder's mean action at z = encoder_mu"),
        ],
        metadata,
    );
    Ok(LatentExport {
        decoder,
        encoder,
        contract,
    })
}

impl LatentExport {
    /// The JSON sidecar's text.
    pub fn contract_json(&self) -> Result<String, ExportError> {
        serde_json::to_string_pretty(&self.contract).map_err(|e| encode_error(e.to_string()))
    }
}
