//! The backward pass of the MLPs (`kernels_py/env/mlp_backward.py`): gradient
//! buffers laid out like the parameters, the split of the weight-gradient reductions, and the
//! launches layer by layer.

use crate::cuda::{Gpu, Stream};
use crate::kernels::{DeviceArray, DeviceArray2, EnvKernels};

use super::NnError;
use super::mlp::{LayerShape, Mlp};

/// Gradients of one network, one flat buffer laid out like its parameters (`w [in, out]` then
/// `b [out]` per layer, then anything after the layers, e.g. the actor's log std), with views of
/// each layer.
pub struct MlpGradients {
    pub flat: DeviceArray<f32>,
    layers: Vec<(DeviceArray2<f32>, DeviceArray<f32>)>,
}

impl MlpGradients {
    /// Zeroed gradients of `len` values (the parameter buffer's length) for `shapes`.
    pub fn new(gpu: &Gpu, shapes: &[LayerShape], len: usize) -> Result<MlpGradients, NnError> {
        let flat = DeviceArray::zeros(gpu, [len])?;
        let layers = shapes
            .iter()
            .map(|s| {
                Ok((
                    flat.view(s.offset, [s.inputs, s.outputs])?,
                    flat.view(s.bias_offset(), [s.outputs])?,
                ))
            })
            .collect::<Result<_, NnError>>()?;
        Ok(MlpGradients { flat, layers })
    }

    /// Layer `l`'s `(dw [in, out], db [out])`.
    pub fn layer(&self, l: usize) -> Option<&(DeviceArray2<f32>, DeviceArray<f32>)> {
        self.layers.get(l)
    }
}

/// Queues the backward pass of `mlp` after its forward pass of `input`: from `d_output`
/// (`dL/d output`, `[M, outputs]`), every layer's `dw` and `db` are added to `grads` (clear it
/// first). The hidden activations of `mlp` are overwritten with the gradients of their
/// pre-activations; run the forward pass again before reading them. The GEMMs run as
/// `mlp.gemm` says; its cuBLAS path needs `scratch` of at least M x (the widest hidden layer)
/// values ([`input_gradient_scratch_len`]).
#[allow(clippy::too_many_arguments)]
pub(crate) fn record_mlp_backward(
    kernels: &EnvKernels,
    stream: &Stream,
    mlp: &Mlp,
    input: &DeviceArray2<f32>,
    d_output: &DeviceArray2<f32>,
    grads: &MlpGradients,
    target_blocks: usize,
    scratch: Option<&DeviceArray<f32>>,
) -> Result<(), NnError> {
    let last = mlp.layers.len() - 1;
    if d_output.shape() != mlp.activations[last].shape() {
        return Err(NnError::Shape(format!(
            "output gradient {:?} for an output of {:?}",
            d_output.shape(),
            mlp.activations[last].shape()
        )));
    }
    let gemm = &mlp.gemm;
    for l in (0..=last).rev() {
        let dz = if l == last {
            d_output
        } else {
            &mlp.activations[l]
        };
        let x = if l == 0 {
            input
        } else {
            &mlp.activations[l - 1]
        };
        let layer = |l: usize| {
            grads
                .layer(l)
                .ok_or_else(|| NnError::Shape(format!("no gradient buffer for layer {l}")))
        };
        let (dw, db) = layer(l)?;
        // A hidden layer's bias gradient may have come with the input gradient above.
        let db = (l == last || !gemm.bias_with_input_gradient()).then_some(db);
        // The weight gradient reads x (the layer below's output) before the input gradient
        // overwrites it.
        gemm.record_weight_gradient(kernels, stream, x, dz, dw, db, target_blocks)?;
        if l > 0 {
            let (_, db_below) = layer(l - 1)?;
            let w = &mlp.layers[l].0;
            gemm.record_input_gradient_elu(kernels, stream, dz, w, x, scratch, db_below)?;
        }
    }
    Ok(())
}

/// Values of the scratch buffer the cuBLAS input gradients of `rows` rows need: the product
/// `dz w^T` of the widest layer input past the first (M x K; the first layer has no input
/// gradient).
pub fn input_gradient_scratch_len(rows: usize, networks: &[&[LayerShape]]) -> usize {
    let widest = networks
        .iter()
        .flat_map(|layers| layers.iter().skip(1).map(|l| l.inputs))
        .max()
        .unwrap_or(0);
    rows * widest
}
