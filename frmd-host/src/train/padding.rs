//! End-of-episode padding of demonstrations for the teacher and student (as Diffusion Policy's
//! sequence sampler pads `n_action_steps - 1` steps after each episode).
//!
//! Demonstrations stop at the first step where the task's success test holds, so the windows of
//! [`Dataset::windows`] never show what to do once the goal is reached: a policy that arrives a
//! few centimetres off (or slightly too fast) is outside the data. Measured on avoid (MLP-SiLU
//! teacher, 20k steps, 10 plotted episodes): most failures reached the goal and then turned
//! back, several into the obstacle. Repeating each episode's final observation and action
//! `steps` times adds windows that start at the final state with a zero action rate and hold the
//! final action; windows that already overlapped the end are unchanged (they were padded with the
//! final action anyway), and the min/max normalization is unchanged (only existing rows repeat).
//!
//! Measured (avoid, output-layer lr x10, 20k steps, 8 padded steps): the failure mode changed
//! from turning back at the goal to stopping 10-30 cm short of it; success 17 % vs 20 % without
//! padding (30 episodes), so padding is off by default (`--pad-end 0`).
use crate::data::Dataset;

/// A copy of `data` with each episode's last observation/action row repeated `steps` more times.
pub fn pad_episode_ends(data: &Dataset, steps: usize) -> anyhow::Result<Dataset> {
    data.validate()?;
    if steps == 0 {
        return Ok(data.clone());
    }
    let (o, a) = (data.obs_dim, data.action_dim);
    let extra = data.num_episodes() * steps;
    let mut padded = Dataset {
        obs: Vec::with_capacity(data.obs.len() + extra * o),
        action: Vec::with_capacity(data.action.len() + extra * a),
        episode_ends: Vec::with_capacity(data.episode_ends.len()),
        ..data.clone()
    };
    for range in data.episode_ranges() {
        padded
            .obs
            .extend_from_slice(&data.obs[range.start * o..range.end * o]);
        padded
            .action
            .extend_from_slice(&data.action[range.start * a..range.end * a]);
        let last = range.end - 1;
        for _ in 0..steps {
            padded
                .obs
                .extend_from_slice(&data.obs[last * o..(last + 1) * o]);
            padded
                .action
                .extend_from_slice(&data.action[last * a..(last + 1) * a]);
        }
        padded.episode_ends.push((padded.action.len() / a) as i64);
    }
    padded.validate()?;
    Ok(padded)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn data() -> Dataset {
        let obs: Vec<f32> = (0..7).map(|i| i as f32).collect();
        let action: Vec<f32> = (0..14).map(|i| 10.0 + i as f32 * 0.5).collect();
        Dataset::handmade(obs, action, vec![3, 7], (1, 2))
    }

    #[test]
    fn padding_repeats_final_rows_and_adds_hold_windows() {
        let d = data();
        let p = pad_episode_ends(&d, 2).unwrap();
        assert_eq!(p.episode_ends, vec![5, 11]);
        assert_eq!(
            p.obs,
            vec![0.0, 1.0, 2.0, 2.0, 2.0, 3.0, 4.0, 5.0, 6.0, 6.0, 6.0]
        );
        assert_eq!(&p.action[6..10], &[12.0, 12.5, 12.0, 12.5]);
        let (plain, norm) = d.windows(2, 3).unwrap();
        let (more, padded_norm) = p.windows(2, 3).unwrap();
        assert_eq!(norm, padded_norm, "normalization must not change");
        assert_eq!(more.len(), plain.len() + 4);
        // Windows of the original steps are unchanged (episode 1's windows, then the padded ones).
        assert_eq!(&more.actions[..3 * 6], &plain.actions[..3 * 6]);
        // The last padded window of episode 1: rate 0, holds the final action.
        let w = 4;
        assert_eq!(&more.prev_rate[w * 2..w * 2 + 2], &[0.0, 0.0]);
        let last_action = &more.actions[2 * 6 + 4..2 * 6 + 6];
        assert_eq!(
            &more.actions[w * 6..w * 6 + 6],
            &[last_action, last_action, last_action].concat()[..]
        );
        assert_eq!(pad_episode_ends(&d, 0).unwrap(), d);
    }
}
