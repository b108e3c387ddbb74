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
        })
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
}
