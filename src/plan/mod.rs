//! A floor plan (the paper's `.wall` file, its Fig. 14): vertical walls over polylines, the floor
//! plane z = 0, an optional ceiling, and optional robot poses. Plain types with no I/O;
//! `formats::wall` reads a plan and [`Plan::validate`] checks it.
//!
//! - [`Segment`] and its primitives (`segment`): distance, ray crossing, bounds;
//! - `grid`: the spatial index over a plan's segments (ray casting, searches near a point);
//! - `outline`: closed polylines and the inside tests behind free space.

pub(crate) mod grid;
pub(crate) mod outline;
pub(crate) mod segment;

pub use segment::Segment;

use crate::geometry::Pose;
use nalgebra::Point2;

/// Largest coordinate a plan may have, in any axis, and largest wall height \[m\]: 10,000 km.
/// Far beyond any building (UTM coordinates, up to 10^7 m, still pass); beyond it, sums and
/// products of coordinates start to lose the millimetres the simulator works in.
pub const MAX_COORDINATE: f64 = 1e7;

#[derive(Clone, Debug, PartialEq)]
pub struct Plan {
    /// Height of every wall above the floor \[m\]; > 0.
    pub wall_height: f64,
    /// Polylines of at least two distinct points; each segment is a wall from z = 0 to
    /// `wall_height` (zero-length pieces, where a point repeats, are no wall).
    pub walls: Vec<Vec<Point2<f64>>>,
    /// A ceiling plane at `wall_height`.
    pub ceiling: bool,
    /// Robot poses in chronological order (angles in radians here; degrees in the file).
    pub poses: Vec<Pose>,
}

/// What is wrong with a plan, and where: `path` is the JSON path of the `.wall` file
/// (`wallheight`, `walls[3]`, `poses[2][1]`).
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("{path}: {message}")]
pub struct PlanError {
    pub path: String,
    pub message: String,
}

fn plan_error(path: impl Into<String>, message: impl Into<String>) -> PlanError {
    PlanError {
        path: path.into(),
        message: message.into(),
    }
}

/// A number for a message: huge ones in exponent form (Rust prints every digit otherwise),
/// as `formats::limits` does.
fn show(v: f64) -> String {
    if v.is_finite() && v.abs() >= 1e7 {
        format!("{v:e}")
    } else {
        v.to_string()
    }
}

/// `v` as a coordinate: finite and within [`MAX_COORDINATE`].
fn check_coordinate(v: f64, path: impl FnOnce() -> String) -> Result<(), PlanError> {
    if v.is_finite() && v.abs() <= MAX_COORDINATE {
        Ok(())
    } else {
        Err(plan_error(
            path(),
            format!(
                "{} m is beyond the limit of +-{MAX_COORDINATE:e} m for a plan",
                show(v)
            ),
        ))
    }
}

impl Plan {
    /// Checks what the rest of the crate relies on: a positive wall height, walls of at least
    /// two distinct points, finite coordinates within [`MAX_COORDINATE`], finite pose angles.
    /// The first problem found is the error.
    pub fn validate(&self) -> Result<(), PlanError> {
        let h = self.wall_height;
        if !(h > 0.0 && h.is_finite()) {
            return Err(plan_error(
                "wallheight",
                format!("must be a positive number of metres, not {h}"),
            ));
        }
        check_coordinate(h, || "wallheight".into())?;
        for (i, wall) in self.walls.iter().enumerate() {
            if wall.len() < 2 {
                return Err(plan_error(
                    format!("walls[{i}]"),
                    format!("a wall needs at least 2 points, this has {}", wall.len()),
                ));
            }
            for (j, p) in wall.iter().enumerate() {
                check_coordinate(p.x, || format!("walls[{i}][{j}][0]"))?;
                check_coordinate(p.y, || format!("walls[{i}][{j}][1]"))?;
            }
            // A wall that never leaves its first point has no length: nothing to see, and no
            // side to be inside of.
            if wall.iter().all(|p| *p == wall[0]) {
                return Err(plan_error(
                    format!("walls[{i}]"),
                    format!(
                        "all {} points are the same point [{}, {}]; a wall needs two distinct \
                         points",
                        wall.len(),
                        wall[0].x,
                        wall[0].y
                    ),
                ));
            }
        }
        for (i, p) in self.poses.iter().enumerate() {
            for (k, v) in [p.x, p.y, p.z].into_iter().enumerate() {
                check_coordinate(v, || format!("poses[{i}][{k}]"))?;
            }
            for (k, v) in [p.rz, p.ry, p.rx].into_iter().enumerate() {
                if !v.is_finite() {
                    return Err(plan_error(
                        format!("poses[{i}][{}]", k + 3),
                        "an angle must be a finite number of degrees",
                    ));
                }
            }
        }
        Ok(())
    }

