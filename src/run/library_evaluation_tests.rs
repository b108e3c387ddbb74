use super::*;
use crate::env::{EvalStart, EvaluationProtocol, clip_evaluation};
use crate::motion::{Character, MotionLibraryBuilder, SyntheticMotion};
use crate::run::clip_sampling::ClipSampling;
use crate::run::clips_table::clips_table;
use crate::run::metrics::{IterationRecord, UpdateStats};

const DT: f64 = 1.0 / 30.0;

/// Three clips: a looping 1 s walk, a clamped 2 s one, a clamped 14 s one (longer than the
/// 10-s window), and how the evaluation plays them.
fn library() -> (MotionLibrary, Vec<ClipEvaluation>) {
    let character = Character::humanoid().unwrap();
    let mut builder = MotionLibraryBuilder::new("test library", DT);
    for (name, frames, mode) in [
        ("walk", 31, LoopMode::Wrap),
        ("punch", 61, LoopMode::Clamp),
        ("long", 421, LoopMode::Clamp),
    ] {
        let motion = SyntheticMotion {
            frames,
            loop_mode: mode,
            ..SyntheticMotion::default()
        }
        .reference_motion(&character)
        .unwrap();
        builder.push(name, "synthetic", &motion, 1.0).unwrap();
    }
    let library = builder.finish().unwrap();
    let protocol = EvaluationProtocol {
        envs: 12,
        steps: None,
        start: EvalStart::Spread,
        window_s: Some(LIBRARY_EVALUATION_WINDOW_S),
    };
    let evaluations: Vec<ClipEvaluation> = (0..3)
        .map(|c| {
            let s = library.segment(c).unwrap();
            clip_evaluation(&protocol, s.duration(), DT, s.loop_mode())
        })
        .collect();
    (library, evaluations)
}

fn plan(envs: usize) -> LibraryPlan {
    let (library, evaluations) = library();
    LibraryPlan::new(&library, &evaluations, envs).unwrap()
}

/// An episode of `steps` steps at a global MPJPE of `mpjpe` per step.
fn env(completed: bool, steps: u32, mpjpe: f64) -> EnvEvaluation {
    let s = f64::from(steps);
    EnvEvaluation {
        completed,
        robotics_terminated: false,
        steps,
        pose_error_sum: 0.05 * s,
        global_position_error_sum: mpjpe * s,
        ee_position_error_sum: 0.07 * s,
        ee_orientation_error_sum: 0.2 * s,
    }
}

/// Every env's episode complete (`fail` lists envs that fail at step 5).
fn episodes(plan: &LibraryPlan, fail: &[usize]) -> Vec<EnvEvaluation> {
    (0..plan.envs)
        .map(|e| {
            let (clip, _) = plan.start_of(e);
            if fail.contains(&e) {
                env(false, 5, 0.1)
            } else {
                env(true, plan.clips[clip].evaluation.steps, 0.1)
            }
        })
        .collect()
}

#[test]
fn the_plan_evaluates_long_clips_over_windows_and_short_ones_whole() {
    let plan = plan(12);
    let steps: Vec<u32> = plan.clips.iter().map(|c| c.evaluation.steps).collect();
    assert_eq!(steps, [30, 60, 300]);
    assert_eq!(plan.longest_steps(), 300);
    assert!(!plan.clips[0].evaluation.windowed && plan.clips[2].evaluation.windowed);
    // Env i plays clip i mod 3 from start i div 3 of 4.
    assert_eq!(plan.start_of(0), (0, 0.0));
    assert_eq!(plan.start_of(4).0, 1);
    assert_eq!(plan.start_of(1).1, 0.0, "a clamped short clip starts at 0");
    let (clip, start) = plan.start_of(5);
    assert_eq!(clip, 2);
    assert!(start > 0.0 && start + 301.0 * DT <= 14.0, "{start}");
    let (_, walk) = plan.start_of(3);
    assert!((walk - 0.25).abs() < 1e-6, "{walk}");
    // Fewer envs than clips: some clip would go unevaluated.
    let (library, evaluations) = library();
    let err = LibraryPlan::new(&library, &evaluations, 2).unwrap_err();
    assert!(err.to_string().contains("every clip needs an env"), "{err}");
    assert!(LibraryPlan::new(&library, &evaluations[..2], 12).is_err());
}

