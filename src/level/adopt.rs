//! The segmentation that produced the attitude, for the stages after it (the pseudo-level
//! scan's wall mask and floor heights, sect. 6, and the `--polygons` output): when the attitude
//! comes from re-segmentation, its models replace the first segmentation's patches. Before,
//! the refined segmentation was thrown away and the pseudo-level scan kept the first one's,
//! grown in the robot frame at a tolerance that follows the noise (30 cm at 10 cm), whose
//! patches run across a wall's foot onto the floor.

use super::LevelEstimate;
use super::patches::{Patch, UNLABELLED};
use super::refine::Model;

/// Replaces `est`'s patches and labels by the refined `models` (each a patch of its members;
/// a point the refined segmentation left out, a corner or a wall's foot in reach of two
/// models, is unlabelled).
pub(crate) fn adopt_refined(est: &mut LevelEstimate, models: Vec<Model>) {
    let Some(grid) = &est.grid else {
        return;
    };
    let cols = grid.cols.max(1);
    let mut labels = vec![UNLABELLED; grid.points.len()];
    let patches: Vec<Patch> = models
        .into_iter()
        .filter(|m| !m.members.is_empty())
        .enumerate()
        .map(|(k, m)| {
            for &i in &m.members {
                labels[i] = k as u32;
            }
            let rows = m.members.iter().map(|&i| i / cols);
            let row_range = (rows.clone().min().unwrap_or(0), rows.max().unwrap_or(0));
            Patch {
                fit: m.fit,
                kind: m.kind,
                members: m.members,
                row_range,
            }
        })
        .collect();
    est.patches = patches;
    est.labels = labels;
}
