//! The segmentation that produced the attitude, for the stages after it (the pseudo-level
//! scan's wall mask and floor heights, sect. 6, and the `--polygons` output): when the attitude
//! comes from re-segmentation, its models replace the first segmentation's patches. Before,
//! the refined segmentation was thrown away and the pseudo-level scan kept the first one's,
//! grown in the robot frame at a tolerance that follows the noise (30 cm at 10 cm), whose
//! patches run across a wall's foot onto the floor.

use super::LevelEstimate;
use super::patches::{Patch, labels_of, rows_span_sorted};
use super::refine::Model;

/// Replaces `est`'s patches and labels by the refined `models` (each a patch of its members;
/// a point the refined segmentation left out, a corner or a wall's foot in reach of two
/// models, is unlabelled).
pub(crate) fn adopt_refined(est: &mut LevelEstimate, models: Vec<Model>) {
    let Some(grid) = &est.grid else {
        return;
    };
    let patches: Vec<Patch> = models
        .into_iter()
        .filter(|m| !m.members.is_empty())
        .map(|m| Patch {
            row_range: rows_span_sorted(&m.members, grid.cols),
            fit: m.fit,
            kind: m.kind,
            members: m.members,
        })
        .collect();
    est.labels = labels_of(grid.points.len(), &patches);
    est.patches = patches;
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::level::SurfaceKind;
    use crate::level::grid::{PlaneFit, PoseGrid};
    use crate::level::patches::UNLABELLED;
    use crate::scan::Scan;
    use nalgebra::{Point3, Vector3};

    fn fit() -> PlaneFit {
        PlaneFit {
            centroid: Point3::origin(),
            normal: Vector3::x(),
            in_plane: [(1.0, Vector3::y()), (1.0, Vector3::z())],
            n: 2,
            weight: 2.0,
            dn2: 1.0,
            residual_ss: 0.0,
        }
    }

    /// Three scans of 10 rays, every reading 2 m: a grid of 3 rows by 10 columns.
    fn estimate() -> LevelEstimate {
        let scans: Vec<Scan> = [-0.1, 0.0, 0.1]
            .iter()
            .map(|&e| {
                let mut s = Scan::with_even_bearings(10, -0.5, 0.5);
                s.elevation = Some(e);
                s.readings = vec![Some(2.0); 10];
                s.valid = vec![true; 10];
                s
            })
            .collect();
        let mut est = LevelEstimate::empty(0.01);
        est.grid = Some(PoseGrid::from_scans(&scans).unwrap());
        est.labels = vec![0; 30];
        est
    }

    #[test]
    fn refined_models_become_the_patches_and_labels() {
        let mut est = estimate();
        let model = |kind, members: Vec<usize>| Model {
            kind,
            fit: fit(),
            members,
        };
        let models = vec![
            model(SurfaceKind::Wall, vec![1, 2, 12, 23]),
            model(SurfaceKind::Wall, Vec::new()),
            model(SurfaceKind::Floor, vec![20, 21]),
        ];
        adopt_refined(&mut est, models);
        // The empty model is dropped; the floor is the second patch.
        assert_eq!(est.patches.len(), 2);
        assert_eq!(est.patches[0].kind, SurfaceKind::Wall);
        assert_eq!(est.patches[0].row_range, (0, 2));
        assert_eq!(est.patches[1].kind, SurfaceKind::Floor);
        assert_eq!(est.patches[1].row_range, (2, 2));
        for i in 0..30 {
            let want = match i {
                1 | 2 | 12 | 23 => 0,
                20 | 21 => 1,
                _ => UNLABELLED,
            };
            assert_eq!(est.labels[i], want, "point {i}");
        }
    }
}
