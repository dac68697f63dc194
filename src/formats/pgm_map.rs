//! ROS `map_server` maps: an occupancy grid as a PGM image and the YAML file that describes it,
//! as `map_saver` writes them (ROS 1 map_server, ROS 2 nav2_map_server: `image`, `mode`,
//! `resolution`, `origin`, `negate`, `occupied_thresh`, `free_thresh`).
//!
//! Binary PGM (P5), 8 bits, the image's first row the map's top (largest y), in map_saver's
//! three values: 0 (black) occupied, 254 (white) free, 205 (grey) unknown. A cell is occupied
//! when its occupancy probability is above [`Classes::occupied`], free below [`Classes::free`];
//! the YAML's thresholds are map_saver's, which read those three values back as they were meant.
//! `origin` is the world pose of the lower-left pixel's corner, `[x, y, yaw]`.

use crate::occupancy::OccupancyGrid;
use std::fmt::Write as _;

/// How a cell's probability becomes occupied, free or unknown.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Classes {
    /// Above this probability a cell is occupied. Default 0.65 (map_saver's): one hit.
    pub occupied: f64,
    /// Below this probability a cell is free. Default 0.35: two rays through it (one leaves
    /// it at 0.4).
    pub free: f64,
}

impl Default for Classes {
    fn default() -> Self {
        Self {
            occupied: 0.65,
            free: 0.35,
        }
    }
}

/// The YAML's `occupied_thresh` and `free_thresh`, map_saver's: pixel value v reads as
/// probability (255 - v) / 255, so 0 is occupied, 254 free and 205 (0.196...) unknown.
pub const OCCUPIED_THRESH: f64 = 0.65;
pub const FREE_THRESH: f64 = 0.196;

/// Pixel values, as map_saver writes them.
pub const OCCUPIED: u8 = 0;
pub const FREE: u8 = 254;
pub const UNKNOWN: u8 = 205;

/// The grid as a binary PGM.
pub fn pgm_bytes(grid: &OccupancyGrid, t: &Classes) -> Vec<u8> {
    let mut out = format!(
        "P5\n# CREATOR: levelscan map {:.3} m/pix\n{} {}\n255\n",
        grid.resolution, grid.width, grid.height
    )
    .into_bytes();
    out.reserve(grid.width * grid.height);
    for row in (0..grid.height).rev() {
        for col in 0..grid.width {
            let p = grid.probability(col, row);
            out.push(if p > t.occupied {
                OCCUPIED
            } else if p < t.free {
                FREE
            } else {
                UNKNOWN
            });
        }
    }
    out
}

/// The map's YAML, naming `image` (a path relative to the YAML file, as map_server reads it).
pub fn yaml_text(image: &str, grid: &OccupancyGrid) -> String {
    let mut s = String::new();
    // A file name with YAML's special characters is quoted (JSON strings are YAML).
    let name = if image
        .chars()
        .all(|c| c.is_ascii_alphanumeric() || "._-/".contains(c))
    {
        image.to_string()
    } else {
        serde_json::to_string(image).unwrap_or_default()
    };
    let _ = writeln!(s, "image: {name}");
    let _ = writeln!(s, "mode: trinary");
    let _ = writeln!(s, "resolution: {}", grid.resolution);
    let _ = writeln!(s, "origin: [{}, {}, 0.0]", grid.origin[0], grid.origin[1]);
    let _ = writeln!(s, "negate: 0");
    let _ = writeln!(s, "occupied_thresh: {OCCUPIED_THRESH}");
    let _ = writeln!(s, "free_thresh: {FREE_THRESH}");
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid() -> OccupancyGrid {
        // 3 x 2 cells: row 0 (bottom) occupied, free (p 0.27), unseen; row 1 (top) free, free,
        // occupied.
        OccupancyGrid {
            resolution: 0.1,
            origin: [-1.5, 2.0],
            width: 3,
            height: 2,
            log_odds: vec![2.0, -1.0, 0.0, -1.5, -2.0, 3.0],
        }
    }

    #[test]
    fn pgm_rows_run_from_the_top_in_map_savers_values() {
        let bytes = pgm_bytes(&grid(), &Classes::default());
        let header = b"P5\n# CREATOR: levelscan map 0.100 m/pix\n3 2\n255\n";
        assert_eq!(&bytes[..header.len()], header);
        assert_eq!(
            &bytes[header.len()..],
            &[FREE, FREE, OCCUPIED, OCCUPIED, FREE, UNKNOWN]
        );
    }

    #[test]
    fn yaml_says_where_the_lower_left_corner_is() {
        let y = yaml_text("office map.pgm", &grid());
        assert_eq!(
            y,
            "image: \"office map.pgm\"\nmode: trinary\nresolution: 0.1\norigin: [-1.5, 2, 0.0]\n\
             negate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.196\n"
        );
    }
}
