//! `push` (medium/hard): push a puck onto a target with the end effector, with contact physics
//! from rapier2d.
//!
//! Top-down view, no gravity. The end effector is a kinematic disc (radius 8 cm) that follows the
//! point mass of [`super::point_mass`]; the puck is a dynamic disc (radius 15 cm, 1 kg) whose
//! linear and angular damping stand in for floor friction. Rapier runs at 0.05 s, two steps per
//! control period. The puck starts within 0.8 m of the centre, the target 1.0-1.4 m away, and the
//! end effector 1.2-1.5 m behind the puck, at up to 20 degrees off the push line.
//!
//! Observation (10): `[ee_x, ee_y, ee_vx, ee_vy, puck - ee (x, y), puck_vx, puck_vy,
//! target - puck (x, y)]` (m, m/s). The puck is rotation-symmetric, so its pose is its position.
//! The puck is given relative to the end effector and the target relative to the puck (the
//! expert's push line); see the `tasks` module docs for why.
//! Success: puck centre within 5 cm of the target.
//! Expert: one smooth path, a circular-arc approach (curvature about 1 rad/m at most) that ends
//! behind the puck heading along the push line, then straight through to where the puck sits on the target, with minimum-jerk
//! timing at 0.4 m/s on average; contact happens at speed, without a stop. While pushing, the
//! expert steers sideways against the puck's drift off the line. If the path has ended, the puck
//! has come to rest and it is not on the target (which happens only when the pusher was
//! disturbed, e.g. in perturbed demonstrations), the expert plans a new approach and push from
//! where things are.
use super::geom::{Cubic, SmoothPath, TimedPath, V2};
use super::point_mass::{parse_target, PointMass};
use super::rng::TaskRng;
use super::{last_obs, v2_at, LayoutItem, Role, Shape, Task, TaskSpec, CONTROL_DT};
use crate::tasks::{Policy, PolicyInput};
use rapier2d::prelude::*;

const OBS_FIELDS: &[&str] = &[
    "ee_x [m]",
    "ee_y [m]",
    "ee_vx [m/s]",
    "ee_vy [m/s]",
    "puck_x - ee_x [m]",
    "puck_y - ee_y [m]",
    "puck_vx [m/s]",
    "puck_vy [m/s]",
    "target_x - puck_x [m]",
    "target_y - puck_y [m]",
];
const SPEC: TaskSpec = TaskSpec {
    name: "push",
    obs_fields: OBS_FIELDS,
    max_steps: 150,
};
/// End-effector (pusher) radius, metres.
pub const PUSHER_RADIUS: f64 = 0.08;
/// Puck radius, metres.
pub const PUCK_RADIUS: f64 = 0.15;
const PUCK_MASS: f64 = 1.0;
/// Damping rates standing in for floor friction, 1/s.
const PUCK_LINEAR_DAMPING: f64 = 5.0;
const PUCK_ANGULAR_DAMPING: f64 = 5.0;
const GOAL_TOLERANCE: f64 = 0.05;
/// Physics steps per control period.
const PHYSICS_STEPS: usize = 2;

pub struct Push {
    world: PhysicsWorld,
    pusher: RigidBodyHandle,
    puck: RigidBodyHandle,
    ee: PointMass,
    target: V2,
}

impl Default for Push {
    /// Placeholder bodies in an empty world until [`Task::reset`] builds the layout.
    fn default() -> Self {
        let mut world = PhysicsWorld::default();
        let pusher = world.insert_body(RigidBodyBuilder::fixed());
        let puck = world.insert_body(RigidBodyBuilder::fixed());
        Self {
            world,
            pusher,
            puck,
            ee: PointMass::default(),
            target: V2::ZERO,
        }
    }
}

impl Push {
    fn puck_state(&self) -> (V2, V2) {
        let body = &self.world.bodies[self.puck];
        let (p, v) = (body.translation(), body.linvel());
        (
            V2::new(f64::from(p.x), f64::from(p.y)),
            V2::new(f64::from(v.x), f64::from(v.y)),
        )
    }
}

fn vector(p: V2) -> Vector {
    Vector::new(p.x as f32, p.y as f32)
}

fn inside(p: V2, half_extent: f64) -> bool {
    p.x.abs() <= half_extent && p.y.abs() <= half_extent
}

