//! The Gaussian MLP actor and the MLP critic on the GPU (docs/env.md, "Policy").
//!
//! Each network is an `nn::mlp::Mlp`: one flat `f32` device buffer of parameters, laid out layer
//! by layer as `w [in, out]` row-major then `b [out]`; the actor's buffer ends with the
//! state-independent `log_std [A]`. The forward pass runs as `policy.gemm` says
//! ([`PolicyGemm`]), queued on a stream only: it records into a CUDA graph like any other
//! launch.

use rand::SeedableRng;
use rand::rngs::StdRng;
use thiserror::Error;

use crate::cuda::{Gpu, Stream};
use crate::env::{ActStorage, Rollout, RolloutError, RolloutPolicy};
use crate::kernels::{DeviceArray, DeviceArray2, EnvError, EnvKernels};
use crate::nn::mlp::Mlp;
use crate::nn::{LayerShape, NnError, PolicyGemm, initial_parameters, mlp_layout};

use super::config::PolicyConfig;

/// Why the policy cannot be built or run: its own shape checks, or the networks'.
#[derive(Debug, Error)]
pub enum PolicyError {
    #[error(transparent)]
    Env(#[from] EnvError),
    #[error(transparent)]
    Nn(#[from] NnError),
    #[error("policy: {0}")]
    Shape(String),
}

/// The rollout's policy: actor (mean and log std) and critic, for a batch of envs.
pub struct GaussianPolicy {
    actor_shapes: Vec<LayerShape>,
    critic_shapes: Vec<LayerShape>,
    actor: Mlp,
    critic: Mlp,
    log_std: DeviceArray<f32>,
    gemm: PolicyGemm,
    observation_size: usize,
    action_size: usize,
    batch: usize,
    seed: i32,
}

impl GaussianPolicy {
    /// A freshly initialized policy for `observation_size` inputs and `action_size` actions,
    /// with activations for `batch` envs; `seed` seeds the initialization and the sampling.
    /// Its GEMMs run as `config.gemm` says (an error when it asks for cuBLAS and libcublas
    /// cannot be loaded).
    pub fn new(
        gpu: &Gpu,
        config: &PolicyConfig,
        observation_size: usize,
        action_size: usize,
        batch: usize,
        seed: u64,
    ) -> Result<GaussianPolicy, PolicyError> {
        let gemm = PolicyGemm::open(gpu, config.gemm).map_err(EnvError::from)?;
        GaussianPolicy::with_gemm(
            gpu,
            config,
            observation_size,
            action_size,
            batch,
            seed,
            gemm,
        )
    }

    /// [`GaussianPolicy::new`] with its GEMMs already opened (`PolicyGemm::open` of
    /// `config.gemm`): a trainer opens them while its rollout loads.
    pub fn with_gemm(
        gpu: &Gpu,
        config: &PolicyConfig,
        observation_size: usize,
        action_size: usize,
        batch: usize,
        seed: u64,
        gemm: PolicyGemm,
    ) -> Result<GaussianPolicy, PolicyError> {
        if observation_size == 0 || action_size == 0 || batch == 0 {
            return Err(PolicyError::Shape(format!(
                "observation size {observation_size}, action size {action_size} and batch {batch} must be positive"
            )));
        }
        let actor_shapes = mlp_layout(observation_size, &config.actor_hidden, action_size);
        let critic_shapes = mlp_layout(observation_size, &config.critic_hidden, 1);
        let mut rng = StdRng::seed_from_u64(seed);
        let hidden_gain = f64::from(config.init_hidden_gain);
        let mut actor_values = initial_parameters(
            &actor_shapes,
            hidden_gain,
            f64::from(config.init_output_gain),
            &mut rng,
        );
        let log_std_offset = actor_values.len();
        actor_values.extend(std::iter::repeat_n(config.init_log_std, action_size));
        let critic_values = initial_parameters(&critic_shapes, hidden_gain, 1.0, &mut rng);

        let actor_params = DeviceArray::from_slice(gpu, [actor_values.len()], &actor_values)?;
        let critic_params = DeviceArray::from_slice(gpu, [critic_values.len()], &critic_values)?;
        let log_std = actor_params.view(log_std_offset, [action_size])?;
        Ok(GaussianPolicy {
            actor: Mlp::new(gpu, &actor_shapes, actor_params, batch, gemm.clone())?,
            critic: Mlp::new(gpu, &critic_shapes, critic_params, batch, gemm.clone())?,
            actor_shapes,
            critic_shapes,
            log_std,
            gemm,
            observation_size,
            action_size,
            batch,
            seed: sampling_seed(seed),
        })
    }

    /// A freshly initialized policy sized for `rollout`: its observations, actions and envs.
    pub fn for_rollout(
        gpu: &Gpu,
        config: &PolicyConfig,
        rollout: &Rollout,
        seed: u64,
    ) -> Result<GaussianPolicy, PolicyError> {
        GaussianPolicy::new(
            gpu,
            config,
            rollout.observation_size(),
            rollout.action_size(),
            rollout.num_envs(),
            seed,
        )
    }

    /// This policy with its action sampling keyed by `seed` instead of the one it was
    /// initialized with: on several GPUs every replica starts from the run's parameters but
    /// samples its own noise.
    pub fn with_sampling_seed(mut self, seed: u64) -> GaussianPolicy {
        self.seed = sampling_seed(seed);
        self
    }

    /// The same networks (parameters shared, not copied: updates to this policy's parameters
    /// are seen by both) with activations for `batch` envs, e.g. the evaluation's 32.
    pub fn with_batch(&self, gpu: &Gpu, batch: usize) -> Result<GaussianPolicy, PolicyError> {
        self.with_batch_reading(gpu, batch, &self.actor.params)
    }

    /// [`GaussianPolicy::with_batch`] with the actor reading `actor_params` (the same layout,
    /// e.g. an average of this policy's; shared, not copied) instead of this policy's.
    pub fn with_batch_reading(
        &self,
        gpu: &Gpu,
        batch: usize,
        actor_params: &DeviceArray<f32>,
    ) -> Result<GaussianPolicy, PolicyError> {
        if batch == 0 {
            return Err(PolicyError::Shape("batch must be positive".to_owned()));
        }
        if actor_params.len() != self.actor.params.len() {
            return Err(PolicyError::Shape(format!(
                "{} actor parameters for an actor of {}",
                actor_params.len(),
                self.actor.params.len()
            )));
        }
        let share = |a: &DeviceArray<f32>| a.view(0, [a.len()]);
        let actor_params = share(actor_params)?;
        let log_std = actor_params.view(
            self.actor_shapes.last().map_or(0, LayerShape::end),
            [self.action_size],
        )?;
        let gemm = || self.gemm.clone();
        Ok(GaussianPolicy {
            actor: Mlp::new(gpu, &self.actor_shapes, actor_params, batch, gemm())?,
            critic: Mlp::new(
                gpu,
                &self.critic_shapes,
                share(&self.critic.params)?,
                batch,
                gemm(),
            )?,
            actor_shapes: self.actor_shapes.clone(),
            critic_shapes: self.critic_shapes.clone(),
            log_std,
            gemm: self.gemm.clone(),
            observation_size: self.observation_size,
            action_size: self.action_size,
            batch,
            seed: self.seed,
        })
    }

    /// What computes the GEMMs (shared by [`GaussianPolicy::with_batch`] copies and the
    /// update).
    pub fn gemm(&self) -> &PolicyGemm {
        &self.gemm
    }

    pub fn actor_layers(&self) -> &[LayerShape] {
        &self.actor_shapes
    }

    pub fn critic_layers(&self) -> &[LayerShape] {
        &self.critic_shapes
    }

    /// The actor's flat parameters (layers, then log std) and the critic's.
    pub fn actor_parameters(&self) -> &DeviceArray<f32> {
        &self.actor.params
    }

    pub fn critic_parameters(&self) -> &DeviceArray<f32> {
        &self.critic.params
    }

    /// The actor's mean actions and the critic's values `[batch, 1]` of the last forward pass.
    pub fn mean(&self) -> &DeviceArray2<f32> {
        self.actor.output()
    }

    pub fn value(&self) -> &DeviceArray2<f32> {
        self.critic.output()
    }

    pub fn batch(&self) -> usize {
        self.batch
    }

    pub fn observation_size(&self) -> usize {
        self.observation_size
    }

    pub fn action_size(&self) -> usize {
        self.action_size
    }

    /// The state-independent log standard deviation `[A]`: a view of the end of the actor's
    /// parameters.
    pub fn log_std(&self) -> &DeviceArray<f32> {
        &self.log_std
    }

    /// Queues the actor and critic forward passes of `obs` (`[batch, observation size]`).
    pub fn record_forward(
        &self,
        kernels: &EnvKernels,
        stream: &Stream,
        obs: &DeviceArray2<f32>,
    ) -> Result<(), PolicyError> {
        self.check_observations(obs)?;
        self.actor.record(kernels, stream, obs)?;
        self.critic.record(kernels, stream, obs)?;
        Ok(())
    }

    fn check_observations(&self, obs: &DeviceArray2<f32>) -> Result<(), PolicyError> {
        if obs.shape() != [self.batch, self.observation_size] {
            return Err(PolicyError::Shape(format!(
                "observations of shape {:?}, expected [{}, {}]",
                obs.shape(),
                self.batch,
                self.observation_size
            )));
        }
        Ok(())
    }
}

/// The rollout runs the actor (and, unless the update values the batch, the critic) and samples
/// from the Gaussian.
impl RolloutPolicy for GaussianPolicy {
    fn batch(&self) -> usize {
        self.batch
    }

    fn observation_size(&self) -> usize {
        self.observation_size
    }

    fn action_size(&self) -> usize {
        self.action_size
    }

    /// Forward of `obs`, then actions sampled into `actions` (`[batch, A]`) and stored with
    /// their log-probabilities and the values in row t of the storage.
    fn record_act(
        &self,
        kernels: &EnvKernels,
        stream: &Stream,
        obs: &DeviceArray2<f32>,
        actions: &DeviceArray2<f32>,
        storage: &ActStorage<'_>,
        iteration: &DeviceArray<i32>,
        t: usize,
        deterministic: bool,
    ) -> Result<(), RolloutError> {
        if storage.values_in_update {
            self.check_observations(obs)?;
            self.actor
                .record(kernels, stream, obs)
                .map_err(PolicyError::from)?;
        } else {
            self.record_forward(kernels, stream, obs)?;
        }
        let [horizon, n, a] = storage.actions.shape();
        if n != self.batch || a != self.action_size || actions.shape() != [n, a] || t >= horizon {
            return Err(RolloutError::from(PolicyError::Shape(format!(
                "storage {:?} and actions {:?} for step {t}, expected [T > {t}, {}, {}]",
                storage.actions.shape(),
                actions.shape(),
                self.batch,
                self.action_size
            ))));
        }
        kernels.gaussian_sample(
            stream,
            self.batch,
            self.mean(),
            &self.log_std,
            self.value(),
            iteration,
            t as i32,
            horizon as i32,
            self.seed,
            i32::from(deterministic),
            actions,
            storage.actions,
            storage.log_probs,
            storage.values,
            storage.means,
        )?;
        Ok(())
    }
}

/// The sampling kernel's int seed for a run's u64 seed (the halves xor-ed).
fn sampling_seed(seed: u64) -> i32 {
    (seed ^ (seed >> 32)) as u32 as i32
}

/// A policy error inside the rollout (the rollout knows policies only through
/// [`RolloutPolicy`]).
impl From<PolicyError> for RolloutError {
    fn from(e: PolicyError) -> Self {
        RolloutError::Policy(Box::new(e))
    }
}
