//! The GPU NN toolkit any learner builds on (PPO's actor and critic, the latent controller's
//! networks): every operation is queued on a stream with no host synchronization, so it records
//! into a CUDA graph like any other launch, and checks the shapes its kernels cannot.
//!
//! - [`gemm`]: what computes the GEMMs ([`PolicyGemm`], `policy.gemm` as [`GemmSetting`]):
//!   Warp's tile kernels, or cuBLAS with elementwise epilogues
//!   (`kernels_py/env/{policy, gemm_epilogue}.py`).
//! - [`mlp`]: MLPs as flat parameter buffers ([`LayerShape`], [`mlp_layout`],
//!   [`initial_parameters`]) and their forward pass.
//! - [`backward`]: the MLP backward pass, gradient buffers, the split of the weight-gradient
//!   reductions (`mlp_backward.py`).
//! - [`adam`]: Adam with global gradient-norm clipping (`optimizer.py`).
//! - [`reduce`]: column sums, sums of squares, clears (`reduce.py`).
//! - [`shuffle`]: the per-epoch device shuffle and the minibatch split (`minibatch.py`).
//! - [`NnError`]: what any of them can refuse.

pub mod adam;
pub mod backward;
mod error;
pub mod gemm;
pub mod linear_backward;
pub mod mlp;
pub mod reduce;
pub mod shuffle;

pub use error::NnError;
pub use gemm::{GemmPath, GemmSetting, PolicyGemm};
pub use mlp::{LayerShape, initial_parameters, mlp_layout};