#[test]
fn success_needs_the_episode_rate_and_every_clip_at_its_threshold() {
    let plan = plan(12);
    // Every episode succeeds.
    let s = plan.summarize(&episodes(&plan, &[]), 0.9).unwrap();
    assert!(s.success && s.clip_start_success);
    let library = s.library.as_ref().unwrap();
    assert_eq!(library.clips_at_threshold, 3);
    assert_eq!(library.clips[2].window_s, Some(LIBRARY_EVALUATION_WINDOW_S));
    assert_eq!(library.clips[0].window_s, None);
    assert_eq!(s.episode_steps, 300);
    // One failure of 12: 11/12 = 0.917 >= 0.9 of the episodes, but clip 2 at 3/4 < 0.8.
    let s = plan.summarize(&episodes(&plan, &[5]), 0.9).unwrap();
    let library = s.library.as_ref().unwrap();
    assert!(library.episodes_pass && !library.all_clips_pass && !s.success);
    assert_eq!(library.clips[2].success_rate, 0.75);
    assert_eq!(
        (library.clips_at_threshold, library.clip_fraction),
        (2, 2.0 / 3.0)
    );
    // A drifting clip fails by the MPJPE bound, as a single clip's would.
    let mut drifting = episodes(&plan, &[]);
    for e in (1..12).step_by(3) {
        drifting[e] = env(true, 60, 0.3);
    }
    let s = plan.summarize(&drifting, 0.5).unwrap();
    assert_eq!(s.library.as_ref().unwrap().clips[1].success_rate, 0.0);
    assert!(!s.success);
    // Step-weighted MPJPE over every episode.
    assert!((s.global_mpjpe_m - (0.1 * 4.0 * 330.0 + 0.3 * 4.0 * 60.0) / 1560.0).abs() < 1e-12);
}

#[test]
fn an_episode_that_does_not_fit_its_clip_is_named_by_the_clip() {
    let plan = plan(6);
    let mut e = episodes(&plan, &[]);
    e[2] = env(true, 299, 0.1);
    let err = plan.summarize(&e, 0.9).unwrap_err().to_string();
    assert!(err.contains("motion library clip \"long\""), "{err}");
    assert!(
        err.contains("299 steps reported for an episode of 300"),
        "{err}"
    );
    assert!(plan.summarize(&e[..5], 0.9).is_err());
}

#[test]
fn the_clips_table_lists_each_clip_with_its_time_to_threshold() {
    let plan = plan(12);
    let record = |iteration: u64, fail: &[usize]| IterationRecord {
        iteration,
        active_time_s: iteration as f64,
        frames: 0,
        frames_per_s: 0.0,
        mean_return: 0.0,
        mean_episode_length: 0.0,
        update: UpdateStats::default(),
        termination: Default::default(),
        evaluation: Some(plan.summarize(&episodes(&plan, fail), 0.9).unwrap()),
        divergence: None,
        task: None,
        wall_s: None,
    };
    assert!(clips_table(&[]).is_none());
    let records = [record(1, &[0, 3, 5]), record(2, &[5]), record(3, &[])];
    let table = clips_table(&records[..2]).unwrap();
    let lines: Vec<&str> = table.lines().collect();
    assert_eq!(lines.len(), 5, "{table}");
    assert!(lines[0].starts_with("clip\tduration_s\tloop\tevaluated_over"));
    // walk failed twice at iteration 1 (2/4), succeeded at 2.
    assert!(
        lines[1].starts_with("walk\t1.000\twrap\twhole clip\t30\t4\t4\t1.000\t"),
        "{}",
        lines[1]
    );
    // Then the time to 0.8 and the sampler's three columns (none without a trainer's).
    assert!(lines[1].ends_with("\t2.000\t-\t-\t-"), "{}", lines[1]);
    assert!(
        lines[3].contains("10 s windows") && lines[3].ends_with("\t-\t-\t-\t-"),
        "{}",
        lines[3]
    );
    assert!(
        lines[4].starts_with("all (2 of 3 clips at 0.8)"),
        "{}",
        lines[4]
    );
    let table = clips_table(&records).unwrap();
    assert!(
        table.lines().nth(3).unwrap().ends_with("\t3.000\t-\t-\t-"),
        "{table}"
    );
    assert!(
        table.lines().nth(4).unwrap().ends_with("\t3.000\t-\t-\t-"),
        "{table}"
    );
    // With the sampler's part, the clip's row carries it.
    let mut sampled = records.clone();
    if let Some(library) = sampled[2]
        .evaluation
        .as_mut()
        .and_then(|e| e.library.as_mut())
    {
        let part = ClipSampling {
            reset_share: 0.5,
            frame_share: Some(0.25),
            failures_per_step: None,
        };
        library.set_sampling(&[part; 3]);
        // Another library's list is left out.
        library.set_sampling(&[part; 2]);
    }
    let table = clips_table(&sampled).unwrap();
    assert!(
        table
            .lines()
            .nth(1)
            .unwrap()
            .ends_with("\t2.000\t0.500\t0.250\t-"),
        "{table}"
    );
}

#[test]
fn episode_rows_name_each_envs_clip() {
    let plan = plan(6);
    let rows = plan.episode_rows(&episodes(&plan, &[4]));
    assert_eq!(rows[4].clip.as_deref(), Some("punch"));
    assert!(!rows[4].completed);
    assert_eq!(rows[0].clip.as_deref(), Some("walk"));
    let json = serde_json::to_string(&rows[0]).unwrap();
    assert!(json.contains("\"clip\":\"walk\""), "{json}");
}
