//! One GPU's worker thread: it opens its device, builds its [`Trainer`] replica, then runs the
//! jobs the coordinating thread sends, one at a time, and answers each on the shared reply
//! channel. Leaving (the job channel closed, or a panic) drops the trainer and its graphs, and
//! says so on the reply channel, so that the coordinator never waits for a thread that is gone.

use std::any::Any;
use std::sync::Arc;
use std::sync::mpsc::{Receiver, Sender};
use std::thread::JoinHandle;

use crate::cuda::{Communicator, Gpu};
use crate::plan::PlanStore;

use super::super::trainer::{Trainer, TrainerConfig};
use super::super::trainer_error::TrainerError;
use crate::env::TrainMotion;

/// A job's answer, type-erased (the coordinator downcasts it to what it asked for).
pub(super) type Answer = Result<Box<dyn Any + Send>, TrainerError>;

/// Work for one replica.
pub(super) type Job = Box<dyn FnOnce(&mut Trainer) -> Answer + Send>;

/// The call number of the setup's answer (the first each worker sends).
pub(super) const SETUP_CALL: u64 = 0;

/// What a worker says on the reply channel.
pub(super) enum Reply {
    /// The answer to call `call`.
    Answer {
        rank: usize,
        call: u64,
        answer: Answer,
    },
    /// The worker left its loop (or panicked): it answers nothing more.
    Exited { rank: usize },
}

/// What the setup answers: facts about the replica the coordinator reports.
pub(super) struct Built {
    pub gemm: String,
    pub evaluation_steps: u32,
    pub gpu_name: String,
}

/// Everything a worker starts from (shared with the other workers).
pub(super) struct Start {
    pub config: Arc<TrainerConfig>,
    /// One clip, or a motion library (every GPU holds the whole library table).
    pub motion: Arc<TrainMotion>,
    pub store: Arc<PlanStore>,
}

/// The coordinator's handle on one worker.
pub(super) struct Worker {
    pub jobs: Option<Sender<(u64, Job)>>,
    pub thread: Option<JoinHandle<()>>,
}

/// Sends [`Reply::Exited`] when the worker's thread ends, however it ends.
struct ExitNotice {
    rank: usize,
    replies: Sender<Reply>,
}

impl Drop for ExitNotice {
    fn drop(&mut self) {
        let _ = self.replies.send(Reply::Exited { rank: self.rank });
    }
}

/// Starts the worker of `communicator`'s rank on its device.
pub(super) fn spawn(
    communicator: Communicator,
    start: &Start,
    replies: Sender<Reply>,
) -> Result<Worker, TrainerError> {
    let (jobs, inbox) = std::sync::mpsc::channel();
    let rank = communicator.rank();
    let start = Start {
        config: Arc::clone(&start.config),
        motion: Arc::clone(&start.motion),
        store: Arc::clone(&start.store),
    };
    let thread = std::thread::Builder::new()
        .name(format!("gpu{}-rank{rank}", communicator.device()))
        .spawn(move || run(communicator, start, inbox, replies))
        .map_err(|e| {
            TrainerError::Setup(format!("cannot start the thread of GPU rank {rank}: {e}"))
        })?;
    Ok(Worker {
        jobs: Some(jobs),
        thread: Some(thread),
    })
}

fn run(
    communicator: Communicator,
    start: Start,
    inbox: Receiver<(u64, Job)>,
    replies: Sender<Reply>,
) {
    let rank = communicator.rank();
    let _notice = ExitNotice {
        rank,
        replies: replies.clone(),
    };
    let built = Gpu::open(communicator.device())
        .map_err(TrainerError::from)
        .and_then(|gpu| {
            let trainer = Trainer::replica(
                &gpu,
                &start.store,
                start.motion.tracked(),
                &start.config,
                &communicator,
            )?;
            Ok((gpu, trainer))
        });
    let mut trainer = match built {
        Ok((gpu, trainer)) => {
            let facts = Built {
                gemm: trainer.gemm().describe(),
                evaluation_steps: trainer.evaluation_steps(),
                gpu_name: gpu.info().name.clone(),
            };
            let answer: Answer = Ok(Box::new(facts));
            if replies
                .send(Reply::Answer {
                    rank,
                    call: SETUP_CALL,
                    answer,
                })
                .is_err()
            {
                return;
            }
            trainer
        }
        Err(error) => {
            let _ = replies.send(Reply::Answer {
                rank,
                call: SETUP_CALL,
                answer: Err(error),
            });
            return;
        }
    };
    while let Ok((call, job)) = inbox.recv() {
        let answer = job(&mut trainer);
        if replies.send(Reply::Answer { rank, call, answer }).is_err() {
            break;
        }
    }
    // The trainer (its graphs) goes before this thread's communicator handle; the graphs hold
    // the communicator themselves, so NCCL destroys it only after them either way.
    drop(trainer);
}
