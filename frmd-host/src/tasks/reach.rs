//! `reach` (easy): drive the end effector to a random goal and stop there.
//!
//! Observation (6): `[ee_x, ee_y, ee_vx, ee_vy, goal - ee (x, y)]` (m, m/s): the goal relative
//! to the end effector, like every built-in task's objects (see `tasks` module docs).
//! Success: end effector within 3 cm of the goal and slower than 0.1 m/s.
//! Expert: a gently bent path (a parabola whose apex is offset sideways by up to 8 % of the
//! distance, side and amount from the expert's seeded stream, so curvature stays below
//! 0.64 rad/m) traversed with minimum-jerk timing at 0.5 m/s on average.
use super::expert::{PathExpert, PathPlanner};
use super::geom::{Cubic, SmoothPath, TimedPath, V2};
use super::point_mass::{parse_target, PointMass};
use super::rng::TaskRng;
use super::{v2_at, LayoutItem, Role, Shape, Task, TaskSpec, CONTROL_DT};
use crate::tasks::Policy;

const OBS_FIELDS: &[&str] = &[
    "ee_x [m]",
    "ee_y [m]",
    "ee_vx [m/s]",
    "ee_vy [m/s]",
    "goal_x - ee_x [m]",
    "goal_y - ee_y [m]",
];
const SPEC: TaskSpec = TaskSpec {
    name: "reach",
    obs_fields: OBS_FIELDS,
    max_steps: 100,
};
const GOAL_TOLERANCE: f64 = 0.03;
const SPEED_TOLERANCE: f64 = 0.1;
const HALF_EXTENT: f64 = 1.6;
const MIN_DISTANCE: f64 = 1.0;

#[derive(Default)]
pub struct Reach {
    ee: PointMass,
    goal: V2,
}

impl Task for Reach {
    fn spec(&self) -> &'static TaskSpec {
        &SPEC
    }

    fn reset(&mut self, seed: u64) {
        let mut rng = TaskRng::new(seed, b"reach/layout");
        loop {
            let start = V2::new(
                rng.uniform(-HALF_EXTENT, HALF_EXTENT),
                rng.uniform(-HALF_EXTENT, HALF_EXTENT),
            );
            let goal = V2::new(
                rng.uniform(-HALF_EXTENT, HALF_EXTENT),
                rng.uniform(-HALF_EXTENT, HALF_EXTENT),
            );
            if (goal - start).norm() >= MIN_DISTANCE {
                self.ee = PointMass::at_rest(start);
                self.goal = goal;
                return;
            }
        }
    }

    fn observe(&self) -> Vec<f32> {
        let (p, v, g) = (self.ee.pos, self.ee.vel, self.goal - self.ee.pos);
        [p.x, p.y, v.x, v.y, g.x, g.y]
            .iter()
            .map(|&x| x as f32)
            .collect()
    }

    fn step(&mut self, action: &[f32]) -> anyhow::Result<()> {
        let target = parse_target(action)?;
        self.ee.advance(target, CONTROL_DT, |_| {});
        Ok(())
    }

    fn success(&self) -> bool {
        (self.ee.pos - self.goal).norm() < GOAL_TOLERANCE && self.ee.vel.norm() < SPEED_TOLERANCE
    }

    fn ee_position(&self) -> [f64; 2] {
        self.ee.pos.to_array()
    }

    fn expert(&self) -> Box<dyn Policy> {
        Box::new(ReachExpert::default())
    }

    fn layout(&self) -> Vec<LayoutItem> {
        vec![LayoutItem {
            role: Role::Goal,
            shape: Shape::Disc {
                center: self.goal.to_array(),
                radius: GOAL_TOLERANCE,
            },
        }]
    }
}

/// Scripted expert for [`Reach`].
pub type ReachExpert = PathExpert<ReachPlanner>;

/// [`ReachExpert`]'s plan: the gently bent path of the module docs.
#[derive(Clone, Copy, Debug, Default)]
pub struct ReachPlanner;

impl PathPlanner for ReachPlanner {
    const SPEC: &'static TaskSpec = &SPEC;

    fn plan(&self, seed: u64, obs: &[f32]) -> TimedPath {
        let start = v2_at(obs, 0);
        let goal = start + v2_at(obs, 4);
        let mut rng = TaskRng::new(seed, b"reach/expert");
        let bend = rng.uniform(-0.08, 0.08) * (goal - start).norm();
        let control = start.lerp(goal, 0.5) + (goal - start).unit().perp() * (2.0 * bend);
        TimedPath::with_speed(
            SmoothPath::new(vec![Cubic::quadratic(start, control, goal)]),
            0.5,
            2.0,
        )
    }
}
