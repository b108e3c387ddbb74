//! A checkpoint's actor as an ONNX model (opset 17, IR version 8): the observation normalizer
//! then the MLP, float32 initializers, input `obs [batch, D]` and output `actions [batch, A]`
//! (the mean action) with a named dynamic batch axis, and the deployment contract in
//! `metadata_props` ([`contract`]). No GPU: the weights are the checkpoint's.
//!
//! The graph: `Sub(obs, mean)`, `Mul(·, 1 / sqrt(var + 1e-8))`, `Clip(·, -clip, clip)`, then per
//! layer `Gemm(x, W, b)` with `Elu` between layers. The normalizer stays three nodes rather than
//! being folded into the first layer's weights: the clip between them is not linear.

pub mod contract;
pub mod proto;

use prost::Message as _;

use crate::env::layout::JointLayout;
use crate::motion::Character;
use crate::ppo::{LayerShape, mlp_layout};
use crate::train::checkpoint::tensor_names;
use crate::train::{Checkpoint, PolicyShapes, TrainConfig, TrainError};

use super::{ExportError, Format};
use contract::{PolicyContract, VARIANCE_EPSILON};
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

fn tensor(name: &str, dims: &[usize], values: impl IntoIterator<Item = f32>) -> TensorProto {
    TensorProto {
        dims: dims.iter().map(|&d| d as i64).collect(),
        data_type: FLOAT,
        name: name.to_string(),
        raw_data: values.into_iter().flat_map(|v| v.to_le_bytes()).collect(),
    }
}

fn node(op: &str, inputs: &[&str], output: &str) -> NodeProto {
    NodeProto {
        input: inputs.iter().map(|s| s.to_string()).collect(),
        output: vec![output.to_string()],
        name: output.to_string(),
        op_type: op.to_string(),
        ..Default::default()
    }
}

fn value_info(name: &str, size: usize, doc: &str) -> ValueInfoProto {
    ValueInfoProto {
        name: name.to_string(),
        r#type: Some(TypeProto {
            tensor_type: Some(TensorTypeProto {
                elem_type: FLOAT,
                shape: Some(TensorShapeProto {
                    dim: vec![
                        Dimension {
                            value: Some(DimensionValue::DimParam(BATCH.to_string())),
                        },
                        Dimension {
                            value: Some(DimensionValue::DimValue(size as i64)),
                        },
                    ],
                }),
            }),
        }),
        doc_string: doc.to_string(),
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
        .config(checkpoint.source())
        .map_err(TrainError::from)?;
    if config.goal.is_some() {
        // The contract describes tracking's observation blocks, not the goal task's.
        return Err(ExportError::Unsupported(format!(
            "{}: a goal-task policy; its ONNX export is not built yet (docs/goal.md)",
            checkpoint.source()
        )));
    }
    let shapes = PolicyShapes::new(&config, character)?;
    shapes.check(checkpoint)?;
    let layout = JointLayout::for_character(character)
        .map_err(|e| ExportError::Unsupported(e.to_string()))?;
    let (d, a) = (shapes.observation_size, shapes.action_size);
    let actor = checkpoint
        .get::<f32>(tensor_names::ACTOR, &[shapes.actor_params])
        .map_err(TrainError::from)?;
    let count = checkpoint
        .get::<f64>(tensor_names::OBS_COUNT, &[2])
        .map_err(TrainError::from)?;
    let mean = checkpoint
        .get::<f64>(tensor_names::OBS_MEAN, &[d])
        .map_err(TrainError::from)?;
    let m2 = checkpoint
        .get::<f64>(tensor_names::OBS_M2, &[d])
        .map_err(TrainError::from)?;
    let (mean, inv_std) = normalizer(count, mean, m2);
    let clip = config.obs.clip;

    let mut initializer = vec![
        tensor("obs_mean", &[d], mean.iter().map(|&v| v as f32)),
        tensor("obs_inv_std", &[d], inv_std.iter().map(|&v| v as f32)),
        tensor("obs_clip_min", &[], [-clip]),
        tensor("obs_clip_max", &[], [clip]),
    ];
    let mut nodes = vec![
        node("Sub", &[INPUT, "obs_mean"], "obs_centered"),
        node("Mul", &["obs_centered", "obs_inv_std"], "obs_scaled"),
        node(
            "Clip",
            &["obs_scaled", "obs_clip_min", "obs_clip_max"],
            "obs_normalized",
        ),
    ];
    let layers = actor_layers(&config, &shapes);
    let mut x = "obs_normalized".to_string();
    for (l, layer) in layers.iter().enumerate() {
        let (w, b) = (format!("actor.{l}.weight"), format!("actor.{l}.bias"));
        initializer.push(tensor(
            &w,
            &[layer.inputs, layer.outputs],
            actor[layer.offset..layer.bias_offset()].iter().copied(),
        ));
        initializer.push(tensor(
            &b,
            &[layer.outputs],
            actor[layer.bias_offset()..layer.end()].iter().copied(),
        ));
        let last = l + 1 == layers.len();
        let y = if last {
            OUTPUT.to_string()
        } else {
            format!("actor.{l}.linear")
        };
        nodes.push(node("Gemm", &[&x, &w, &b], &y));
        if !last {
            let z = format!("actor.{l}.elu");
            let mut elu = node("Elu", &[&y], &z);
            elu.attribute.push(AttributeProto {
                name: "alpha".to_string(),
                r#type: ATTRIBUTE_FLOAT,
                f: 1.0,
                i: 0,
            });
            nodes.push(elu);
            x = z;
        }
    }

    let contract =
        PolicyContract::new(&checkpoint.meta, &config, character, &layout, d, physics_dt);
    let metadata_props = contract
        .metadata()
        .map_err(|e| encode_error(e.to_string()))?
        .into_iter()
        .map(|(key, value)| StringStringEntryProto { key, value })
        .collect();
    let model = ModelProto {
        ir_version: IR_VERSION,
        opset_import: vec![OperatorSetIdProto {
            domain: String::new(),
            version: OPSET,
        }],
        producer_name: "instantmimic".to_string(),
        producer_version: env!("CARGO_PKG_VERSION").to_string(),
        domain: String::new(),
        model_version: 1,
        doc_string: format!(
            "{} tracking policy (iteration {}, seed {}): observation -> mean action; see metadata_props",
            contract.motion, contract.checkpoint.iteration, contract.checkpoint.seed
        ),
        graph: Some(GraphProto {
            node: nodes,
            name: "actor".to_string(),
            initializer,
            doc_string: String::new(),
            input: vec![value_info(
                INPUT,
                d,
                "raw observation (contract: observation.blocks)",
            )],
            output: vec![value_info(OUTPUT, a, "mean action")],
        }),
        metadata_props,
    };
    Ok(PolicyExport { model, contract })
}
