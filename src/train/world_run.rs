//! `train` as one rank of a world of processes (docs/train.md, "Several processes"): one
//! process per GPU, on one host or several, launched by torchrun, Slurm or by hand. Rank 0
//! opens the run directory (new or resumed), hosts the rendezvous and hands every other rank
//! NCCL's world id and the checkpoint it resumes from; every rank then builds its replica on
//! its GPU at the same time, and the ranks train in step ([`RankReplica`]): rank 0 runs the
//! harness (evaluation, checkpoints, metrics) and the others follow it.

use std::time::Duration;

use super::config::TrainConfig;
use super::error::TrainError;
use super::gpu_loop::{RunStart, TrainSetup, library_note};
use super::ppo_trainer::trainer_config;
use crate::cuda::{Communicator, Gpu, nccl_version};
use crate::env::{TrackedMotion, training_solver_note};
use crate::ppo::{Followed, RankReplica, Trainer, TrainerConfig};
use crate::run::{Checkpoint, RunDir, RunSummary, Scorer, run_loop};
use crate::world::{Control, Host, Watch, WorldError, WorldSpec, join};

/// NCCL's world id: the first bytes of what rank 0 hands the others.
const WORLD_ID_BYTES: usize = 128;

/// A world of processes as `train` runs in it.
#[derive(Clone, Debug)]
pub struct WorldRun {
    pub spec: WorldSpec,
    /// How long a rank waits for the others: to join, and at every step (rank 0's evaluations
    /// and checkpoints between iterations included).
    pub timeout: Duration,
}

/// How this rank's part ended.
#[derive(Debug)]
pub enum RankOutcome {
    /// Rank 0: the run's summary (as a single process's run).
    Leader(Box<RunSummary>),
    /// Any other rank: the iterations it ran beside rank 0.
    Follower(Followed),
}

/// The fingerprint every rank's configuration must share: CRC-32 of the resolved configuration
/// and of this build's version, so that ranks of other settings or builds are refused at the
/// rendezvous instead of training apart.
pub fn world_fingerprint(config: &TrainConfig) -> Result<u64, TrainError> {
    let text = config.to_toml()?;
    let version = env!("CARGO_PKG_VERSION");
    Ok(u64::from(crc32fast::hash(text.as_bytes())) << 32
        | u64::from(crc32fast::hash(version.as_bytes())))
}

/// Refuses what a world of processes does not train (one line, the key named).
pub fn check_world_config(config: &TrainConfig) -> Result<(), TrainError> {
    let refuse = |what: &str| {
        Err(TrainError::Setup(format!(
            "{what} trains in one process; a world of processes (--rank, torchrun, Slurm) trains the PPO tracker"
        )))
    };
    if config.latent.is_some() {
        return refuse("[latent] (the latent controller)");
    }
    if let Some(section) = config.task_sections().section() {
        return refuse(&format!("[{section}] (a task policy)"));
    }
    if !config.run.gpus.is_empty() {
        return Err(TrainError::Setup(
            "run.gpus (--gpus) names the GPUs of one process; in a world of processes each rank takes its GPU from LOCAL_RANK (--local-rank): leave run.gpus out".to_owned(),
        ));
    }
    Ok(())
}

/// This rank's part of the run `setup` describes.
pub fn train_as_rank(setup: &TrainSetup, world: &WorldRun) -> Result<RankOutcome, TrainError> {
    check_world_config(&setup.config)?;
    let spec = &world.spec;
    let fingerprint = world_fingerprint(&setup.config)?;
    let motion = setup.motion.tracked();
    if spec.is_leader() {
        lead(setup, world, fingerprint, motion).map(|s| RankOutcome::Leader(Box::new(s)))
    } else {
        follow(setup, world, fingerprint, motion).map(RankOutcome::Follower)
    }
}

