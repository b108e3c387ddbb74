//! The env kernels' launches of one control step (docs/env.md, "One control step of the rollout
//! graph"): each passes the reference table with its clip index and every env's clip id, so a
//! single clip (the library of one) and a motion library run the same launches.

use crate::cuda::Stream;
use crate::kernels::Yardstick;
use crate::plan::KINEMATICS_PLAN;

use super::super::evaluation::EpisodeScores;
use super::super::storage::RolloutStorage;
use super::super::task::Task;
use super::groups::ResetRows;
use super::{Rollout, RolloutError, reset_rows};
use crate::env::config::ActionMode;
use crate::env::layout::{TRACKING_LANES, observe_threads_per_env};

impl Rollout {
    pub(super) fn record_scores(
        &self,
        s: &Stream,
        storage: &RolloutStorage,
        scores: &EpisodeScores,
        yardstick: &Yardstick,
        t: i32,
    ) -> Result<(), RolloutError> {
        let p = &self.physics;
        self.kernels.evaluation_accumulate(
            s,
            self.num_envs,
            &p.qpos,
            &p.xpos,
            &p.xquat,
            self.table.table(),
            self.table.layout(),
            self.table.clip_offsets(),
            &self.joints.end_effectors,
            &self.joints.tracked_bodies,
            self.joints.anchor,
            &self.state.clip_id,
            &self.state.ref_time,
            t,
            &storage.rewards,
            &storage.terminated,
            &storage.truncated,
            yardstick,
            &scores.clip_steps,
            &scores.status,
            &scores.steps,
            &scores.sums,
            &scores.robotics_terminated,
        )?;
        Ok(())
    }

    /// The PD targets of this control step's actions (once per control step: the actions and
    /// the reference time hold over its substeps).
    pub(super) fn record_pd_targets(&self, s: &Stream) -> Result<(), RolloutError> {
        let j = &self.joints;
        self.kernels.pd_targets(
            s,
            self.num_envs * j.num_joints,
            &self.state.actions,
            &j.kind,
            &j.qpos,
            &j.dof,
            &j.scale,
            &j.center,
            self.table.table(),
            self.table.clip_offsets(),
            &self.state.clip_id,
            &self.state.ref_time,
            // The targets are the pose at the end of this control step (the reward's time).
            self.control_dt as f32,
            i32::from(self.action_mode == ActionMode::Residual),
            self.action_scale,
            &self.state.pd_targets,
        )?;
        Ok(())
    }

    /// The torques of one substep, from the targets [`Rollout::record_pd_targets`] left.
    pub(super) fn record_pd_control(&self, s: &Stream) -> Result<(), RolloutError> {
        let j = &self.joints;
        self.kernels.pd_control(
            s,
            self.num_envs * j.num_joints,
            &self.state.pd_targets,
            &self.physics.qpos,
            &self.physics.qvel,
            &self.physics.dof_damping,
            &j.kind,
            &j.qpos,
            &j.dof,
            &j.kp,
            &j.limit,
            &self.physics.ctrl,
        )?;
        Ok(())
    }

    pub(super) fn record_reward(
        &self,
        s: &Stream,
        storage: &RolloutStorage,
        t: i32,
    ) -> Result<(), RolloutError> {
        let (p, st) = (&self.physics, &self.state);
        let tracking = match &self.task {
            Task::Tracking(tracking) => tracking,
            Task::Goal(goal) => {
                self.kernels.goal_reward_termination(
                    s,
                    self.num_envs,
                    &p.qpos,
                    &goal.params,
                    t,
                    &self.phase_statistics.iteration,
                    &st.episode_step,
                    &goal.goal,
                    &goal.distance,
                    &storage.rewards,
                    &storage.terminated,
                    &storage.truncated,
                    &st.done,
                    &st.failure,
                    &goal.counters,
                )?;
                return Ok(());
            }
        };
        self.kernels.tracking_error_sums(
            s,
            self.num_envs * TRACKING_LANES,
            &p.qpos,
            &p.qvel,
            &p.xpos,
            &p.xquat,
            self.table.table(),
            self.table.layout(),
            self.table.clip_offsets(),
            &self.joints.kind,
            &self.joints.qpos,
            &self.joints.end_effectors,
            &self.joints.tracked_bodies,
            tracking,
            &st.clip_id,
            &st.ref_time,
            &st.error_sums,
        )?;
        self.kernels.reward_termination(
            s,
            self.num_envs,
            &p.qpos,
            &p.qvel,
            &p.subtree_com,
            &st.error_sums,
            self.table.table(),
            self.table.layout(),
            self.table.clip_offsets(),
            &self.joints.kind,
            &self.joints.end_effectors,
            &self.joints.tracked_bodies,
            tracking,
            t,
            &st.clip_id,
            &st.ref_time,
            &st.episode_step,
            &storage.rewards,
            &storage.terminated,
            &storage.truncated,
            &st.done,
            &st.failure,
            &st.errors,
            &self.phase_statistics.visits,
            &self.phase_statistics.failures,
        )?;
        Ok(())
    }

