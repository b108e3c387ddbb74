//! What the adaptive reset sampler gives each clip of a library (docs/library.md, "The reset
//! sampler"), read from the sampler's own statistics at each evaluation: the clip's share of
//! the next rollout's resets, its share of the recent training frames, and its failures per
//! control step. Written beside the clip's evaluation (`metrics.jsonl`'s
//! `evaluation.library.clips[]`, and `clips.tsv`). A clip that is not learnt can then be told
//! apart: starved of resets, or favoured by the sampler but short of frames (its episodes end
//! within steps while the others' last seconds), or given both and still failing.

/// One clip's part in the sampler.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ClipSampling {
    /// The clip's share of the resets the CDF draws (its cells' probabilities summed).
    pub reset_share: f64,
    /// The clip's share of the control steps played in training (its cells' decayed visit
    /// counts over every cell's: the tracking kernel counts a visit per env and step); `None`
    /// before any step.
    pub frame_share: Option<f64>,
    /// Failing steps per step played on the clip (the decayed counts the CDF is made from);
    /// `None` when no cell has been visited.
    pub failures_per_step: Option<f64>,
}

/// Each clip's sampling from the sampler's `[clips, bins]` arrays (row-major): the CDF over
/// every cell (clip after clip, ending at 1) and the decayed visit and failure counts. `None`
/// when the arrays do not have `clips * bins` values or the CDF is not a non-decreasing run of
/// finite values.
pub fn clip_sampling(
    cdf: &[f32],
    visits: &[f32],
    failures: &[f32],
    clips: usize,
    bins: usize,
) -> Option<Vec<ClipSampling>> {
    let cells = clips.checked_mul(bins)?;
    if cells == 0 || cdf.len() != cells || visits.len() != cells || failures.len() != cells {
        return None;
    }
    if cdf.iter().any(|x| !x.is_finite()) || cdf.windows(2).any(|w| w[1] < w[0]) {
        return None;
    }
    let sum = |x: &[f32]| x.iter().map(|&v| f64::from(v)).sum::<f64>();
    let all_visits = sum(visits);
    let mut before = 0.0f64;
    let sampling = (0..clips)
        .map(|c| {
            let row = c * bins..(c + 1) * bins;
            let end = f64::from(cdf[row.end - 1]);
            let (v, f) = (sum(&visits[row.clone()]), sum(&failures[row]));
            let share = end - before;
            before = end;
            ClipSampling {
                reset_share: share,
                frame_share: (all_visits > 0.0).then(|| v / all_visits),
                failures_per_step: (v > 0.0).then(|| f / v),
            }
        })
        .collect();
    Some(sampling)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shares_are_the_cdfs_steps_and_the_visits_and_rates_the_clips_cells_together() {
        // Two clips of two bins: the first twice as likely to be drawn, the second played for
        // a sixth of the steps.
        let cdf = [0.3, 2.0 / 3.0, 0.8, 1.0];
        let visits = [10.0, 10.0, 4.0, 0.0];
        let failures = [5.0, 1.0, 4.0, 0.0];
        let s = clip_sampling(&cdf, &visits, &failures, 2, 2).unwrap();
        assert!((s[0].reset_share - 2.0 / 3.0).abs() < 1e-7, "{s:?}");
        assert!((s[1].reset_share - 1.0 / 3.0).abs() < 1e-7, "{s:?}");
        assert_eq!(s[0].frame_share, Some(20.0 / 24.0));
        assert_eq!(s[1].frame_share, Some(4.0 / 24.0));
        assert_eq!(s[0].failures_per_step, Some(0.3));
        assert_eq!(s[1].failures_per_step, Some(1.0));
        let unvisited = clip_sampling(&cdf, &[0.0; 4], &[0.0; 4], 2, 2).unwrap();
        assert_eq!(unvisited[1].failures_per_step, None);
        assert_eq!(unvisited[0].frame_share, None);
    }

    #[test]
    fn arrays_of_another_shape_or_a_broken_cdf_give_none() {
        let ones = [1.0f32; 4];
        assert!(clip_sampling(&[0.5, 1.0], &ones, &ones, 2, 2).is_none());
        assert!(clip_sampling(&[0.5, 0.4, 0.8, 1.0], &ones, &ones, 2, 2).is_none());
        assert!(clip_sampling(&[0.5, f32::NAN, 0.8, 1.0], &ones, &ones, 2, 2).is_none());
        assert!(clip_sampling(&[], &[], &[], 0, 2).is_none());
    }
}
