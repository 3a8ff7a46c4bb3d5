//! `avoid` (medium): reach a goal behind a round obstacle that can be passed on either side.
//!
//! Start near y = -1.6 m, goal near y = +1.6 m, obstacle (radius 0.3-0.4 m) near the midpoint, a
//! few centimetres off the start-goal line. The end effector is a disc of radius 5 cm; touching
//! the obstacle fails the episode at once.
//!
//! Observation (9): `[ee_x, ee_y, ee_vx, ee_vy, goal - ee (x, y), obstacle - ee (x, y),
//! obstacle_radius]` (m, m/s; relative positions, see the `tasks` module docs).
//! Success: no contact, end effector within 3 cm of the goal and slower than 0.1 m/s.
//! Expert: flips a fair coin (from its seeded stream) for the side, then follows a half-sine
//! detour whose apex clears the obstacle by 25 cm, with minimum-jerk timing at 0.6 m/s on
//! average. Demonstrations are therefore bimodal: averaging the two modes drives straight into
//! the obstacle.
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
    "obstacle_x - ee_x [m]",
    "obstacle_y - ee_y [m]",
    "obstacle_radius [m]",
];
const SPEC: TaskSpec = TaskSpec {
    name: "avoid",
    obs_fields: OBS_FIELDS,
    max_steps: 120,
};
const GOAL_TOLERANCE: f64 = 0.03;
const SPEED_TOLERANCE: f64 = 0.1;
/// Radius of the end effector disc, metres.
pub const EE_RADIUS: f64 = 0.05;
/// Clearance the expert keeps between the end effector and the obstacle at the apex, metres.
const EXPERT_MARGIN: f64 = 0.25;

#[derive(Default)]
pub struct Avoid {
    ee: PointMass,
    goal: V2,
    obstacle: V2,
    radius: f64,
    collided: bool,
}

impl Task for Avoid {
    fn spec(&self) -> &'static TaskSpec {
        &SPEC
    }

    fn reset(&mut self, seed: u64) {
        let mut rng = TaskRng::new(seed, b"avoid/layout");
        let start = V2::new(rng.uniform(-0.4, 0.4), rng.uniform(-1.7, -1.5));
        let goal = V2::new(rng.uniform(-0.4, 0.4), rng.uniform(1.5, 1.7));
        let normal = (goal - start).unit().perp();
        let offset = rng.uniform(-0.05, 0.05);
        self.obstacle = start.lerp(goal, 0.5) + normal * offset;
        self.radius = rng.uniform(0.3, 0.4);
        self.ee = PointMass::at_rest(start);
        self.goal = goal;
        self.collided = false;
    }

    fn observe(&self) -> Vec<f32> {
        let (p, v) = (self.ee.pos, self.ee.vel);
        let (g, o) = (self.goal - p, self.obstacle - p);
        [p.x, p.y, v.x, v.y, g.x, g.y, o.x, o.y, self.radius]
            .iter()
            .map(|&x| x as f32)
            .collect()
    }

    fn step(&mut self, action: &[f32]) -> anyhow::Result<()> {
        let target = parse_target(action)?;
        let (center, reach) = (self.obstacle, self.radius + EE_RADIUS);
        let mut hit = false;
        self.ee.advance(target, CONTROL_DT, |pm| {
            hit |= (pm.pos - center).norm() < reach
        });
        self.collided |= hit;
        Ok(())
    }

    fn success(&self) -> bool {
        !self.collided
            && (self.ee.pos - self.goal).norm() < GOAL_TOLERANCE
            && self.ee.vel.norm() < SPEED_TOLERANCE
    }

    fn failed(&self) -> bool {
        self.collided
    }

    fn ee_position(&self) -> [f64; 2] {
        self.ee.pos.to_array()
    }

    fn expert(&self) -> Box<dyn Policy> {
        Box::new(AvoidExpert::default())
    }

    fn layout(&self) -> Vec<LayoutItem> {
        vec![
            LayoutItem {
                role: Role::Obstacle,
                shape: Shape::Disc {
                    center: self.obstacle.to_array(),
                    radius: self.radius,
                },
            },
            LayoutItem {
                role: Role::Goal,
                shape: Shape::Disc {
                    center: self.goal.to_array(),
                    radius: GOAL_TOLERANCE,
                },
            },
        ]
    }
}

/// Scripted expert for [`Avoid`]; which side it passes is a seeded coin flip.
pub type AvoidExpert = PathExpert<AvoidPlanner>;

/// [`AvoidExpert`]'s plan: the half-sine detour on the coin's (or the forced) side.
#[derive(Clone, Copy, Debug, Default)]
pub struct AvoidPlanner {
    forced_side: Option<f64>,
}

impl AvoidExpert {
    /// The side (+1: along the left normal of the start-goal line, -1: right) for a seed.
    pub fn side(seed: u64) -> f64 {
        TaskRng::new(seed, b"avoid/side").sign()
    }

    /// An expert that always passes on `side` (+1 or -1) instead of flipping a coin.
    pub fn with_side(side: f64) -> Self {
        Self::new(AvoidPlanner {
            forced_side: Some(side.signum()),
        })
    }
}

/// The detour: a half sine of amplitude `amplitude` along `normal` over the chord from `start`
/// to `goal`, as two cubic segments meeting at the apex with a tangent parallel to the chord.
fn detour(start: V2, goal: V2, normal: V2, amplitude: f64) -> SmoothPath {
    let chord = goal - start;
    let apex = start.lerp(goal, 0.5) + normal * amplitude;
    // d/dv of start + chord*v/2 + normal*A*sin(pi v/2) at v = 0 and v = 1, divided by 3.
    let lean = normal * (amplitude * std::f64::consts::PI / 6.0);
    let half = chord * (1.0 / 6.0);
    SmoothPath::new(vec![
        Cubic {
            p0: start,
            p1: start + half + lean,
            p2: apex - half,
            p3: apex,
        },
        Cubic {
            p0: apex,
            p1: apex + half,
            p2: goal - half + lean,
            p3: goal,
        },
    ])
}

impl PathPlanner for AvoidPlanner {
    const SPEC: &'static TaskSpec = &SPEC;

    fn plan(&self, seed: u64, obs: &[f32]) -> TimedPath {
        let start = v2_at(obs, 0);
        let (goal, obstacle) = (start + v2_at(obs, 4), start + v2_at(obs, 6));
        let radius = f64::from(obs[8]);
        let normal = (goal - start).unit().perp();
        let side = self.forced_side.unwrap_or_else(|| AvoidExpert::side(seed));
        // Signed offset of the obstacle from the chord midpoint, along the normal.
        let offset = (obstacle - start.lerp(goal, 0.5)).dot(normal);
        let amplitude = radius + EE_RADIUS + EXPERT_MARGIN + side * offset;
        TimedPath::with_speed(detour(start, goal, normal * side, amplitude), 0.6, 2.0)
    }
}
