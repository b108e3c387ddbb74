//! PPO on the GPU: the policy of the rollout and the update.
//!
//! - [`GaussianPolicy`]: the actor and critic MLPs, their flat parameter buffers, the forward pass
//!   and action sampling (`kernels_py/env/policy.py`).
//! - [`PpoUpdate`]: the whole update (GAE, device shuffle, minibatch forward, loss, backward,
//!   gradient clipping, Adam, KL-adaptive learning rate, statistics) recorded onto a stream with
//!   no host work, for capture into a CUDA graph (`kernels_py/env/{gae, minibatch, ppo_loss,
//!   mlp_backward, reduce, optimizer, ppo_statistics}.py`).
//! - [`PolicyGemm`]: what computes the networks' GEMMs (`policy.gemm`): Warp's tile kernels, or
//!   cuBLAS with elementwise epilogues (`kernels_py/env/gemm_epilogue.py`), in the same graphs.
//! - The parts, each with the shape checks its kernels cannot do: [`batch`] (what the rollout
//!   hands over, GAE, shuffle, gather), [`loss`] (loss gradients, the statistics layout),
//!   [`backward`] (MLP backward, split weight-gradient reductions), [`reduce`], [`adam`].
//! - [`UpdateStage`]: the update's parts, as NVTX ranges and event-timed (`bench full`).
//! - [`config`]: the `[policy]` and `[ppo]` sections of the training configuration.

pub mod adam;
pub mod backward;
pub mod batch;
pub mod config;
mod flops;
pub mod gemm;
pub mod loss;
pub(crate) mod policy;
pub mod reduce;
mod update;
mod update_stages;

pub use batch::PpoBatch;
pub use config::{GemmSetting, KlMeasure, PolicyConfig, PpoConfig};
pub use flops::UpdateFlops;
pub use gemm::{GemmPath, PolicyGemm};
pub use loss::PpoStatistics;
pub use policy::{GaussianPolicy, LayerShape, PolicyError, initial_parameters, mlp_layout};
pub use update::{PpoError, PpoOptimizerState, PpoUpdate};
pub use update_stages::UpdateStage;
