//! The end effector shared by all tasks: a unit point mass pulled toward the commanded position
//! target by a critically damped spring (natural frequency `OMEGA`), integrated with
//! semi-implicit Euler substeps. A position target that jumps is therefore smoothed over about
//! 1/OMEGA seconds, like a stiff position-controlled robot.
use super::geom::V2;

/// Natural frequency of the tracking loop, rad/s.
pub const OMEGA: f64 = 15.0;
/// Integration substep, seconds.
pub const SUBSTEP: f64 = 0.01;
/// Commanded targets are clamped to this box (metres), so that a wild policy cannot blow up the
/// simulation.
pub const TARGET_LIMIT: f64 = 3.0;

/// Position (m) and velocity (m/s) of the end effector.
#[derive(Clone, Copy, Debug, Default)]
pub struct PointMass {
    pub pos: V2,
    pub vel: V2,
}

impl PointMass {
    pub fn at_rest(pos: V2) -> Self {
        Self { pos, vel: V2::ZERO }
    }

    /// One substep of length `h` toward `target`.
    pub fn substep(&mut self, target: V2, h: f64) {
        let acc = (target - self.pos) * (OMEGA * OMEGA) - self.vel * (2.0 * OMEGA);
        self.vel = self.vel + acc * h;
        self.pos = self.pos + self.vel * h;
    }

    /// Advances `dt` seconds toward `target` in `SUBSTEP` pieces, calling `constrain` after
    /// each substep (contacts with fixed geometry; a no-op for free space).
    pub fn advance(&mut self, target: V2, dt: f64, mut constrain: impl FnMut(&mut PointMass)) {
        let substeps = (dt / SUBSTEP).round().max(1.0) as usize;
        let h = dt / substeps as f64;
        for _ in 0..substeps {
            self.substep(target, h);
            constrain(self);
        }
    }
}

/// Validates a raw action and turns it into a clamped 2-D target.
pub fn parse_target(action: &[f32]) -> anyhow::Result<V2> {
    match action {
        [x, y] if x.is_finite() && y.is_finite() => Ok(V2::new(
            f64::from(*x).clamp(-TARGET_LIMIT, TARGET_LIMIT),
            f64::from(*y).clamp(-TARGET_LIMIT, TARGET_LIMIT),
        )),
        [_, _] => anyhow::bail!("action {action:?} is not finite"),
        _ => anyhow::bail!(
            "action has {} values, expected 2 (x, y target in metres)",
            action.len()
        ),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn converges_without_overshoot() {
        let mut pm = PointMass::at_rest(V2::ZERO);
        let target = V2::new(1.0, 0.0);
        let mut max_x: f64 = 0.0;
        for _ in 0..20 {
            pm.advance(target, 0.1, |_| {});
            max_x = max_x.max(pm.pos.x);
        }
        assert!((pm.pos.x - 1.0).abs() < 1e-3, "x = {}", pm.pos.x);
        assert!(max_x < 1.0 + 1e-3, "overshoot to {max_x}");
    }

    #[test]
    fn rejects_bad_actions() {
        assert!(parse_target(&[0.0]).is_err());
        assert!(parse_target(&[f32::NAN, 0.0]).is_err());
        assert_eq!(
            parse_target(&[9.0, -9.0]).unwrap(),
            V2::new(TARGET_LIMIT, -TARGET_LIMIT)
        );
    }
}
