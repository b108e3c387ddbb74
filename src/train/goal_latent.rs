//! A goal run in a latent controller's action space (docs/goal.md, "The latent action space"):
//! the decoder `goal.decoder` (or `train --decoder`) names, loaded and checked against the run,
//! and the PPO head's shapes (its action is the latent residual). The decoder as the trainer
//! drives it, and the digest a resume checks, are `latent`'s ([`GoalDecoder`]).

use std::path::Path;

use super::character::check_trained_character;
use super::config::TrainConfig;
use super::error::TrainError;
use super::latent_setup::frozen_decoder_of;
use super::preflight::PolicyShapes;
use crate::env::ActionMode;
use crate::env::layout::JointLayout;
use crate::latent::{GoalDecoder, decoder_digest};
use crate::motion::Character;
use crate::nn::{LayerShape, mlp_layout};
use crate::run::checkpoint::Checkpoint;

/// The decoder `config`'s `goal.decoder` names (None without one: the action is the PD
/// target), checked against the run on `character`: a latent controller's checkpoint whose
/// decoder acts as this run's PD control expects (absolute targets, the same scale and control
/// rate) and reads columns the goal observation has. Every refusal is one line naming the file.
pub fn load_goal_decoder(
    config: &TrainConfig,
    character: &Character,
) -> Result<Option<GoalDecoder>, TrainError> {
    let Some(goal) = config.goal.as_ref().filter(|g| !g.decoder.is_empty()) else {
        return Ok(None);
    };
    let path = Path::new(&goal.decoder);
    let source = path.display().to_string();
    // Name the key: the path may have come from the config file or from --decoder.
    let checkpoint = Checkpoint::load(path)
        .map_err(|e| TrainError::Setup(format!("goal.decoder (train --decoder): {e}")))?;
    check_trained_character(&checkpoint, character)
        .map_err(|e| TrainError::Setup(format!("goal.decoder (train --decoder): {e}")))?;
    let trained = checkpoint.meta.config::<TrainConfig>(&source)?;
    let frozen = frozen_decoder_of(&checkpoint, &source)?;
    let refuse = |reason: String| Err(TrainError::Setup(format!("{source}: {reason}")));
    let (env, run_env) = (&trained.env, &config.env);
    if env.action_mode != ActionMode::Absolute {
        return refuse(
            "a decoder trained with env.action_mode = \"residual\" outputs offsets from a reference pose, which the goal task has none of (train the tracker and the latent controller with env.action_mode = \"absolute\")".to_owned(),
        );
    }
    if env.action_scale != run_env.action_scale {
        return refuse(format!(
            "a decoder trained with env.action_scale = {}; this run has {} (set env.action_scale = {})",
            env.action_scale, run_env.action_scale, env.action_scale
        ));
    }
    if env.substeps != run_env.substeps {
        return refuse(format!(
            "a decoder trained at {} physics steps per control step; this run has env.substeps = {}",
            env.substeps, run_env.substeps
        ));
    }
    let layout = JointLayout::for_character(character)?;
    let decoding = frozen.goal_decoding(&trained.obs, &config.obs, layout.observation_counts())?;
    let digest = decoder_digest(
        &frozen.decoder,
        &frozen.prior,
        frozen.proprio_columns.len(),
        frozen.latent_size,
        frozen.action_size,
    );
    Ok(Some(GoalDecoder {
        frozen,
        decoding,
        scale: goal.latent_action_scale,
        digest,
    }))
}

/// The PPO head's shapes of a goal run driving `decoder`: the goal observation in, the latent
/// residual out.
pub fn head_shapes(decoder: &GoalDecoder, config: &TrainConfig) -> PolicyShapes {
    let (d, l) = (
        decoder.decoding.observation_size,
        decoder.frozen.latent_size,
    );
    let end = |layers: Vec<LayerShape>| layers.last().map_or(0, LayerShape::end);
    PolicyShapes {
        observation_size: d,
        observation_counts: decoder.decoding.counts,
        action_size: l,
        actor_params: end(mlp_layout(d, &config.policy.actor_hidden, l)) + l,
        critic_params: end(mlp_layout(d, &config.policy.critic_hidden, 1)),
    }
}

