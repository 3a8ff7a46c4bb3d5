//! `insert` (hard): carry a peg over a wall and insert it into a slot with 1 cm clearance per
//! side.
//!
//! A horizontal wall (top surface at `wall_y`, random in [-1.2, -0.6] m) fills the arena below
//! its top except for a slot of depth 20 cm at a random `slot_x`. The peg is 10 cm wide; the slot
//! is 12 cm wide, so the peg enters only if its centre is within 1 cm of the slot centre. The end
//! effector position is the centre of the peg's tip. Contacts are resolved geometrically on the
//! point mass: the tip cannot go below the top surface outside the slot (resting there under a
//! downward push, Coulomb friction with mu = 0.5 holds the peg, so pressing down beside the slot
//! jams it), and inside the slot the side walls and the bottom stop it.
//!
//! Observation (7): `[tip_x, tip_y, tip_vx, tip_vy, slot_x - tip_x, wall_y - tip_y, contact]` (m,
//! m/s; the slot relative to the tip, see the `tasks` module docs; contact is
//! 1 when the peg touched the wall during the last control period, else 0).
//! Success: the tip is within 2 cm of the slot bottom.
//! Expert: one smooth path, a circular-arc approach that ends 15 cm above the slot centre heading
//! straight down, then a straight descent aimed 1 cm below the slot bottom, with minimum-jerk
//! timing at 0.5 m/s on average (so the descent is the slow end of the profile). One closed-loop
//! rule guards the descent: while the tip is above the slot entrance and more than 5 mm beside
//! the slot centre, the expert commands no lower than 3 cm above the wall, so it realigns (and
//! lifts a jammed peg) instead of pressing down beside the slot. On its own path the rule never
//! fires; it matters for perturbed demonstrations (`frmd collect --perturb-std`).
use super::expert::{PathExpert, PathPlanner};
use super::geom::{Cubic, SmoothPath, TimedPath, V2};
use super::point_mass::{parse_target, PointMass, OMEGA, SUBSTEP};
use super::rng::TaskRng;
use super::{v2_at, LayoutItem, Role, Shape, Task, TaskSpec, CONTROL_DT};
use crate::tasks::Policy;

const OBS_FIELDS: &[&str] = &[
    "tip_x [m]",
    "tip_y [m]",
    "tip_vx [m/s]",
    "tip_vy [m/s]",
    "slot_x - tip_x [m]",
    "wall_y - tip_y [m]",
    "contact [0/1]",
];
const SPEC: TaskSpec = TaskSpec {
    name: "insert",
    obs_fields: OBS_FIELDS,
    max_steps: 150,
};
/// Peg width, metres.
pub const PEG_WIDTH: f64 = 0.10;
/// Lateral clearance on each side of the peg in the slot, metres.
pub const CLEARANCE: f64 = 0.01;
/// Slot depth, metres.
pub const SLOT_DEPTH: f64 = 0.20;
const FRICTION: f64 = 0.5;
/// The tip counts as inserted within this distance of the slot bottom, metres.
const INSERT_TOLERANCE: f64 = 0.02;
/// Wall thickness drawn in plots, metres.
const WALL_THICKNESS: f64 = 0.4;

#[derive(Default)]
pub struct Insert {
    tip: PointMass,
    slot_x: f64,
    wall_y: f64,
    contact: bool,
}

impl Insert {
    /// One substep toward `target` with contacts; returns whether the peg touched the wall.
    fn substep(&mut self, target: V2, h: f64) -> bool {
        let before = self.tip.pos;
        let force = (target - self.tip.pos) * (OMEGA * OMEGA) - self.tip.vel * (2.0 * OMEGA);
        let mut vel = self.tip.vel + force * h;
        let mut pos = before + vel * h;
        let mut touched = false;
        let bottom = self.wall_y - SLOT_DEPTH;
        if pos.y < self.wall_y {
            if before.y >= self.wall_y && (pos.x - self.slot_x).abs() > CLEARANCE {
                // Landing on (or sliding along) the top surface beside the slot.
                pos.y = self.wall_y;
                vel.y = 0.0;
                let normal = (-force.y).max(0.0);
                let slowdown = FRICTION * normal * h;
                if vel.x.abs() <= slowdown {
                    vel.x = 0.0;
                } else {
                    vel.x -= slowdown * vel.x.signum();
                }
                pos.x = before.x + vel.x * h;
                touched = true;
            } else {
                // Inside the slot: side walls and bottom.
                let low = self.slot_x - CLEARANCE;
                let high = self.slot_x + CLEARANCE;
                if pos.x < low || pos.x > high {
                    pos.x = pos.x.clamp(low, high);
                    vel.x = 0.0;
                    touched = true;
                }
                if pos.y < bottom {
                    pos.y = bottom;
                    vel.y = 0.0;
                    touched = true;
                }
            }
        }
        self.tip.pos = pos;
        self.tip.vel = vel;
        touched
    }
}

