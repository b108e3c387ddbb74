//! MLPs on the GPU, for any learner's networks (the actor and critic, the latent controller's
//! encoder, decoder and prior; docs/env.md, "Policy").
//!
//! Each network's parameters are one flat `f32` device buffer (so the optimizer is one kernel
//! over all of them), laid out layer by layer as `w [in, out]` row-major then `b [out]`; a
//! buffer may hold more after the layers (the actor's `log_std [A]`). Layers are views into it.
//! The forward pass is `kernels_py/env/policy.py` (tile GEMMs with bias and ELU) or cuBLAS with
//! `gemm_epilogue.py`, as `policy.gemm` says ([`PolicyGemm`]), queued on a stream only: it
//! records into a CUDA graph like any other launch.

use rand::rngs::StdRng;
use rand_distr::{Distribution, StandardNormal};

use crate::cuda::{Gpu, Stream};
use crate::kernels::{DeviceArray, DeviceArray2, EnvError, EnvKernels};

use super::NnError;
use super::gemm::PolicyGemm;

/// Where one layer lives in a flat parameter buffer.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct LayerShape {
    pub inputs: usize,
    pub outputs: usize,
    /// Offset of `w` (then `b` at `offset + inputs * outputs`), in values.
    pub offset: usize,
}

impl LayerShape {
    pub fn bias_offset(&self) -> usize {
        self.offset + self.inputs * self.outputs
    }

    pub fn end(&self) -> usize {
        self.bias_offset() + self.outputs
    }
}

/// Layer shapes of an MLP `inputs -> hidden... -> outputs`, packed from offset 0.
pub fn mlp_layout(inputs: usize, hidden: &[u32], outputs: usize) -> Vec<LayerShape> {
    let mut sizes = vec![inputs];
    sizes.extend(hidden.iter().map(|&h| h as usize));
    sizes.push(outputs);
    let mut offset = 0;
    sizes
        .windows(2)
        .map(|io| {
            let layer = LayerShape {
                inputs: io[0],
                outputs: io[1],
                offset,
            };
            offset = layer.end();
            layer
        })
        .collect()
}

/// Initial parameters: weights N(0, gain^2 / inputs), `hidden_gain` for every layer but the
/// last and `last_gain` for the last (config `policy.init_hidden_gain`, He's sqrt(2), and
/// `policy.init_output_gain`), biases 0.
pub fn initial_parameters(
    layers: &[LayerShape],
    hidden_gain: f64,
    last_gain: f64,
    rng: &mut StdRng,
) -> Vec<f32> {
    let total = layers.last().map_or(0, LayerShape::end);
    let mut params = vec![0.0f32; total];
    for (l, layer) in layers.iter().enumerate() {
        let gain = if l + 1 == layers.len() {
            last_gain
        } else {
            hidden_gain
        };
        let std = gain / (layer.inputs as f64).sqrt();
        for w in &mut params[layer.offset..layer.bias_offset()] {
            let g: f64 = StandardNormal.sample(rng);
            *w = (std * g) as f32;
        }
    }
    params
}

/// An MLP on the GPU: its layers as views into `params`, and activations for a batch (each
/// layer's output; a backward pass, [`super::backward::record_mlp_backward`], reads them and
/// overwrites the hidden ones).
pub(crate) struct Mlp {
    pub(crate) params: DeviceArray<f32>,
    /// Each layer's `w [in, out]` and `b [out]`.
    pub(crate) layers: Vec<(DeviceArray2<f32>, DeviceArray<f32>)>,
    pub(crate) activations: Vec<DeviceArray2<f32>>,
    /// What computes the layers (shared with the other networks of the policy).
    pub(crate) gemm: PolicyGemm,
}

impl Mlp {
    pub(crate) fn new(
        gpu: &Gpu,
        shapes: &[LayerShape],
        params: DeviceArray<f32>,
        batch: usize,
        gemm: PolicyGemm,
    ) -> Result<Mlp, EnvError> {
        let mut layers = Vec::new();
        let mut activations = Vec::new();
        for s in shapes {
            layers.push((
                params.view(s.offset, [s.inputs, s.outputs])?,
                params.view(s.bias_offset(), [s.outputs])?,
            ));
            activations.push(DeviceArray::zeros(gpu, [batch, s.outputs])?);
        }
        Ok(Mlp {
            params,
            layers,
            activations,
            gemm,
        })
    }

    /// Queues the forward pass of `input` (`[batch, inputs]`); the result is the last activation.
    pub(crate) fn record(
        &self,
        kernels: &EnvKernels,
        stream: &Stream,
        input: &DeviceArray2<f32>,
    ) -> Result<(), NnError> {
        let mut x = input;
        let last = self.layers.len() - 1;
        for (l, ((w, b), y)) in self.layers.iter().zip(&self.activations).enumerate() {
            self.gemm
                .record_linear(kernels, stream, x, w, b, y, l != last)?;
            x = y;
        }
        Ok(())
    }

    pub(crate) fn output(&self) -> &DeviceArray2<f32> {
        &self.activations[self.activations.len() - 1]
    }
}