/// `train --dry-run`'s lines of a goal run driving `decoder`: the three networks and the latent
/// size.
pub fn describe_decoder(decoder: &GoalDecoder, config: &TrainConfig) -> String {
    let f = &decoder.frozen;
    let hidden =
        |layers: &[LayerShape]| -> Vec<usize> { layers.iter().skip(1).map(|l| l.inputs).collect() };
    let head = head_shapes(decoder, config);
    let p = f.proprio_columns.len();
    let l = f.latent_size;
    format!(
        "decoder       {} (frozen, with its observation statistics): latent size {l}\n\
             networks      head (PPO) {} -> {:?} -> {l} (z = mu_prior + {} x action); prior {p} -> {:?} -> {}; decoder {p} + {l} -> {:?} -> {} (the PD targets)\n\
             observation   {} goal-observation columns feed the prior and decoder ({} of {} in its training observation)",
        f.source,
        head.observation_size,
        config.policy.actor_hidden,
        decoder.scale,
        hidden(&f.prior_layers),
        2 * l,
        hidden(&f.decoder_layers),
        f.action_size,
        p,
        p,
        f.observation_size,
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::latent::DECODER_DIGEST;
    use crate::latent::checkpoint::insert_latent_networks;
    use crate::run::CheckpointMeta;
    use crate::train::latent_setup::latent_shapes;

    fn repo(path: &str) -> std::path::PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR")).join(path)
    }

    /// A latent controller's checkpoint (absolute PD targets, parameters from `seed`) in `dir`.
    fn latent_checkpoint(dir: &Path, seed: u64) -> String {
        let mut config = TrainConfig::load(&repo("configs/latent/library.toml")).expect("valid");
        config.env.action_mode = ActionMode::Absolute;
        let character = Character::humanoid().expect("humanoid");
        let shapes = latent_shapes(&config, &PolicyShapes::new(&config, &character).unwrap())
            .expect("shapes");
        let (e, d, p) = shapes.initial_parameters(1.0, 0.01, seed);
        let n = shapes.observation_size;
        let mut c = Checkpoint::new(CheckpointMeta::new(&config, 3, 1.0, 10).expect("meta"));
        insert_latent_networks(
            &mut c,
            &shapes,
            [e, d, p],
            [vec![4.0, 4.0], vec![0.5; n], vec![8.0; n]],
        )
        .expect("inserted");
        let path = dir.join(format!("latent_{seed}.safetensors"));
        c.save(&path).expect("saved");
        path.display().to_string()
    }

    fn goal_config(decoder: &str) -> TrainConfig {
        let mut config =
            TrainConfig::load(&repo("configs/goal/reach_latent.toml")).expect("valid goal config");
        config.goal.as_mut().expect("[goal]").decoder = decoder.to_owned();
        config
    }

    #[test]
    fn a_run_checkpoint_must_record_the_decoder_it_drives() {
        let dir = tempfile::tempdir().expect("temp dir");
        let character = Character::humanoid().expect("humanoid");
        let first = latent_checkpoint(dir.path(), 1);
        let second = latent_checkpoint(dir.path(), 2);
        let config = goal_config(&first);
        let loaded = load_goal_decoder(&config, &character)
            .expect("fits")
            .expect("a decoder is named");
        let other = load_goal_decoder(&goal_config(&second), &character)
            .expect("fits")
            .expect("a decoder is named");
        assert_ne!(loaded.digest, other.digest);
        assert_eq!(&loaded.digest[2..], &[263, 64, 28]);
        // The head: the goal observation in, the latent residual out.
        let head = head_shapes(&loaded, &config);
        assert_eq!((head.observation_size, head.action_size), (266, 64));
        // The goal observation's decoder columns are normalized by the checkpoint's statistics,
        // the goal block by mean 0 and variance 1.
        assert_eq!(loaded.decoding.obs_mean[..263], [0.5; 263]);
        assert_eq!(loaded.decoding.obs_m2[263..], [4.0; 3]);

        let run_checkpoint = |digest: Option<[i32; 5]>| {
            let mut c = Checkpoint::new(CheckpointMeta::new(&config, 5, 1.0, 10).expect("meta"));
            if let Some(d) = digest {
                c.insert(DECODER_DIGEST, &[5], d.to_vec()).expect("digest");
            }
            let path = dir.path().join("iter_5.safetensors");
            c.save(&path).expect("saved");
            Checkpoint::load(&path).expect("loads")
        };
        loaded
            .check_checkpoint(&run_checkpoint(Some(loaded.digest)))
            .expect("its own decoder");
        for (digest, words) in [
            (Some(other.digest), ["another decoder", first.as_str()]),
            (None, ["records no latent decoder", first.as_str()]),
        ] {
            let e = loaded
                .check_checkpoint(&run_checkpoint(digest))
                .expect_err("refused")
                .to_string();
            assert!(
                e.contains("iter_5.safetensors: ") && !e.contains('\n'),
                "{e}"
            );
            for word in words {
                assert!(e.contains(word), "{e} lacks {word}");
            }
        }
        // No decoder named: the goal task's actions are PD targets.
        assert!(
            load_goal_decoder(&goal_config(""), &character)
                .expect("no decoder")
                .is_none()
        );
    }

    #[test]
    fn the_digest_changes_with_any_parameter_bit() {
        let decoder = vec![0.25f32; 10];
        let prior = vec![-1.0f32; 6];
        let digest = decoder_digest(&decoder, &prior, 3, 2, 4);
        let mut flipped = decoder.clone();
        flipped[7] = f32::from_bits(flipped[7].to_bits() ^ 1);
        assert_ne!(decoder_digest(&flipped, &prior, 3, 2, 4), digest);
        assert_ne!(decoder_digest(&decoder, &prior, 3, 3, 4), digest);
        assert_eq!(decoder_digest(&decoder, &prior, 3, 2, 4), digest);
    }

    #[test]
    fn the_committed_latent_goal_config_is_reach_with_its_latent_keys() {
        let latent = TrainConfig::load(&repo("configs/goal/reach_latent.toml")).expect("valid");
        let reach = TrainConfig::load(&repo("configs/goal/reach.toml")).expect("valid");
        let (g, r) = (latent.goal.clone().unwrap(), reach.goal.clone().unwrap());
        assert!(g.decoder.is_empty(), "no decoder is committed");
        assert_eq!(g.latent_action_scale, 3.0);
        // The task is reach.toml's; only the action space's keys differ.
        assert_eq!(
            (g.episode_s, g.min_distance, g.max_distance, g.reach_radius),
            (r.episode_s, r.min_distance, r.max_distance, r.reach_radius)
        );
        assert_eq!(latent.obs, reach.obs);
        assert_eq!(latent.ppo, reach.ppo);
        assert_eq!(latent.motion_library, reach.motion_library);
        assert_eq!(latent.policy.init_log_std, -0.5);
        assert_eq!(latent.env.action_scale, 0.875);
        // A bad latent action scale is refused with its key.
        let mut bad = latent.clone();
        bad.goal.as_mut().unwrap().latent_action_scale = 0.0;
        let e = bad
            .validate("reach_latent.toml")
            .expect_err("refused")
            .to_string();
        assert!(e.contains("goal.latent_action_scale"), "{e}");
    }
}
