//! PPO on the GPU: the policy of the rollout (and, with issue 5, the update).
//!
//! - [`GaussianPolicy`]: the actor and critic MLPs, their flat parameter buffers, the forward pass
//!   and action sampling (`kernels_py/env/policy.py`).

mod policy;

pub use policy::{
    ActStorage, GaussianPolicy, LayerShape, PolicyError, initial_parameters, mlp_layout,
};
