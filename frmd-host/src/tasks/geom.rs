//! Planar geometry for the tasks and their experts: 2-D vectors, minimum-jerk timing and smooth
//! paths made of cubic Bezier segments, traversed at a prescribed arc length.
use std::ops::{Add, Mul, Sub};

/// A 2-D vector or point, metres (or metres per second, as the context says).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct V2 {
    pub x: f64,
    pub y: f64,
}

impl V2 {
    pub const ZERO: V2 = V2 { x: 0.0, y: 0.0 };

    pub const fn new(x: f64, y: f64) -> Self {
        Self { x, y }
    }

    pub fn dot(self, other: V2) -> f64 {
        self.x * other.x + self.y * other.y
    }

    /// z component of the 3-D cross product.
    pub fn cross(self, other: V2) -> f64 {
        self.x * other.y - self.y * other.x
    }

    pub fn norm(self) -> f64 {
        self.x.hypot(self.y)
    }

    /// Unit vector in the same direction; the zero vector stays zero.
    pub fn unit(self) -> V2 {
        let n = self.norm();
        if n > 0.0 {
            self * (1.0 / n)
        } else {
            V2::ZERO
        }
    }

    /// Rotated by +90 degrees (counter-clockwise).
    pub fn perp(self) -> V2 {
        V2::new(-self.y, self.x)
    }

    pub fn lerp(self, other: V2, u: f64) -> V2 {
        self + (other - self) * u
    }

    pub fn to_f32(self) -> [f32; 2] {
        [self.x as f32, self.y as f32]
    }

    pub fn to_array(self) -> [f64; 2] {
        [self.x, self.y]
    }
}

impl Add for V2 {
    type Output = V2;
    fn add(self, o: V2) -> V2 {
        V2::new(self.x + o.x, self.y + o.y)
    }
}

impl Sub for V2 {
    type Output = V2;
    fn sub(self, o: V2) -> V2 {
        V2::new(self.x - o.x, self.y - o.y)
    }
}

impl Mul<f64> for V2 {
    type Output = V2;
    fn mul(self, k: f64) -> V2 {
        V2::new(self.x * k, self.y * k)
    }
}

/// Minimum-jerk time scaling: 0 at u <= 0, 1 at u >= 1, zero velocity and acceleration at both
/// ends (10u^3 - 15u^4 + 6u^5).
pub fn min_jerk(u: f64) -> f64 {
    let u = u.clamp(0.0, 1.0);
    u * u * u * (10.0 + u * (-15.0 + 6.0 * u))
}

/// A cubic Bezier segment.
#[derive(Clone, Copy, Debug)]
pub struct Cubic {
    pub p0: V2,
    pub p1: V2,
    pub p2: V2,
    pub p3: V2,
}

impl Cubic {
    /// The straight segment from `a` to `b`.
    pub fn line(a: V2, b: V2) -> Self {
        Self {
            p0: a,
            p1: a.lerp(b, 1.0 / 3.0),
            p2: a.lerp(b, 2.0 / 3.0),
            p3: b,
        }
    }

    /// The quadratic Bezier with control point `c`, raised to a cubic.
    pub fn quadratic(a: V2, c: V2, b: V2) -> Self {
        Self {
            p0: a,
            p1: a.lerp(c, 2.0 / 3.0),
            p2: b.lerp(c, 2.0 / 3.0),
            p3: b,
        }
    }

    /// The cubic approximation of the circular arc from `start` to `end` that arrives at `end`
    /// heading along the unit vector `end_heading` (the arc of least curvature with that end
    /// tangent; its curvature is 2 sin(phi) / |end - start|, phi the angle between the chord and
    /// `end_heading`). Degenerates to a straight segment when the chord is along the heading.
    pub fn arc_to(start: V2, end: V2, end_heading: V2) -> Self {
        let chord = end - start;
        let length = chord.norm();
        let along = chord.unit();
        // The start heading mirrors the end heading about the chord.
        let start_heading = along * (2.0 * along.dot(end_heading)) - end_heading;
        let cos_half = ((1.0 + along.dot(end_heading).clamp(-1.0, 1.0)) / 2.0).sqrt();
        let handle = length / (3.0 * (cos_half * cos_half).max(0.25));
        Self {
            p0: start,
            p1: start + start_heading * handle,
            p2: end - end_heading * handle,
            p3: end,
        }
    }

    pub fn at(&self, u: f64) -> V2 {
        let v = 1.0 - u;
        self.p0 * (v * v * v)
            + self.p1 * (3.0 * v * v * u)
            + self.p2 * (3.0 * v * u * u)
            + self.p3 * (u * u * u)
    }
}

/// Samples per segment in the arc-length table.
const ARC_SAMPLES: usize = 256;

/// A chain of cubic segments with an arc-length table, so a point can be placed at a given
/// distance along the path. Positions are exact points of the curve (the table only maps
/// distance to the curve parameter).
#[derive(Clone, Debug)]
pub struct SmoothPath {
    segments: Vec<Cubic>,
    /// Cumulative length at each table entry; entry `k` is segment `k / ARC_SAMPLES`,
    /// parameter `(k % ARC_SAMPLES) / ARC_SAMPLES`, plus one final entry.
    cumulative: Vec<f64>,
}