fn lead(
    setup: &TrainSetup,
    world: &WorldRun,
    fingerprint: u64,
    motion: TrackedMotion<'_>,
) -> Result<RunSummary, TrainError> {
    let spec = &world.spec;
    // The port first: a port in use is the first thing to say.
    let host = Host::bind(spec.rendezvous.port)?;
    // The world forms before the run directory is touched: a world that does not form leaves
    // nothing to clean up. The checkpoint a resume continues from is read-only until then.
    let resume = match &setup.start {
        RunStart::New { .. } => None,
        RunStart::Resume { root } => RunDir::inspect_resume::<TrainConfig>(root)?
            .checkpoint
            .map(|(path, _)| path.display().to_string()),
    };
    let world_id = Communicator::new_world_id()?;
    eprintln!(
        "world of {} processes: rank 0 waits for the others on port {} (at most {} s)",
        spec.size,
        host.port(),
        world.timeout.as_secs()
    );
    let control = host.gather(
        spec.size,
        fingerprint,
        &shared_bytes(&world_id, resume.as_deref()),
        world.timeout,
    )?;
    let (session, checkpoint) =
        setup.open_session_after("the world's rendezvous", motion.character())?;
    let opened = checkpoint.as_ref().map(|c| c.source().to_owned());
    let file = |p: &Option<String>| {
        p.as_ref()
            .and_then(|p| std::path::Path::new(p).file_name().map(|f| f.to_owned()))
    };
    if file(&opened) != file(&resume) {
        // The run directory changed between the inspection and its opening.
        return Err(TrainError::Setup(format!(
            "the run directory's newest checkpoint changed while the world formed ({} then {}): resume again",
            resume.as_deref().unwrap_or("none"),
            opened.as_deref().unwrap_or("none")
        )));
    }
    let gpu = Gpu::open(rank_device(spec)?)?;
    let communicator = Communicator::join_world(&gpu, spec.size, 0, &world_id)?;
    let config = trainer_config(session.config(), motion.character())?;
    let (trainer, watch) =
        watched_replica(&gpu, setup, motion, &config, &communicator, &control, world)?;
    let mut notes = vec![format!("GEMMs: {} (every rank)", trainer.gemm().describe())];
    notes.extend(training_solver_note(&setup.store, &config.rollout.env)?);
    if let Ok((version, library)) = nccl_version() {
        notes.push(format!(
            "world of {} processes ({}): {} envs each, {} in all; NCCL {version} ({library}); rank 0 on GPU {}",
            spec.size,
            gpu.info().name,
            setup.config.env.num_envs,
            u64::from(setup.config.env.num_envs) * spec.size as u64,
            gpu.info().ordinal
        ));
    }
    let scorer = Scorer::new(
        trainer.evaluation_rollout().0,
        motion,
        &session.config().run,
        false,
    )?;
    if let Scorer::Library(plan) = &scorer {
        notes.push(library_note(plan));
    }
    let mut replica = RankReplica::new(trainer, control, watch, world.timeout, setup.stop.clone());
    let result = run_loop(session, &mut replica, checkpoint, &scorer, notes);
    match &result {
        Ok(_) => replica.finish(None)?,
        Err(e) => replica.finish(Some(&e.to_string()))?,
    }
    Ok(result?)
}

fn follow(
    setup: &TrainSetup,
    world: &WorldRun,
    fingerprint: u64,
    motion: TrackedMotion<'_>,
) -> Result<Followed, TrainError> {
    let spec = &world.spec;
    eprintln!(
        "rank {} of {}: joining rank 0 at {} (at most {} s)",
        spec.rank,
        spec.size,
        spec.rendezvous,
        world.timeout.as_secs()
    );
    let (shared, control) = join(
        &spec.rendezvous,
        spec.size,
        spec.rank,
        fingerprint,
        world.timeout,
    )?;
    let (world_id, resume) = parse_shared(&shared)?;
    let gpu = Gpu::open(rank_device(spec)?)?;
    let communicator = Communicator::join_world(&gpu, spec.size, spec.rank, world_id)?;
    let config = trainer_config(&setup.config, motion.character())?;
    let (trainer, watch) =
        watched_replica(&gpu, setup, motion, &config, &communicator, &control, world)?;
    let mut replica = RankReplica::new(trainer, control, watch, world.timeout, setup.stop.clone());
    if let Some(path) = resume {
        // Rank 0's checkpoint, on a file system every rank sees.
        let checkpoint = Checkpoint::load(std::path::Path::new(&path)).map_err(|e| {
            TrainError::Setup(format!(
                "rank {} resumes from rank 0's checkpoint, which it cannot read ({e}): every rank needs the run directory on a shared file system",
                spec.rank
            ))
        })?;
        replica.restore(&checkpoint)?;
    }
    eprintln!(
        "rank {} of {} on GPU {} ({}): following rank 0",
        spec.rank,
        spec.size,
        gpu.info().ordinal,
        gpu.info().name
    );
    let followed = replica.follow()?;
    eprintln!(
        "rank {} of {}: rank 0 stopped the run after {} iterations",
        spec.rank, spec.size, followed.iterations
    );
    Ok(followed)
}