    /// Every wall segment of every polyline (zero-length pieces skipped).
    pub fn segments(&self) -> Vec<Segment> {
        self.walls.iter().flat_map(|w| wall_pieces(w)).collect()
    }

    /// Distance from `p` to the nearest wall, infinite for a plan with no walls.
    pub fn distance_to_walls(&self, p: &Point2<f64>) -> f64 {
        self.segments()
            .iter()
            .map(|s| s.distance_to(p))
            .fold(f64::INFINITY, f64::min)
    }

    /// Axis-aligned bounds of all wall points: (min, max).
    pub fn bounds(&self) -> Option<(Point2<f64>, Point2<f64>)> {
        segment::bounds(self.walls.iter().flatten().copied())
    }
}

/// A rectangular room `w` x `h` with its corner at the origin: the scene of many unit tests.
/// One wall polyline's segments, zero-length pieces skipped.
pub(crate) fn wall_pieces(wall: &[Point2<f64>]) -> impl Iterator<Item = Segment> + '_ {
    wall.windows(2)
        .map(|p| Segment { a: p[0], b: p[1] })
        .filter(|s| s.length() > 0.0)
}

#[cfg(test)]
pub(crate) fn box_plan(w: f64, h: f64, height: f64, ceiling: bool) -> Plan {
    Plan {
        wall_height: height,
        walls: vec![vec![
            Point2::new(0.0, 0.0),
            Point2::new(w, 0.0),
            Point2::new(w, h),
            Point2::new(0.0, h),
            Point2::new(0.0, 0.0),
        ]],
        ceiling,
        poses: vec![],
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn err(plan: &Plan) -> String {
        plan.validate().unwrap_err().to_string()
    }

    #[test]
    fn a_box_room_is_valid() {
        let mut plan = box_plan(4.0, 3.0, 2.5, true);
        plan.poses.push(Pose::new(1.0, 1.0, 0.45, 7.0, 0.1, -0.1));
        assert_eq!(plan.validate(), Ok(()));
    }

    #[test]
    fn degenerate_walls_are_named_by_their_path() {
        let p = Point2::new(5.0, 5.0);
        let mut plan = box_plan(10.0, 8.0, 3.0, false);
        plan.walls.push(vec![p, p, p]);
        assert_eq!(
            err(&plan),
            "walls[1]: all 3 points are the same point [5, 5]; a wall needs two distinct points"
        );
        plan.walls[1] = vec![p];
        assert_eq!(
            err(&plan),
            "walls[1]: a wall needs at least 2 points, this has 1"
        );
        // Repeated points inside a wall are only zero-length pieces, skipped.
        plan.walls[1] = vec![p, p, Point2::new(6.0, 5.0)];
        assert_eq!(plan.validate(), Ok(()));
        assert_eq!(plan.segments().len(), 5);
    }

    #[test]
    fn absurd_sizes_are_refused() {
        let mut plan = box_plan(10.0, 8.0, 3.0, false);
        plan.walls[0][2].y = 2e7;
        assert_eq!(
            err(&plan),
            "walls[0][2][1]: 2e7 m is beyond the limit of +-1e7 m for a plan"
        );
        let mut plan = box_plan(10.0, 8.0, 1e300, false);
        assert!(err(&plan).starts_with("wallheight: 1e300 m is beyond"));
        plan.wall_height = f64::NAN;
        assert_eq!(
            err(&plan),
            "wallheight: must be a positive number of metres, not NaN"
        );
        let mut plan = box_plan(10.0, 8.0, 3.0, false);
        plan.poses.push(Pose::new(1.0, -1e8, 0.4, 0.0, 0.0, 0.0));
        assert!(err(&plan).starts_with("poses[0][1]: -1e8 m is beyond"));
        plan.poses[0] = Pose::new(1.0, 1.0, 0.4, 0.0, f64::INFINITY, 0.0);
        assert_eq!(
            err(&plan),
            "poses[0][4]: an angle must be a finite number of degrees"
        );
        // UTM-sized coordinates are fine.
        let mut plan = box_plan(10.0, 8.0, 3.0, false);
        plan.walls[0].iter_mut().for_each(|p| p.y += 5_800_000.0);
        assert_eq!(plan.validate(), Ok(()));
    }
}
