//! The PPO learner's checkpoint tensors beside the ones every learner shares
//! ([`crate::run::checkpoint::tensor_names`]): the actor and the critic, Adam's moments of each,
//! and the value normalization's statistics. The trainer writes and restores them; export and
//! the loaders of a tracker (a latent controller's teacher, `eval`, `replay`) read them.

/// Every PPO tensor's name (docs/train.md, "Checkpoints").
pub mod ppo_tensor_names {
    /// Actor parameters, f32 `[P]`: layer by layer `w [in, out]` then `b [out]`, then `log_std [A]`.
    pub const ACTOR: &str = "actor.params";
    /// Critic parameters, f32 `[P]`, the same layout without `log_std`.
    pub const CRITIC: &str = "critic.params";
    // What an exact continuation needs beyond the policy (training checkpoints only).
    pub const ADAM_ACTOR_M: &str = "adam.actor.m";
    pub const ADAM_ACTOR_V: &str = "adam.actor.v";
    pub const ADAM_CRITIC_M: &str = "adam.critic.m";
    pub const ADAM_CRITIC_V: &str = "adam.critic.v";
    /// f64 `[3]`: the returns' running count, mean and M2 (value normalization).
    pub const VALUE_STATISTICS: &str = "value_norm.stats";
    /// With `ppo.evaluation_average`: the moving average of the actor's parameters, f32 `[P]`
    /// in `ACTOR`'s layout, the policy the run's evaluations ran (and so the one to deploy).
    pub const ACTOR_AVERAGE: &str = "actor.average";
}

/// The name of the actor tensor a checkpoint's evaluations ran, which `eval`, `export` and a
/// latent controller's teacher use: the average of the actor's parameters where the run kept
/// one (`ppo.evaluation_average`), else the actor itself.
pub fn evaluated_actor(checkpoint: &crate::run::Checkpoint) -> &'static str {
    if checkpoint.tensor(ppo_tensor_names::ACTOR_AVERAGE).is_some() {
        ppo_tensor_names::ACTOR_AVERAGE
    } else {
        ppo_tensor_names::ACTOR
    }
}
