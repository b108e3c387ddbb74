//! The pieces every exported graph is built from: float32 and int64 initializers, the
//! observation normalizer as the GPU applies it (`Sub`, `Mul`, `Clip`), an MLP as `Gemm`s with
//! `Elu` between them, column gathers and slices, and the model around a graph.

use std::collections::BTreeSet;

use crate::nn::LayerShape;

use super::proto::*;
use super::{BATCH, IR_VERSION, OPSET};

/// The nodes and initializers of one graph under construction.
#[derive(Default)]
pub struct GraphBuilder {
    pub nodes: Vec<NodeProto>,
    pub initializer: Vec<TensorProto>,
    /// Initializer names already added: a network used twice (the decoder from `z` and from
    /// the prior's mean) shares its weights.
    names: BTreeSet<String>,
}

fn tensor(name: &str, dims: &[usize], data_type: i32, raw_data: Vec<u8>) -> TensorProto {
    TensorProto {
        dims: dims.iter().map(|&d| d as i64).collect(),
        data_type,
        name: name.to_string(),
        raw_data,
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

fn int_attribute(name: &str, i: i64) -> AttributeProto {
    AttributeProto {
        name: name.to_string(),
        r#type: ATTRIBUTE_INT,
        f: 0.0,
        i,
    }
}

/// A `[batch, size]` float input or output.
pub fn value_info(name: &str, size: usize, doc: &str) -> ValueInfoProto {
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

impl GraphBuilder {
    /// A float32 initializer (added once per name).
    pub fn floats(&mut self, name: &str, dims: &[usize], values: impl IntoIterator<Item = f32>) {
        if self.names.insert(name.to_string()) {
            let raw = values.into_iter().flat_map(|v| v.to_le_bytes()).collect();
            self.initializer.push(tensor(name, dims, FLOAT, raw));
        }
    }

    /// An int64 initializer (added once per name).
    pub fn ints(&mut self, name: &str, values: &[i64]) {
        if self.names.insert(name.to_string()) {
            let raw = values.iter().flat_map(|v| v.to_le_bytes()).collect();
            self.initializer
                .push(tensor(name, &[values.len()], INT64, raw));
        }
    }

    pub fn op(&mut self, op: &str, inputs: &[&str], output: &str) {
        self.nodes.push(node(op, inputs, output));
    }

    /// `(input - mean) * inv_std` clipped to `[-clip, clip]`, as `{prefix}_normalized`
    /// (initializers `{prefix}_mean`, `{prefix}_inv_std`, `{prefix}_clip_min/max`).
    pub fn normalize(
        &mut self,
        input: &str,
        prefix: &str,
        mean: &[f64],
        inv_std: &[f64],
        clip: f32,
    ) -> String {
        let name = |s: &str| format!("{prefix}_{s}");
        self.floats(&name("mean"), &[mean.len()], mean.iter().map(|&v| v as f32));
        self.floats(
            &name("inv_std"),
            &[inv_std.len()],
            inv_std.iter().map(|&v| v as f32),
        );
        self.floats(&name("clip_min"), &[], [-clip]);
        self.floats(&name("clip_max"), &[], [clip]);
        self.op("Sub", &[input, &name("mean")], &name("centered"));
        self.op(
            "Mul",
            &[&name("centered"), &name("inv_std")],
            &name("scaled"),
        );
        self.op(
            "Clip",
            &[&name("scaled"), &name("clip_min"), &name("clip_max")],
            &name("normalized"),
        );
        name("normalized")
    }

    /// The MLP `layers` of `params` (weights `{weights}.{l}.weight`, `.bias`) on `input`, ELU
    /// between layers, into `output`; intermediate values are named `{nodes}.{l}.*`.
    pub fn mlp(
        &mut self,
        weights: &str,
        nodes: &str,
        layers: &[LayerShape],
        params: &[f32],
        input: &str,
        output: &str,
    ) {
        let mut x = input.to_string();
        for (l, layer) in layers.iter().enumerate() {
            let (w, b) = (
                format!("{weights}.{l}.weight"),
                format!("{weights}.{l}.bias"),
            );
            self.floats(
                &w,
                &[layer.inputs, layer.outputs],
                params[layer.offset..layer.bias_offset()].iter().copied(),
            );
            self.floats(
                &b,
                &[layer.outputs],
                params[layer.bias_offset()..layer.end()].iter().copied(),
            );
            let last = l + 1 == layers.len();
            let y = if last {
                output.to_string()
            } else {
                format!("{nodes}.{l}.linear")
            };
            self.op("Gemm", &[&x, &w, &b], &y);
            if !last {
                let z = format!("{nodes}.{l}.elu");
                let mut elu = node("Elu", &[&y], &z);
                elu.attribute.push(AttributeProto {
                    name: "alpha".to_string(),
                    r#type: ATTRIBUTE_FLOAT,
                    f: 1.0,
                    i: 0,
                });
                self.nodes.push(elu);
                x = z;
            }
        }
    }

    /// Columns `columns` of `[batch, D]` `input` into `[batch, columns.len()]` `output`.
    pub fn gather_columns(&mut self, input: &str, columns: &[i32], output: &str) {
        let indices = format!("{output}_columns");
        let values: Vec<i64> = columns.iter().map(|&c| i64::from(c)).collect();
        self.ints(&indices, &values);
        let mut gather = node("Gather", &[input, &indices], output);
        gather.attribute.push(int_attribute("axis", 1));
        self.nodes.push(gather);
    }

    /// Columns `start..end` of `input` into `output`.
    pub fn slice_columns(&mut self, input: &str, start: usize, end: usize, output: &str) {
        let (s, e, axes) = (
            format!("{output}_start"),
            format!("{output}_end"),
            format!("{output}_axes"),
        );
        self.ints(&s, &[start as i64]);
        self.ints(&e, &[end as i64]);
        self.ints(&axes, &[1]);
        self.op("Slice", &[input, &s, &e, &axes], output);
    }

    /// `[a | b]` along the columns.
    pub fn concat_columns(&mut self, a: &str, b: &str, output: &str) {
        let mut concat = node("Concat", &[a, b], output);
        concat.attribute.push(int_attribute("axis", 1));
        self.nodes.push(concat);
    }

    /// The model of this graph with `inputs`, `outputs` and `metadata`.
    pub fn model(
        self,
        name: &str,
        doc: String,
        inputs: Vec<ValueInfoProto>,
        outputs: Vec<ValueInfoProto>,
        metadata: Vec<(String, String)>,
    ) -> ModelProto {
        ModelProto {
            ir_version: IR_VERSION,
            opset_import: vec![OperatorSetIdProto {
                domain: String::new(),
                version: OPSET,
            }],
            producer_name: "instantmimic".to_string(),
            producer_version: env!("CARGO_PKG_VERSION").to_string(),
            domain: String::new(),
            model_version: 1,
            doc_string: doc,
            graph: Some(GraphProto {
                node: self.nodes,
                name: name.to_string(),
                initializer: self.initializer,
                doc_string: String::new(),
                input: inputs,
                output: outputs,
            }),
            metadata_props: metadata
                .into_iter()
                .map(|(key, value)| StringStringEntryProto { key, value })
                .collect(),
        }
    }
}
