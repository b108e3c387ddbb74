//! Recording a rollout for a replay (src/replay/): every env's state at each frame into a
//! [`Trajectory`], and the reference rows the kernels looked up.

use super::{Rollout, RolloutError};
use crate::cuda::{Graph, Stream};
use crate::env::policy::RolloutPolicy;
use crate::env::stages::StageRecorder;
use crate::env::task::Task;
use crate::env::trajectory::Trajectory;
use crate::kernels::DeviceArray;

impl Rollout {
    /// An empty record of every env's state for each of this rollout's frames: the state it
    /// starts from and the one after each control step.
    pub fn new_trajectory(&self) -> Result<Trajectory, RolloutError> {
        let sizes = self.physics.sizes;
        let trajectory = Trajectory::zeros(
            &self.gpu,
            self.horizon + 1,
            self.num_envs,
            sizes.nq,
            sizes.nbody,
        )?;
        // The goal task's record keeps each frame's goal and goals reached too.
        Ok(match &self.task {
            Task::Goal(goal) => trajectory.with_goals(&self.gpu, goal.counters.shape()[1])?,
            Task::Tracking(_) => trajectory,
        })
    }

    /// Captures the rollout into a graph that also copies every env's state into
    /// `trajectory` (from [`Rollout::new_trajectory`]) at the start and after every control
    /// step, before the reset. The graph writes into `trajectory` and `policy` at each launch:
    /// keep them alive as long as the graph.
    pub fn capture_recorded(
        &self,
        policy: &dyn RolloutPolicy,
        trajectory: &Trajectory,
    ) -> Result<Graph, RolloutError> {
        if trajectory.frames() != self.horizon + 1 {
            return Err(RolloutError::Setup(format!(
                "a record of {} frames for a rollout of {} steps (make it with Rollout::new_trajectory)",
                trajectory.frames(),
                self.horizon
            )));
        }
        let stream = self.gpu.stream();
        let graph = stream.capture(|s| {
            self.record_rollout(
                s,
                policy,
                &mut StageRecorder::untimed(),
                Some(trajectory),
                0..self.horizon,
                0,
            )
        })?;
        graph.upload(stream)?;
        Ok(graph)
    }

    /// The reference rows of clips `clips` at their times `times` (s), `[times.len(), stride]`
    /// row-major, as the env kernels see them (`lookup_reference`); waits for the GPU.
    pub fn reference_rows(&self, clips: &[i32], times: &[f32]) -> Result<Vec<f32>, RolloutError> {
        if times.is_empty() {
            return Ok(Vec::new());
        }
        let device_clips = DeviceArray::from_slice(&self.gpu, [clips.len()], clips)?;
        let device_times = DeviceArray::from_slice(&self.gpu, [times.len()], times)?;
        let rows = DeviceArray::zeros(&self.gpu, [times.len(), self.table.stride()])?;
        self.table.lookup(
            &self.kernels,
            self.gpu.stream(),
            &device_clips,
            &device_times,
            &rows,
        )?;
        Ok(rows.download()?)
    }

    /// Frame `frame` of `trajectory`: the physics state and the episode times as they are now.
    pub(super) fn record_frame(
        &self,
        s: &Stream,
        trajectory: &Trajectory,
        frame: usize,
    ) -> Result<(), RolloutError> {
        let p = &self.physics;
        trajectory.record_frame(s, frame, &p.qpos, &p.xpos, &p.xquat, &self.state.ref_time)?;
        if let Task::Goal(goal) = &self.task {
            trajectory.record_goals(s, frame, &goal.goal, &goal.counters)?;
        }
        Ok(())
    }
}