impl Task for Insert {
    fn spec(&self) -> &'static TaskSpec {
        &SPEC
    }

    fn reset(&mut self, seed: u64) {
        let mut rng = TaskRng::new(seed, b"insert/layout");
        self.wall_y = rng.uniform(-1.2, -0.6);
        self.slot_x = rng.uniform(-1.5, 1.5);
        let start = V2::new(
            rng.uniform(-1.8, 1.8),
            (self.wall_y + rng.uniform(1.3, 2.3)).min(1.9),
        );
        self.tip = PointMass::at_rest(start);
        self.contact = false;
    }

    fn observe(&self) -> Vec<f32> {
        let (p, v) = (self.tip.pos, self.tip.vel);
        let contact = if self.contact { 1.0 } else { 0.0 };
        [
            p.x,
            p.y,
            v.x,
            v.y,
            self.slot_x - p.x,
            self.wall_y - p.y,
            contact,
        ]
        .iter()
        .map(|&x| x as f32)
        .collect()
    }

    fn step(&mut self, action: &[f32]) -> anyhow::Result<()> {
        let target = parse_target(action)?;
        let substeps = (CONTROL_DT / SUBSTEP).round() as usize;
        let h = CONTROL_DT / substeps as f64;
        let mut touched = false;
        for _ in 0..substeps {
            touched |= self.substep(target, h);
        }
        self.contact = touched;
        Ok(())
    }

    fn success(&self) -> bool {
        self.tip.pos.y <= self.wall_y - SLOT_DEPTH + INSERT_TOLERANCE
            && (self.tip.pos.x - self.slot_x).abs() <= CLEARANCE
    }

    fn ee_position(&self) -> [f64; 2] {
        self.tip.pos.to_array()
    }

    fn expert(&self) -> Box<dyn Policy> {
        Box::new(InsertExpert::default())
    }

    fn layout(&self) -> Vec<LayoutItem> {
        let (slot_low, slot_high) = (
            self.slot_x - PEG_WIDTH / 2.0 - CLEARANCE,
            self.slot_x + PEG_WIDTH / 2.0 + CLEARANCE,
        );
        let (top, floor) = (self.wall_y, self.wall_y - WALL_THICKNESS);
        let bottom = self.wall_y - SLOT_DEPTH;
        vec![
            LayoutItem {
                role: Role::Wall,
                shape: Shape::Rect {
                    min: [-2.5, floor],
                    max: [slot_low, top],
                },
            },
            LayoutItem {
                role: Role::Wall,
                shape: Shape::Rect {
                    min: [slot_high, floor],
                    max: [2.5, top],
                },
            },
            LayoutItem {
                role: Role::Wall,
                shape: Shape::Rect {
                    min: [slot_low, floor],
                    max: [slot_high, bottom],
                },
            },
            LayoutItem {
                role: Role::Goal,
                shape: Shape::Disc {
                    center: [self.slot_x, bottom],
                    radius: INSERT_TOLERANCE,
                },
            },
        ]
    }
}

/// Scripted expert for [`Insert`].
pub type InsertExpert = PathExpert<InsertPlanner>;

/// [`InsertExpert`]'s plan (arc, then straight down) and its descent guard.
#[derive(Clone, Copy, Debug, Default)]
pub struct InsertPlanner;

/// Height above the wall top where the approach arc ends and the straight descent begins, metres.
const PRE_INSERT_HEIGHT: f64 = 0.15;
/// The expert descends below [`HOVER_HEIGHT`] only with the tip this close to the slot centre,
/// metres (half the clearance).
const ALIGN_TOLERANCE: f64 = 0.005;
/// Lowest command above the wall top while the tip is not aligned with the slot, metres.
const HOVER_HEIGHT: f64 = 0.03;

/// The descent guard: `command` unchanged when the tip at `tip` is aligned with the slot or
/// already inside it, else raised to [`HOVER_HEIGHT`] above the wall.
fn guard_descent(command: V2, tip: V2, slot_x: f64, wall_y: f64) -> V2 {
    let entering = tip.y < wall_y;
    let aligned = (tip.x - slot_x).abs() <= ALIGN_TOLERANCE;
    if entering || aligned {
        command
    } else {
        V2::new(command.x, command.y.max(wall_y + HOVER_HEIGHT))
    }
}

fn plan(start: V2, slot_x: f64, wall_y: f64) -> TimedPath {
    let above = V2::new(slot_x, wall_y + PRE_INSERT_HEIGHT);
    let down = V2::new(0.0, -1.0);
    let press = V2::new(slot_x, wall_y - SLOT_DEPTH - 0.01);
    let path = SmoothPath::new(vec![
        Cubic::arc_to(start, above, down),
        Cubic::line(above, press),
    ]);
    TimedPath::with_speed(path, 0.5, 2.0)
}

/// The tip and the slot (its centre x and the wall top y) in an observation.
fn tip_and_slot(obs: &[f32]) -> (V2, f64, f64) {
    let tip = v2_at(obs, 0);
    (tip, tip.x + f64::from(obs[4]), tip.y + f64::from(obs[5]))
}

impl PathPlanner for InsertPlanner {
    const SPEC: &'static TaskSpec = &SPEC;

    fn plan(&self, _seed: u64, obs: &[f32]) -> TimedPath {
        let (tip, slot_x, wall_y) = tip_and_slot(obs);
        plan(tip, slot_x, wall_y)
    }

    fn command(&self, target: V2, obs: &[f32]) -> V2 {
        let (tip, slot_x, wall_y) = tip_and_slot(obs);
        guard_descent(target, tip, slot_x, wall_y)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn descent_guard_holds_a_misaligned_tip_above_the_wall() {
        let (slot_x, wall_y) = (0.4, -1.0);
        let press = V2::new(slot_x, wall_y - 0.21);
        let hover = V2::new(slot_x, wall_y + HOVER_HEIGHT);
        // Misaligned above the wall (or resting on it): held at the hover height.
        for tip in [V2::new(0.42, -0.9), V2::new(0.38, wall_y)] {
            assert_eq!(guard_descent(press, tip, slot_x, wall_y), hover);
        }
        // Aligned, or already inside the entrance: the command passes unchanged.
        for tip in [V2::new(0.404, -0.9), V2::new(0.409, wall_y - 0.001)] {
            assert_eq!(guard_descent(press, tip, slot_x, wall_y), press);
        }
        // Commands above the hover height are never lowered or moved.
        let high = V2::new(0.0, wall_y + 0.5);
        assert_eq!(
            guard_descent(high, V2::new(0.3, -0.9), slot_x, wall_y),
            high
        );
    }
}