impl Task for Push {
    fn spec(&self) -> &'static TaskSpec {
        &SPEC
    }

    fn reset(&mut self, seed: u64) {
        let mut rng = TaskRng::new(seed, b"push/layout");
        let (puck, target, start) = loop {
            let puck = V2::new(rng.uniform(-0.8, 0.8), rng.uniform(-0.8, 0.8));
            let heading = rng.uniform(-std::f64::consts::PI, std::f64::consts::PI);
            let dir = V2::new(heading.cos(), heading.sin());
            let target = puck + dir * rng.uniform(1.0, 1.4);
            let off_axis = rng.uniform(-20f64, 20.0).to_radians() + heading;
            let start = puck - V2::new(off_axis.cos(), off_axis.sin()) * rng.uniform(1.2, 1.5);
            if inside(target, 1.5) && inside(start, 1.9) {
                break (puck, target, start);
            }
        };
        let mut world = PhysicsWorld {
            gravity: Vector::ZERO,
            ..PhysicsWorld::default()
        };
        world.integration_parameters.dt = (CONTROL_DT / PHYSICS_STEPS as f64) as f32;
        let area = std::f64::consts::PI * PUCK_RADIUS * PUCK_RADIUS;
        let (puck_body, _) = world.insert(
            RigidBodyBuilder::dynamic()
                .translation(vector(puck))
                .linear_damping(PUCK_LINEAR_DAMPING as f32)
                .angular_damping(PUCK_ANGULAR_DAMPING as f32)
                .can_sleep(false),
            ColliderBuilder::ball(PUCK_RADIUS as f32)
                .density((PUCK_MASS / area) as f32)
                .friction(0.3)
                .restitution(0.0),
        );
        let (pusher_body, _) = world.insert(
            RigidBodyBuilder::kinematic_position_based().translation(vector(start)),
            ColliderBuilder::ball(PUSHER_RADIUS as f32)
                .friction(0.3)
                .restitution(0.0),
        );
        self.world = world;
        self.puck = puck_body;
        self.pusher = pusher_body;
        self.ee = PointMass::at_rest(start);
        self.target = target;
    }

    fn observe(&self) -> Vec<f32> {
        let (p, v, t) = (self.ee.pos, self.ee.vel, self.target);
        let (q, w) = self.puck_state();
        let (puck, target) = (q - p, t - q);
        [
            p.x, p.y, v.x, v.y, puck.x, puck.y, w.x, w.y, target.x, target.y,
        ]
        .iter()
        .map(|&x| x as f32)
        .collect()
    }

    fn step(&mut self, action: &[f32]) -> anyhow::Result<()> {
        let target = parse_target(action)?;
        for _ in 0..PHYSICS_STEPS {
            // The end effector integrates in its usual 0.01 s substeps; rapier then moves the
            // kinematic pusher to where it ended up.
            self.ee
                .advance(target, CONTROL_DT / PHYSICS_STEPS as f64, |_| {});
            self.world.bodies[self.pusher].set_next_kinematic_translation(vector(self.ee.pos));
            self.world.step();
        }
        Ok(())
    }

    fn success(&self) -> bool {
        (self.puck_state().0 - self.target).norm() < GOAL_TOLERANCE
    }

    fn ee_position(&self) -> [f64; 2] {
        self.ee.pos.to_array()
    }

    fn expert(&self) -> Box<dyn Policy> {
        Box::new(PushExpert::default())
    }

    fn layout(&self) -> Vec<LayoutItem> {
        vec![
            LayoutItem {
                role: Role::Object,
                shape: Shape::Disc {
                    center: self.puck_state().0.to_array(),
                    radius: PUCK_RADIUS,
                },
            },
            LayoutItem {
                role: Role::Goal,
                shape: Shape::Disc {
                    center: self.target.to_array(),
                    radius: GOAL_TOLERANCE,
                },
            },
        ]
    }
}

/// Scripted expert for [`Push`].
#[derive(Default)]
pub struct PushExpert {
    plan: Option<PushPlan>,
    step: usize,
}

struct PushPlan {
    path: TimedPath,
    /// Unit push direction (puck start to target).
    dir: V2,
    target: V2,
}

/// After its path has ended, the expert re-plans once the puck is slower than this (m/s) ...
const REST_SPEED: f64 = 0.02;
/// ... and its centre is farther than this from the target, metres (inside the success radius).
const REPLAN_DISTANCE: f64 = 0.03;

/// Gap left between pusher and puck at the end of the approach curve, metres.
const APPROACH_GAP: f64 = 0.05;
/// Lateral steering gain while pushing (metres of pusher offset per metre of puck drift); above 1
/// so that the pusher ends up beyond the puck's centre line and pushes it back.
const STEER_GAIN: f64 = 1.5;

fn plan(ee: V2, puck: V2, target: V2) -> PushPlan {
    let dir = (target - puck).unit();
    let contact = PUCK_RADIUS + PUSHER_RADIUS;
    let behind = puck - dir * (contact + APPROACH_GAP);
    let finish = target - dir * contact;
    let path = SmoothPath::new(vec![
        Cubic::arc_to(ee, behind, dir),
        Cubic::line(behind, finish),
    ]);
    PushPlan {
        path: TimedPath::with_speed(path, 0.4, 2.0),
        dir,
        target,
    }
}

impl Policy for PushExpert {
    fn name(&self) -> String {
        "expert".into()
    }

    fn reset(&mut self, _seed: u64) {
        self.plan = None;
        self.step = 0;
    }

    fn act(&mut self, input: &PolicyInput<'_>) -> anyhow::Result<Vec<Vec<f32>>> {
        let obs = last_obs(input, &SPEC)?;
        let ee = v2_at(obs, 0);
        let puck = ee + v2_at(obs, 4);
        let target = puck + v2_at(obs, 8);
        let puck_speed = v2_at(obs, 6).norm();
        let finished = self
            .plan
            .as_ref()
            .is_some_and(|p| self.step as f64 * CONTROL_DT > p.path.duration);
        if finished && puck_speed < REST_SPEED && (puck - target).norm() > REPLAN_DISTANCE {
            self.plan = None;
            self.step = 0;
        }
        let plan = self.plan.get_or_insert_with(|| plan(ee, puck, target));
        let command = plan.path.at(self.step as f64 * CONTROL_DT);
        // Steer against the puck's sideways drift (zero until contact): the pusher moves past
        // the side the puck drifted to, which pushes the puck back toward the line.
        let normal = plan.dir.perp();
        let drift = (puck - plan.target).dot(normal);
        let command = command + normal * (STEER_GAIN * drift);
        self.step += 1;
        Ok(vec![command.to_f32().to_vec()])
    }
}