    /// The masked reset of step `t`; the body kinematics of the envs reset follow it
    /// ([`Rollout::record_kinematics`] after a reset).
    pub(super) fn record_reset(&self, s: &Stream, t: i32) -> Result<(), RolloutError> {
        let (p, st) = (&self.physics, &self.state);
        // One thread per env and lane: a lane per qpos and per qvel entry, and one for the rest.
        let lanes = p.qpos.shape()[1] + p.qvel.shape()[1] + 1;
        // A snapshot evaluation resets per group, on its rows: the kernel spreads env n's start
        // by n of its `done`.
        let whole;
        let targets: Vec<&ResetRows> = match &self.groups {
            Some(groups) => groups.groups.iter().map(|g| &g.rows).collect(),
            None => {
                whole = reset_rows(st, p, 0, self.num_envs)?;
                vec![&whole]
            }
        };
        for g in targets {
            self.kernels.reset_masked(
                s,
                g.done.len() * lanes,
                &g.done,
                self.table.table(),
                self.table.layout(),
                self.table.clip_offsets(),
                self.joints.root_quat,
                &self.joints.kind,
                &self.joints.qpos,
                &self.phase_statistics.cdf,
                &self.start_spread,
                &self.phase_statistics.iteration,
                t,
                &self.reset,
                &g.qpos,
                &g.qvel,
                &g.ctrl,
                &g.qacc_warmstart,
                &g.clip_id,
                &g.ref_time,
                &g.episode_step,
                &g.actions,
            )?;
        }
        // The goal task starts at rest with a new goal around the new root.
        if let Task::Goal(goal) = &self.task {
            self.kernels.goal_reset(
                s,
                self.num_envs,
                &st.done,
                &goal.params,
                t,
                &self.phase_statistics.iteration,
                &p.qpos,
                &p.qvel,
                &goal.goal,
                &goal.distance,
                &goal.counters,
            )?;
        }
        Ok(())
    }

    /// The body kinematics the reward and observation read, of the current state: the
    /// kinematics plan over every world, or with `env.body_kinematics = "fused"` the
    /// `body_frames` and `body_velocities` launches, after a reset (`after_reset`) only for
    /// the envs reset.
    pub(super) fn record_kinematics(
        &self,
        s: &Stream,
        after_reset: bool,
    ) -> Result<(), RolloutError> {
        match &self.body_kinematics {
            None => self.sim.record(KINEMATICS_PLAN, s)?,
            Some(model) => model.record(
                &self.kernels,
                s,
                self.num_envs,
                &self.physics,
                &self.state.done,
                after_reset,
            )?,
        }
        Ok(())
    }

    /// The observation into `storage`'s row `row`, normalized (statistics updated when
    /// `update`).
    pub(super) fn record_observation(
        &self,
        s: &Stream,
        storage: &RolloutStorage,
        row: usize,
        update: bool,
    ) -> Result<(), RolloutError> {
        let p = &self.physics;
        let norm = &self.normalizer;
        let tracked = &self.joints.tracked_bodies;
        self.kernels.observe(
            s,
            self.num_envs * observe_threads_per_env(tracked.len()),
            &p.qpos,
            &p.qvel,
            &p.xpos,
            &p.xquat,
            &p.cvel,
            &p.subtree_com,
            self.table.table(),
            self.table.layout(),
            self.table.clip_offsets(),
            &self.joints.end_effectors,
            tracked,
            &self.state.clip_id,
            &self.state.ref_time,
            &self.state.actions,
            &self.observation,
            &norm.raw,
        )?;
        if let Task::Goal(goal) = &self.task {
            self.kernels.goal_observe(
                s,
                self.num_envs,
                &p.qpos,
                &goal.goal,
                goal.column as i32,
                &norm.raw,
            )?;
        }
        match &self.groups {
            Some(groups) => groups.record_normalize(&self.kernels, s, row)?,
            None => norm.record(&self.kernels, s, &storage.observations, row, update)?,
        }
        Ok(())
    }
}
