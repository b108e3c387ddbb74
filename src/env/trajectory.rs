//! Per-step records of a rollout's state, for watching it afterwards (`instantmimic replay`).
//!
//! A [`Trajectory`] holds, on the device, frame f of every env: `d.qpos`, `d.xpos`, `d.xquat`
//! and `ref_time` after f control steps (frame 0: the state the rollout starts from). The
//! rollout graph that records into it ([`crate::env::Rollout::capture_recorded`]) copies each
//! frame with four device-to-device copies per step, after the step's kinematics and the
//! reward (which advanced `ref_time` to the state's time) and before the masked reset (which
//! would replace an env that just ended); nothing waits for the host. [`Trajectory::download`]
//! brings the whole record over once, after the rollout.

use crate::cuda::{Gpu, Stream};

use crate::kernels::{DeviceArray, DeviceArray2, DeviceArray3, DeviceArray4, EnvError};

/// Frames of every env's state on the device: `[frames, envs, ...]`.
pub struct Trajectory {
    qpos: DeviceArray3<f32>,
    xpos: DeviceArray4<f32>,
    xquat: DeviceArray4<f32>,
    ref_time: DeviceArray2<f32>,
    /// The goal task's: each env's goal `[frames, envs, 2]` and counters `[frames, envs, 6]`
    /// (goals this episode among them) after the step's reward (None when tracking).
    goals: Option<(DeviceArray3<f32>, DeviceArray3<i32>)>,
}

impl Trajectory {
    /// Zeroed frames for `envs` envs of `nq` qpos values and `nbody` bodies (the world
    /// included, as in `d.xpos`).
    pub(super) fn zeros(
        gpu: &Gpu,
        frames: usize,
        envs: usize,
        nq: usize,
        nbody: usize,
    ) -> Result<Trajectory, EnvError> {
        Ok(Trajectory {
            qpos: DeviceArray::zeros(gpu, [frames, envs, nq])?,
            xpos: DeviceArray::zeros(gpu, [frames, envs, nbody, 3])?,
            xquat: DeviceArray::zeros(gpu, [frames, envs, nbody, 4])?,
            ref_time: DeviceArray::zeros(gpu, [frames, envs])?,
            goals: None,
        })
    }

    /// This record with the goal task's goals and counters (`counters` columns per env).
    pub(super) fn with_goals(mut self, gpu: &Gpu, counters: usize) -> Result<Trajectory, EnvError> {
        let [frames, envs] = self.ref_time.shape();
        self.goals = Some((
            DeviceArray::zeros(gpu, [frames, envs, 2])?,
            DeviceArray::zeros(gpu, [frames, envs, counters])?,
        ));
        Ok(self)
    }

    /// Whether it records the goal task's goals.
    pub fn has_goals(&self) -> bool {
        self.goals.is_some()
    }

    /// Queues the copies of frame `frame` of the goal task's goals `[envs, 2]` and counters
    /// `[envs, C]` (nothing when this record keeps none).
    pub(super) fn record_goals(
        &self,
        s: &Stream,
        frame: usize,
        goal: &DeviceArray2<f32>,
        counters: &DeviceArray2<i32>,
    ) -> Result<(), EnvError> {
        if let Some((goals, counts)) = &self.goals {
            goal.copy_into(s, goals, frame * goal.len())?;
            counters.copy_into(s, counts, frame * counters.len())?;
        }
        Ok(())
    }

    /// Frames it holds.
    pub fn frames(&self) -> usize {
        self.ref_time.shape()[0]
    }

    /// Queues the copies of frame `frame` from the physics buffers and the episode times (each
    /// `[envs, ...]` as the record's rows).
    pub(super) fn record_frame(
        &self,
        s: &Stream,
        frame: usize,
        qpos: &DeviceArray2<f32>,
        xpos: &DeviceArray3<f32>,
        xquat: &DeviceArray3<f32>,
        ref_time: &DeviceArray<f32>,
    ) -> Result<(), EnvError> {
        qpos.copy_into(s, &self.qpos, frame * qpos.len())?;
        xpos.copy_into(s, &self.xpos, frame * xpos.len())?;
        xquat.copy_into(s, &self.xquat, frame * xquat.len())?;
        ref_time.copy_into(s, &self.ref_time, frame * ref_time.len())?;
        Ok(())
    }

    /// Copies the record to the host (waits for the work queued before).
    pub fn download(&self) -> Result<TrajectoryFrames, EnvError> {
        let [frames, envs, nq] = self.qpos.shape();
        let nbody = self.xpos.shape()[2];
        Ok(TrajectoryFrames {
            frames,
            envs,
            nq,
            nbody,
            qpos: self.qpos.download()?,
            xpos: self.xpos.download()?,
            xquat: self.xquat.download()?,
            ref_time: self.ref_time.download()?,
            goals: match &self.goals {
                Some((goals, counters)) => {
                    Some((goals.download()?, counters.download()?, counters.shape()[2]))
                }
                None => None,
            },
        })
    }
}

/// A [`Trajectory`] on the host, row-major `[frames, envs, ...]`.
#[derive(Clone, Debug, PartialEq)]
pub struct TrajectoryFrames {
    frames: usize,
    envs: usize,
    nq: usize,
    /// Bodies, the world included.
    nbody: usize,
    qpos: Vec<f32>,
    xpos: Vec<f32>,
    xquat: Vec<f32>,
    ref_time: Vec<f32>,
    /// Goals `[frames, envs, 2]`, counters `[frames, envs, C]` and C (the goal task's).
    goals: Option<(Vec<f32>, Vec<i32>, usize)>,
}

impl TrajectoryFrames {
    pub fn frames(&self) -> usize {
        self.frames
    }

    pub fn envs(&self) -> usize {
        self.envs
    }

    /// Env `env`'s qpos at `frame`.
    pub fn qpos(&self, frame: usize, env: usize) -> &[f32] {
        let at = (frame * self.envs + env) * self.nq;
        &self.qpos[at..at + self.nq]
    }

    /// Env `env`'s body positions at `frame`, the world left out (`d.xpos[env, 1:]`).
    pub fn body_pos(&self, frame: usize, env: usize) -> &[f32] {
        let at = (frame * self.envs + env) * self.nbody * 3;
        &self.xpos[at + 3..at + self.nbody * 3]
    }

    /// Env `env`'s body orientations (w, x, y, z) at `frame`, the world left out.
    pub fn body_quat(&self, frame: usize, env: usize) -> &[f32] {
        let at = (frame * self.envs + env) * self.nbody * 4;
        &self.xquat[at + 4..at + self.nbody * 4]
    }

    /// The clip time (s) of env `env`'s state at `frame`.
    pub fn ref_time(&self, frame: usize, env: usize) -> f32 {
        self.ref_time[frame * self.envs + env]
    }

    /// Env `env`'s goal (world x, y) at `frame` (None when tracking).
    pub fn goal(&self, frame: usize, env: usize) -> Option<[f32; 2]> {
        let (goals, _, _) = self.goals.as_ref()?;
        let at = (frame * self.envs + env) * 2;
        Some([goals[at], goals[at + 1]])
    }

    /// Env `env`'s goals reached in its episode up to `frame` (None when tracking).
    pub fn goals_reached(&self, frame: usize, env: usize) -> Option<i32> {
        let (_, counters, columns) = self.goals.as_ref()?;
        let at = (frame * self.envs + env) * columns;
        Some(counters[at + crate::env::GoalCounter::GoalsThisEpisode as usize])
    }
}