/// This rank's replica, built while the watch over the world's connections is on (building it
/// runs NCCL's first collectives), and the watch, which aborts `communicator` when a peer is lost
/// while this rank waits for its GPU.
fn watched_replica(
    gpu: &Gpu,
    setup: &TrainSetup,
    motion: TrackedMotion<'_>,
    config: &TrainerConfig,
    communicator: &Communicator,
    control: &Control,
    world: &WorldRun,
) -> Result<(Trainer, Watch), TrainError> {
    let aborted = communicator.clone();
    let watch = Watch::start(control, world.timeout, move || aborted.abort())?;
    watch.enter();
    let trainer = Trainer::replica(gpu, &setup.store, motion, config, communicator);
    if let Some(verdict) = watch.leave() {
        return Err(verdict.into());
    }
    Ok((trainer?, watch))
}

/// This rank's CUDA device: `LOCAL_RANK` among the GPUs it sees, or the one it sees (a
/// launcher that gives each process one GPU, e.g. Slurm's `--gpus-per-task=1`).
fn rank_device(spec: &WorldSpec) -> Result<usize, TrainError> {
    let count = Gpu::device_count()?;
    match count {
        1 => Ok(0),
        n if spec.local_rank < n => Ok(spec.local_rank),
        n => Err(TrainError::Setup(format!(
            "rank {} has local rank {} but sees {n} GPUs (CUDA_VISIBLE_DEVICES): give each process of a host its own local rank below {n}",
            spec.rank, spec.local_rank
        ))),
    }
}

/// What rank 0 hands the others: NCCL's world id, then the path of the checkpoint it resumes
/// from (empty for a new run).
fn shared_bytes(world_id: &[u8], resume: Option<&str>) -> Vec<u8> {
    let mut bytes = world_id.to_vec();
    bytes.extend_from_slice(resume.unwrap_or("").as_bytes());
    bytes
}

fn parse_shared(bytes: &[u8]) -> Result<(&[u8], Option<String>), TrainError> {
    if bytes.len() < WORLD_ID_BYTES {
        return Err(TrainError::World(WorldError::Protocol(format!(
            "rank 0 sent {} bytes, fewer than NCCL's world id",
            bytes.len()
        ))));
    }
    let (id, path) = bytes.split_at(WORLD_ID_BYTES);
    let path = String::from_utf8(path.to_vec()).map_err(|_| {
        TrainError::World(WorldError::Protocol(
            "rank 0's checkpoint path is not UTF-8".to_owned(),
        ))
    })?;
    Ok((id, (!path.is_empty()).then_some(path)))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_shared_bytes_carry_the_world_id_and_the_resume_path() {
        let id = vec![7u8; WORLD_ID_BYTES];
        let bytes = shared_bytes(&id, Some("runs/a/iter_5.safetensors"));
        let (got, path) = parse_shared(&bytes).expect("parses");
        assert_eq!(
            (got, path.as_deref()),
            (&id[..], Some("runs/a/iter_5.safetensors"))
        );
        let (_, path) = parse_shared(&shared_bytes(&id, None)).expect("parses");
        assert_eq!(path, None);
        assert!(parse_shared(&id[..100]).is_err());
    }

    #[test]
    fn the_fingerprint_follows_the_configuration() {
        let a = TrainConfig::with_motion("walk");
        let mut b = a.clone();
        assert_eq!(
            world_fingerprint(&a).unwrap(),
            world_fingerprint(&b).unwrap()
        );
        b.ppo.clip = 0.3;
        assert_ne!(
            world_fingerprint(&a).unwrap(),
            world_fingerprint(&b).unwrap()
        );
    }

    #[test]
    fn a_world_refuses_what_trains_in_one_process() {
        let mut c = TrainConfig::with_motion("walk");
        assert!(check_world_config(&c).is_ok());
        c.run.gpus = vec![0, 1];
        let e = check_world_config(&c).expect_err("refused").to_string();
        assert!(e.contains("leave run.gpus out"), "{e}");
        c.run.gpus.clear();
        c.goal = Some(crate::env::GoalConfig::default());
        let e = check_world_config(&c).expect_err("refused").to_string();
        assert!(e.contains("[goal]"), "{e}");
    }
}