impl SmoothPath {
    /// Builds the path; `segments` must be non-empty and chained end to start.
    pub fn new(segments: Vec<Cubic>) -> Self {
        let mut cumulative = Vec::with_capacity(segments.len() * ARC_SAMPLES + 1);
        let mut total = 0.0;
        let mut last = segments.first().map_or(V2::ZERO, |s| s.p0);
        for seg in &segments {
            for k in 0..ARC_SAMPLES {
                let p = seg.at(k as f64 / ARC_SAMPLES as f64);
                total += (p - last).norm();
                cumulative.push(total);
                last = p;
            }
        }
        if let Some(seg) = segments.last() {
            total += (seg.p3 - last).norm();
        }
        cumulative.push(total);
        Self {
            segments,
            cumulative,
        }
    }

    pub fn length(&self) -> f64 {
        self.cumulative.last().copied().unwrap_or(0.0)
    }

    pub fn start(&self) -> V2 {
        self.segments.first().map_or(V2::ZERO, |s| s.p0)
    }

    pub fn end(&self) -> V2 {
        self.segments.last().map_or(V2::ZERO, |s| s.p3)
    }

    /// The point at distance `s` along the path (clamped to the ends).
    pub fn at_length(&self, s: f64) -> V2 {
        if self.segments.is_empty() {
            return V2::ZERO;
        }
        if s <= 0.0 {
            return self.start();
        }
        if s >= self.length() {
            return self.end();
        }
        // First table entry with cumulative length >= s.
        let k = self.cumulative.partition_point(|&c| c < s).max(1);
        let (c0, c1) = (self.cumulative[k - 1], self.cumulative[k]);
        let frac = if c1 > c0 { (s - c0) / (c1 - c0) } else { 0.0 };
        let global = (k - 1) as f64 + frac;
        let seg_index =
            ((global / ARC_SAMPLES as f64).floor() as usize).min(self.segments.len() - 1);
        let u = (global - (seg_index * ARC_SAMPLES) as f64) / ARC_SAMPLES as f64;
        self.segments[seg_index].at(u.clamp(0.0, 1.0))
    }
}

/// A path traversed once with minimum-jerk timing over `duration` seconds, then held at its end.
#[derive(Clone, Debug)]
pub struct TimedPath {
    pub path: SmoothPath,
    pub duration: f64,
}

impl TimedPath {
    /// Duration from an average speed (m/s), at least `min_duration` seconds.
    pub fn with_speed(path: SmoothPath, average_speed: f64, min_duration: f64) -> Self {
        let duration = (path.length() / average_speed).max(min_duration);
        Self { path, duration }
    }

    /// Position at time `t` seconds after the start.
    pub fn at(&self, t: f64) -> V2 {
        let u = if self.duration > 0.0 {
            t / self.duration
        } else {
            1.0
        };
        self.path.at_length(self.path.length() * min_jerk(u))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn min_jerk_endpoints_and_symmetry() {
        assert_eq!(min_jerk(0.0), 0.0);
        assert_eq!(min_jerk(1.0), 1.0);
        assert!((min_jerk(0.5) - 0.5).abs() < 1e-12);
        assert!((min_jerk(0.3) + min_jerk(0.7) - 1.0).abs() < 1e-12);
    }

    #[test]
    fn arc_to_matches_circle() {
        // Quarter circle of radius 1 from (1, 0) to (0, 1) arriving heading -x.
        let arc = Cubic::arc_to(V2::new(1.0, 0.0), V2::new(0.0, 1.0), V2::new(-1.0, 0.0));
        for k in 0..=10 {
            let r = arc.at(k as f64 / 10.0).norm();
            assert!((r - 1.0).abs() < 1e-3, "radius {r}");
        }
        let line = Cubic::arc_to(V2::ZERO, V2::new(2.0, 0.0), V2::new(1.0, 0.0));
        assert!((line.at(0.5) - V2::new(1.0, 0.0)).norm() < 1e-12);
    }

    #[test]
    fn arc_length_of_line_and_quarter_circle() {
        let line = SmoothPath::new(vec![Cubic::line(V2::new(0.0, 0.0), V2::new(3.0, 4.0))]);
        assert!((line.length() - 5.0).abs() < 1e-9);
        let mid = line.at_length(2.5);
        assert!((mid - V2::new(1.5, 2.0)).norm() < 1e-6);
        // Standard cubic approximation of a unit quarter circle: length ~ pi/2.
        let k = 0.552_284_75;
        let arc = SmoothPath::new(vec![Cubic {
            p0: V2::new(1.0, 0.0),
            p1: V2::new(1.0, k),
            p2: V2::new(k, 1.0),
            p3: V2::new(0.0, 1.0),
        }]);
        assert!((arc.length() - std::f64::consts::FRAC_PI_2).abs() < 1e-3);
        let p = arc.at_length(arc.length() / 2.0);
        assert!((p.norm() - 1.0).abs() < 1e-3 && (p.x - p.y).abs() < 1e-3);
    }
}
