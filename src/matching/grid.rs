//! Exact nearest-neighbour search over 2D points in a hashed uniform grid, for ICP's data
//! association (one query per source point per iteration).
//!
//! A kd-tree answers any query in logarithmic time but pays a descent and a bucket scan even
//! when the answer is a few centimetres away, which is the common case once ICP is near its
//! optimum; and a scan's tree must be built anew for every scan. Here a point goes into the
//! cell it falls in (O(1), so a growing map just inserts), and a query visits rings of cells
//! around its own, skipping cells farther than the best so far, until nothing unvisited can be
//! closer or within the search radius. A query whose neighbour is close is settled by its own
//! cell alone. The answer is the nearest point exactly (as a kd-tree's); only exact ties may
//! pick a different one of the tied points.

use nalgebra::Point2;
use std::collections::HashMap;
use std::hash::{BuildHasherDefault, Hasher};

/// Cell edge of the metascan map's grid \[m\]. Default for [`PointGrid::default`]: 0.25,
/// half of ICP's 0.5 m association distance, so a bounded query visits at most the 5 × 5
/// cells around its own while a wall through a cell of the 5 cm voxel map puts only a handful
/// of voxels in it. Measured on the intel log (instructions of `levelscan match`): 0.5 costs
/// 4% more.
pub(crate) const CELL: f64 = 0.25;

/// Cell edge of one scan's grid at one ray per degree \[m\]: a scan's points are sparser
/// than the map's voxels away from the scanner, and a query pays more per cell visited than
/// per point compared. Denser scans get proportionally smaller cells (`scan_cell`). Measured
/// (instructions of `levelscan match`): on the intel log (1 ray per degree) 0.125 +17%,
/// 0.25 +3%, 1.0 +3% against 0.5; on the first 700 scans of freiburg-079 (2 rays per degree,
/// pairwise) 0.25 and 0.125 both 9% below 0.5.
pub(crate) const SCAN_CELL: f64 = 0.5;

/// The grid cell for a scan whose points (in ray order, scanner at the origin) span their
/// bearings at `SCAN_CELL` per degree of mean ray step, within 0.125 to 0.5 m. Any cell gives
/// the same answers; this only picks a fast one.
pub(crate) fn scan_cell(points: &[Point2<f64>]) -> f64 {
    let (Some(first), Some(last)) = (points.first(), points.last()) else {
        return SCAN_CELL;
    };
    if points.len() < 2 {
        return SCAN_CELL;
    }
    let span = (last.y.atan2(last.x) - first.y.atan2(first.x))
        .abs()
        .to_degrees();
    let step = span / (points.len() - 1) as f64;
    if step.is_finite() {
        (SCAN_CELL * step).clamp(0.125, SCAN_CELL)
    } else {
        SCAN_CELL
    }
}

/// Cells per tile side, as a power of two: cells are stored in dense 16 × 16 tiles (4 m at the
/// default cell) found by hashing, so the cells of one query are mostly in one tile and cost
/// one hash lookup rather than one each.
const TILE_BITS: i32 = 4;
const TILE: i32 = 1 << TILE_BITS;

/// Rings a query searches before it gives up on the grid and scans every point (only an
/// unbounded query far from all points, or one at absurd coordinates, gets there).
const MAX_RINGS: i32 = 64;

/// Queries farther than this from the origin scan every point \[m\]: there the rounding of
/// `x / cell` could misplace a point by more than the search's 1e-9 m margin.
const FAR: f64 = 1e5;

/// No point: an empty cell's head, a chain's end, a tile not allocated.
const END: u32 = u32::MAX;

/// Largest dense tile directory (entries): a grid whose tiles span more falls back to the
/// hash alone (a scan's or a building's grid needs a few hundred to a few thousand).
const MAX_DIRECTORY: i64 = 1 << 14;

/// Tiles of margin the dense directory gets on each side when it grows, so a growing map
/// rebuilds it only now and then.
const DIRECTORY_MARGIN: i32 = 2;

/// Tile and voxel keys are small integers: one multiply spreads them over the hash's bits (both ends:
/// the table takes its bucket from the low bits and its tag from the high ones). SipHash,
/// the standard default, guards against chosen keys, which costs several times more here.
#[derive(Default)]
pub(crate) struct CellHasher(u64);

impl Hasher for CellHasher {
    fn finish(&self) -> u64 {
        let h = self.0.wrapping_mul(0x9E37_79B9_7F4A_7C15);
        h ^ (h >> 29)
    }

    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.0 = self.0.rotate_left(8) ^ u64::from(b);
        }
    }

    fn write_i32(&mut self, v: i32) {
        self.0 = self.0.rotate_left(32) ^ u64::from(v as u32);
    }

    fn write_i64(&mut self, v: i64) {
        self.0 = self.0.wrapping_mul(0x9E37_79B9_7F4A_7C15).rotate_left(29) ^ v as u64;
    }
}

type TileMap = HashMap<(i32, i32), u32, BuildHasherDefault<CellHasher>>;

/// [`floor_i64`] saturated to `i32` (far outside any map; the same function places points and
/// queries, so the grid stays consistent there too). Every key of a map or a query within
/// `FAR` fits an `i32` with room to spare: those take a 32-bit truncation and one down-step,
/// the rest the general path (NaN too, failing the bound).
#[inline]
fn floor_i32(v: f64) -> i32 {
    if v.abs() < 2_147_483_647.0 {
        let t = v as i32;
        if f64::from(t) > v { t - 1 } else { t }
    } else {
        floor_i64(v).clamp(i64::from(i32::MIN), i64::from(i32::MAX)) as i32
    }
}

/// `v.floor() as i64` without the libm call: exact below 2^52 (the cast truncates, and one
/// down-step fixes negative fractions); beyond, and for NaN, `v` is integral and the cast is
/// the same.
#[inline]
pub(crate) fn floor_i64(v: f64) -> i64 {
    if v.is_nan() || v.abs() >= 4_503_599_627_370_496.0 {
        return v as i64;
    }
    let t = v as i64;
    if (t as f64) > v { t - 1 } else { t }
}

/// The next float above `x` (`f64::next_up`, which needs Rust 1.86): a bound `d2 <= x` is
/// `d2 < just_above(x)`.
fn just_above(x: f64) -> f64 {
    if x.is_nan() || x == f64::INFINITY {
        x
    } else if x == 0.0 {
        f64::from_bits(1)
    } else if x > 0.0 {
        f64::from_bits(x.to_bits() + 1)
    } else {
        f64::from_bits(x.to_bits() - 1)
    }
}

/// What a query found: the item stored with the point, the point, its squared distance.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Hit {
    pub item: u32,
    pub point: Point2<f64>,
    pub dist2: f64,
}

/// A point with its item, chained to the next point of its cell (`END` at the chain's end).
#[derive(Clone, Copy, Debug)]
struct Entry {
    point: Point2<f64>,
    item: u32,
    next: u32,
}

/// Points with an item each (an index into the owner's arrays), chained per cell.
#[derive(Clone, Debug)]
pub(crate) struct PointGrid {
    inv_cell: f64,
    cell: f64,
    /// Tile key -> index into `tiles`.
    index: TileMap,
    /// Each cell's most recently added point (an index into `points`), or `END`.
    tiles: Vec<[u32; (TILE * TILE) as usize]>,
    points: Vec<Entry>,
    /// Smallest and largest occupied cell per axis: a search that has covered them is done.
    lo: (i32, i32),
    hi: (i32, i32),
    /// The tiles of `index` again, densely over a box of tile keys (from `directory_lo`,
    /// `directory_size` tiles per axis), `END` where there is none: a query looks a tile up
    /// with one subtraction and one load, not a hash probe. `directory_all`: every tile is in
    /// it (else the box grew too big and lookups outside it go to the hash).
    directory: Vec<u32>,
    directory_lo: (i32, i32),
    directory_size: (i32, i32),
    directory_all: bool,
}

impl Default for PointGrid {
    fn default() -> Self {
        Self::new(CELL)
    }
}

/// The last tile a query looked up (cells of one query mostly share a tile).
struct TileCursor {
    key: (i32, i32),
    tile: u32,
}

impl PointGrid {
    /// An empty grid of `cell`-metre cells.
    pub(crate) fn new(cell: f64) -> Self {
        Self {
            inv_cell: 1.0 / cell,
            cell,
            index: TileMap::default(),
            tiles: Vec::new(),
            points: Vec::new(),
            lo: (i32::MAX, i32::MAX),
            hi: (i32::MIN, i32::MIN),
            directory: Vec::new(),
            directory_lo: (0, 0),
            directory_size: (0, 0),
            directory_all: true,
        }
    }

    /// A grid of `cell`-metre cells over `points`, each with its index as item, sized for them
    /// once: the tile directory spans their box and their room is reserved before the first
    /// insert, where inserting into an empty grid regrows both as the box and the count grow.
    pub(crate) fn from_points(cell: f64, points: &[Point2<f64>]) -> Self {
        let mut grid = Self::new(cell);
        // Keys grow with the coordinates, so the corners of the points' box give the tiles'.
        let (mut lo, mut hi) = (
            Point2::new(f64::INFINITY, f64::INFINITY),
            Point2::new(f64::NEG_INFINITY, f64::NEG_INFINITY),
        );
        for p in points.iter().filter(|p| p.x.is_finite() && p.y.is_finite()) {
            lo = Point2::new(lo.x.min(p.x), lo.y.min(p.y));
            hi = Point2::new(hi.x.max(p.x), hi.y.max(p.y));
        }
        if lo.x <= hi.x {
            let tile = |p: &Point2<f64>| {
                let key = grid.key(p);
                (key.0 >> TILE_BITS, key.1 >> TILE_BITS)
            };
            let (lo, hi) = (tile(&lo), tile(&hi));
            grid.span_directory(lo, hi);
        }
        grid.points.reserve_exact(points.len());
        for (i, p) in points.iter().enumerate() {
            grid.insert(*p, i as u32);
        }
        grid
    }

    /// The index of tile `t` in the directory, if the directory's box holds it.
    #[inline]
    fn directory_slot(&self, t: (i32, i32)) -> Option<usize> {
        let (x, y) = (
            t.0.wrapping_sub(self.directory_lo.0),
            t.1.wrapping_sub(self.directory_lo.1),
        );
        ((x as u32) < self.directory_size.0 as u32 && (y as u32) < self.directory_size.1 as u32)
            .then(|| (y as usize) * self.directory_size.0 as usize + x as usize)
    }

    /// Records new tile `t` (index `tile`) in the directory, rebuilding it over the box of
    /// all tiles (with a margin) when `t` lies outside its box. Once the box has grown too big
    /// it stays as it is: tiles outside it are found in the hash alone.
    fn add_to_directory(&mut self, t: (i32, i32), tile: u32) {
        if let Some(slot) = self.directory_slot(t) {
            self.directory[slot] = tile;
            return;
        }
        if !self.directory_all {
            return;
        }
        let (mut lo, mut hi) = (t, t);
        for k in self.index.keys() {
            lo = (lo.0.min(k.0), lo.1.min(k.1));
            hi = (hi.0.max(k.0), hi.1.max(k.1));
        }
        if !self.span_directory(lo, hi) {
            // Too spread out: keep the old box, which no longer holds every tile.
            self.directory_all = false;
        }
    }

    /// Rebuilds the directory over the tiles from `lo` to `hi` (with a margin) and fills it
    /// from the hash; false, changing nothing, when that box would be too big.
    fn span_directory(&mut self, lo: (i32, i32), hi: (i32, i32)) -> bool {
        let lo = (lo.0 - DIRECTORY_MARGIN, lo.1 - DIRECTORY_MARGIN);
        let size = (
            i64::from(hi.0) - i64::from(lo.0) + 1 + i64::from(DIRECTORY_MARGIN),
            i64::from(hi.1) - i64::from(lo.1) + 1 + i64::from(DIRECTORY_MARGIN),
        );
        if size.0 * size.1 > MAX_DIRECTORY {
            return false;
        }
        self.directory_lo = lo;
        self.directory_size = (size.0 as i32, size.1 as i32);
        self.directory.clear();
        self.directory.resize((size.0 * size.1) as usize, END);
        let index = std::mem::take(&mut self.index);
        for (&k, &v) in &index {
            if let Some(slot) = self.directory_slot(k) {
                self.directory[slot] = v;
            }
        }
        self.index = index;
        true
    }

    /// The index into `tiles` of tile `t`, if it has one: from the directory inside its box,
    /// from the hash outside it when the directory does not hold every tile.
    #[inline(always)]
    fn tile(&self, t: (i32, i32)) -> u32 {
        match self.directory_slot(t) {
            Some(slot) => self.directory[slot],
            None if self.directory_all => END,
            None => self.index.get(&t).copied().unwrap_or(END),
        }
    }

    fn key(&self, p: &Point2<f64>) -> (i32, i32) {
        (
            floor_i32(p.x * self.inv_cell),
            floor_i32(p.y * self.inv_cell),
        )
    }

    fn slot((x, y): (i32, i32)) -> usize {
        (((y & (TILE - 1)) << TILE_BITS) | (x & (TILE - 1))) as usize
    }

    /// Adds `p` with `item`. Non-finite points are not added (no query could find them).
    pub(crate) fn insert(&mut self, p: Point2<f64>, item: u32) {
        if !(p.x.is_finite() && p.y.is_finite()) {
            return;
        }
        let key = self.key(&p);
        let tile_key = (key.0 >> TILE_BITS, key.1 >> TILE_BITS);
        let tile = match self.tile(tile_key) {
            END => {
                let tile = self.tiles.len() as u32;
                self.tiles.push([END; (TILE * TILE) as usize]);
                self.index.insert(tile_key, tile);
                self.add_to_directory(tile_key, tile);
                tile
            }
            tile => tile,
        };
        let head = &mut self.tiles[tile as usize][Self::slot(key)];
        self.points.push(Entry {
            point: p,
            item,
            next: *head,
        });
        *head = (self.points.len() - 1) as u32;
        self.lo = (self.lo.0.min(key.0), self.lo.1.min(key.1));
        self.hi = (self.hi.0.max(key.0), self.hi.1.max(key.1));
    }

    /// The first point of cell `key`'s chain, or `END`.
    #[inline(always)]
    fn head(&self, key: (i32, i32), cursor: &mut TileCursor) -> u32 {
        let tile_key = (key.0 >> TILE_BITS, key.1 >> TILE_BITS);
        if cursor.key != tile_key {
            cursor.key = tile_key;
            cursor.tile = self.tile(tile_key);
        }
        if cursor.tile == END {
            return END;
        }
        self.tiles[cursor.tile as usize][Self::slot(key)]
    }

    /// The nearest point to `q` with squared distance at most `max_d2`, if any.
    pub(crate) fn nearest_within(&self, q: &Point2<f64>, max_d2: f64) -> Option<Hit> {
        self.search::<false>(q, max_d2).0
    }

    /// [`Self::nearest_within`], with a margin: while a query stays within it of `q` (less,
    /// strictly), no other point can be as near as the one found, so it is still the answer
    /// (and, for a query within the margin, [`Self::again`] gives what this would). The
    /// margin is half the gap between the nearest distance and a lower bound on every other
    /// point's (the second nearest among the points the search tried, the cells it skipped
    /// and the rings it never reached), less 1e-9 m for rounding; when nothing lies within
    /// the bound, the gap between the bound and every point. 0 when the search proved
    /// nothing (every point scanned).
    pub(crate) fn nearest_certified(&self, q: &Point2<f64>, max_d2: f64) -> (Option<Hit>, f64) {
        self.search::<true>(q, max_d2)
    }

    /// What a query at `q` within `max_d2` finds when `point` (with `item`) is known to be
    /// the nearest point to it: `point` if within the bound, the same distance to the bit.
    #[inline]
    pub(crate) fn again(
        q: &Point2<f64>,
        max_d2: f64,
        item: u32,
        point: Point2<f64>,
    ) -> Option<Hit> {
        let (dx, dy) = (point.x - q.x, point.y - q.y);
        let dist2 = dx * dx + dy * dy;
        (dist2 < just_above(max_d2)).then_some(Hit { item, point, dist2 })
    }

    /// The nearest point, and with `CERTIFY` its margin (see `nearest_certified`).
    #[inline(always)]
    fn search<const CERTIFY: bool>(&self, q: &Point2<f64>, max_d2: f64) -> (Option<Hit>, f64) {
        if self.points.is_empty() || !(q.x.abs() < FAR && q.y.abs() < FAR) {
            return (self.scan_all(q, max_d2), 0.0);
        }
        let c = self.cell;
        let (kx, ky) = self.key(q);
        // Offsets of q inside its cell, from its low and its high edge.
        let (fx, fy) = (q.x - kx as f64 * c, q.y - ky as f64 * c);
        let (gx, gy) = (c - fx, c - fy);
        let edges = (fx, fy, gx, gy);
        // A point qualifies when its squared distance is below `limit`: at first just above
        // `max_d2` (so a point at exactly the bound counts), then the best so far.
        let mut found = Found {
            best: END,
            limit: just_above(max_d2),
            second: f64::INFINITY,
        };
        let mut cursor = TileCursor {
            key: (i32::MIN, i32::MIN),
            tile: END,
        };
        // Ring 0, the query's own cell, settles most queries alone.
        let open = 0.0 < found.limit;
        if open && self.holds((kx, ky)) {
            self.walk::<CERTIFY>(self.head((kx, ky), &mut cursor), q, &mut found);
        } else if CERTIFY && !open {
            // A bound below 0 (or NaN) certifies nothing.
            found.second = 0.0;
        }
        // Most queries end here; the rings beyond are out of line, so these do not pay for
        // setting them up.
        if self.searched_enough((kx, ky), 0, edges, &found) {
            return self.certified::<CERTIFY>((kx, ky), 0, edges, &mut found);
        }
        self.search_rings::<CERTIFY>(q, max_d2, (kx, ky), edges, found, cursor)
    }

    /// The answer once rings 0..=`ring` are searched, with its margin under `CERTIFY`.
    #[inline(always)]
    fn certified<const CERTIFY: bool>(
        &self,
        key: (i32, i32),
        ring: i32,
        edges: (f64, f64, f64, f64),
        found: &mut Found,
    ) -> (Option<Hit>, f64) {
        let hit = self.hit(found);
        if !CERTIFY {
            return (hit, 0.0);
        }
        if !self.rings_cover(key, ring) {
            // Every point beyond the rings lies at least this far (as `searched_enough`).
            let reach = self.reach(ring, edges);
            found.second = found
                .second
                .min(if reach > 0.0 { reach * reach } else { 0.0 });
        }
        // Without a hit, `limit` is just above the bound, and every point at least `second`.
        let margin = match hit {
            Some(hit) => 0.5 * (found.second.sqrt() - hit.dist2.sqrt()) - 1e-9,
            None => found.second.sqrt() - found.limit.sqrt() - 1e-9,
        };
        (hit, if margin > 0.0 { margin } else { 0.0 })
    }

    /// Rings 1 and up, after ring 0 left the answer open.
    #[inline(never)]
    fn search_rings<const CERTIFY: bool>(
        &self,
        q: &Point2<f64>,
        max_d2: f64,
        (kx, ky): (i32, i32),
        edges: (f64, f64, f64, f64),
        mut found: Found,
        mut cursor: TileCursor,
    ) -> (Option<Hit>, f64) {
        for ring in 1..MAX_RINGS {
            match ring {
                1 => self.search_ring1::<CERTIFY>(q, (kx, ky), edges, &mut found, &mut cursor),
                _ => self.search_ring::<CERTIFY>(q, (kx, ky), ring, edges, &mut found, &mut cursor),
            }
            if self.searched_enough((kx, ky), ring, edges, &found) {
                return self.certified::<CERTIFY>((kx, ky), ring, edges, &mut found);
            }
        }
        (self.scan_all(q, max_d2), 0.0)
    }

    /// Whether rings 0..=`ring` around cell `(kx, ky)` (q at `edges` from its cell's sides)
    /// hold the answer. Every point outside them lies at least `ring` cells beyond the
    /// nearest side from q (less a margin for the rounding of the cell keys: below 1e-10 m
    /// within `FAR`), so the next ring is searched only while it may hold a point below the
    /// limit.
    #[inline(always)]
    fn searched_enough(
        &self,
        key: (i32, i32),
        ring: i32,
        edges: (f64, f64, f64, f64),
        found: &Found,
    ) -> bool {
        let reach = self.reach(ring, edges);
        self.rings_cover(key, ring) || (reach > 0.0 && reach * reach >= found.limit)
    }

    /// Whether rings 0..=`ring` around cell `(kx, ky)` cover the box of occupied cells.
    #[inline(always)]
    fn rings_cover(&self, (kx, ky): (i32, i32), ring: i32) -> bool {
        kx - ring <= self.lo.0
            && kx + ring >= self.hi.0
            && ky - ring <= self.lo.1
            && ky + ring >= self.hi.1
    }

    /// How far at least every point outside rings 0..=`ring` lies from q (at `edges` from its
    /// cell's sides) \[m\]: `ring` cells beyond the nearest side, less 1e-9 m for the rounding
    /// of the cell keys.
    #[inline(always)]
    fn reach(&self, ring: i32, (fx, fy, gx, gy): (f64, f64, f64, f64)) -> f64 {
        // Plain comparisons: the offsets are finite, so `f64::min`'s NaN handling is not
        // needed.
        let min = |a: f64, b: f64| if a < b { a } else { b };
        min(min(fx, gx), min(fy, gy)) + ring as f64 * self.cell - 1e-9
    }

    /// The answer once the search is done.
    #[inline(always)]
    fn hit(&self, found: &Found) -> Option<Hit> {
        (found.best != END).then(|| {
            let entry = &self.points[found.best as usize];
            Hit {
                item: entry.item,
                point: entry.point,
                dist2: found.limit,
            }
        })
    }

    /// Every point tried: the answer where the rings would take too long.
    fn scan_all(&self, q: &Point2<f64>, max_d2: f64) -> Option<Hit> {
        let mut best: Option<Hit> = None;
        for entry in &self.points {
            let p = entry.point;
            let (dx, dy) = (p.x - q.x, p.y - q.y);
            let dist2 = dx * dx + dy * dy;
            if dist2 <= max_d2 && best.is_none_or(|b| dist2 < b.dist2) {
                best = Some(Hit {
                    item: entry.item,
                    point: p,
                    dist2,
                });
            }
        }
        best
    }

    /// Whether cell `(x, y)` lies in the box of occupied cells.
    #[inline]
    fn holds(&self, (x, y): (i32, i32)) -> bool {
        x >= self.lo.0 && x <= self.hi.0 && y >= self.lo.1 && y <= self.hi.1
    }

    /// Visits the cells at Chebyshev distance `ring` (2 or more) from `(kx, ky)` that could
    /// hold a point below the limit, keeping the nearest. Rows and, in the end rows, columns
    /// too far from q are not stepped through.
    #[inline(never)]
    fn search_ring<const CERTIFY: bool>(
        &self,
        q: &Point2<f64>,
        (kx, ky): (i32, i32),
        ring: i32,
        (fx, fy, gx, gy): (f64, f64, f64, f64),
        found: &mut Found,
        cursor: &mut TileCursor,
    ) {
        let c = self.cell;
        // Distance along one axis from q to the cell `d` cells away (0 for its own).
        let gap = |d: i32, low: f64, high: f64| match d {
            0 => 0.0,
            d if d < 0 => low + (-d - 1) as f64 * c,
            d => high + (d - 1) as f64 * c,
        };
        for dy in -ring..=ring {
            let ey = gap(dy, fy, gy);
            let ey2 = ey * ey;
            let y = ky + dy;
            // A row outside the box of occupied cells has no points; one ruled out by its
            // distance bounds its points.
            if y < self.lo.1 || y > self.hi.1 {
                continue;
            }
            if ey2 >= found.limit {
                if CERTIFY {
                    found.second = found.second.min(ey2);
                }
                continue;
            }
            // Inner rows of a ring have only its two end cells.
            let step = if dy != -ring && dy != ring {
                2 * ring
            } else {
                1
            };
            let mut dx = -ring;
            while dx <= ring {
                let ex = gap(dx, fx, gx);
                let x = kx + dx;
                dx += step;
                if x < self.lo.0 || x > self.hi.0 {
                    continue;
                }
                let d2 = ex * ex + ey2;
                if d2 >= found.limit {
                    if CERTIFY {
                        found.second = found.second.min(d2);
                    }
                    continue;
                }
                self.walk::<CERTIFY>(self.head((x, y), cursor), q, found);
            }
        }
    }

    /// Ring 1 (the one most queries that leave their own cell end with) as a short list of
    /// its eight cells, nearest first: the two sides q is nearest to, the corner between
    /// them, then the rest. A near point found early rules out the farther cells by their
    /// edge distance alone, before their chains are walked.
    #[inline]
    fn search_ring1<const CERTIFY: bool>(
        &self,
        q: &Point2<f64>,
        (kx, ky): (i32, i32),
        (fx, fy, gx, gy): (f64, f64, f64, f64),
        found: &mut Found,
        cursor: &mut TileCursor,
    ) {
        // (cell offset, squared gap) along each axis: near side, far side, own column/row.
        let axis = |low: f64, high: f64| {
            if low <= high {
                ((-1, low * low), (1, high * high))
            } else {
                ((1, high * high), (-1, low * low))
            }
        };
        let (xn, xf) = axis(fx, gx);
        let (yn, yf) = axis(fy, gy);
        let same = (0, 0.0);
        for ((dx, ex2), (dy, ey2)) in [
            (xn, same),
            (same, yn),
            (xn, yn),
            (xf, same),
            (same, yf),
            (xf, yn),
            (xn, yf),
            (xf, yf),
        ] {
            let cell = (kx + dx, ky + dy);
            if !self.holds(cell) {
                continue;
            }
            if ex2 + ey2 >= found.limit {
                if CERTIFY {
                    found.second = found.second.min(ex2 + ey2);
                }
                continue;
            }
            self.walk::<CERTIFY>(self.head(cell, cursor), q, found);
        }
    }

    /// Tries the points of the chain from `at`, keeping the nearest below the limit.
    /// Under `CERTIFY` also the least squared distance of the others tried.
    #[inline(always)]
    fn walk<const CERTIFY: bool>(&self, mut at: u32, q: &Point2<f64>, found: &mut Found) {
        while at != END {
            let entry = &self.points[at as usize];
            let (dx, dy) = (entry.point.x - q.x, entry.point.y - q.y);
            let d2 = dx * dx + dy * dy;
            if d2 < found.limit {
                if CERTIFY && found.best != END {
                    found.second = found.second.min(found.limit);
                }
                found.best = at;
                found.limit = d2;
            } else if CERTIFY {
                found.second = found.second.min(d2);
            }
            at = entry.next;
        }
    }
}

/// A query's best so far: an index into `points` (`END` for none) and the squared distance
/// a point must be below to replace it.
struct Found {
    best: u32,
    limit: f64,
    /// Under `CERTIFY`: a lower bound on the squared distance of every point but `best`
    /// seen or ruled out so far.
    second: f64,
}

#[cfg(test)]
mod tests {
    use super::*;

    fn brute(points: &[Point2<f64>], q: &Point2<f64>, max_d2: f64) -> Option<(u32, f64)> {
        points
            .iter()
            .enumerate()
            .map(|(i, p)| (i as u32, (p - q).norm_squared()))
            .filter(|(_, d2)| *d2 <= max_d2)
            .min_by(|a, b| a.1.total_cmp(&b.1))
    }

    #[test]
    fn nearest_matches_brute_force_bounded_and_unbounded() {
        let points: Vec<Point2<f64>> = (0..500)
            .map(|i| {
                let a = i as f64 * 0.731;
                Point2::new(3.0 * a.cos() + 0.01 * i as f64, 2.0 * (1.3 * a).sin() - 1.0)
            })
            .collect();
        let mut grid = PointGrid::default();
        for (i, p) in points.iter().enumerate() {
            grid.insert(*p, i as u32);
        }
        for k in 0..400 {
            let t = k as f64 * 0.173;
            let q = Point2::new(8.0 * t.sin(), 5.0 * (0.7 * t).cos());
            for max_d2 in [0.01, 0.25, f64::INFINITY] {
                let got = grid.nearest_within(&q, max_d2).map(|h| (h.item, h.dist2));
                assert_eq!(
                    got,
                    brute(&points, &q, max_d2),
                    "query {q:?} within {max_d2}"
                );
            }
        }
    }

    #[test]
    fn nearest_matches_brute_force_beyond_the_dense_directory() {
        // Two clusters 5 km apart: the directory cannot span both, so it keeps the first
        // cluster's box; new tiles inside that box still go into it, the far ones only into
        // the hash.
        let mut points: Vec<Point2<f64>> = (0..60)
            .map(|i| Point2::new(0.37 * i as f64, 0.21 * i as f64))
            .collect();
        points.extend((0..60).map(|i| Point2::new(5000.0 + 0.3 * i as f64, -4000.0)));
        points.extend((0..60).map(|i| Point2::new(-0.29 * i as f64, 3.0 - 0.17 * i as f64)));
        let mut grid = PointGrid::default();
        for (i, p) in points.iter().enumerate() {
            grid.insert(*p, i as u32);
        }
        assert!(!grid.directory_all);
        for q in points.iter().step_by(7) {
            for d in [Point2::new(0.1, -0.05), Point2::new(-0.6, 0.3)] {
                let q = Point2::new(q.x + d.x, q.y + d.y);
                for max_d2 in [0.01, 0.25, f64::INFINITY] {
                    let got = grid.nearest_within(&q, max_d2).map(|h| (h.item, h.dist2));
                    assert_eq!(got, brute(&points, &q, max_d2), "query {q:?}");
                }
            }
        }
    }

    #[test]
    fn a_grid_built_at_once_answers_as_one_built_point_by_point() {
        let mut points: Vec<Point2<f64>> = (0..300)
            .map(|i| {
                let a = i as f64 * 0.021;
                Point2::new(12.0 * a.cos(), 9.0 * a.sin())
            })
            .collect();
        points.push(Point2::new(f64::NAN, 1.0));
        points.push(Point2::new(40.0, -35.0));
        let at_once = PointGrid::from_points(SCAN_CELL, &points);
        let mut one_by_one = PointGrid::new(SCAN_CELL);
        for (i, p) in points.iter().enumerate() {
            one_by_one.insert(*p, i as u32);
        }
        for k in 0..300 {
            let t = k as f64 * 0.173;
            let q = Point2::new(14.0 * t.sin(), 11.0 * (0.7 * t).cos());
            for max_d2 in [0.01, 0.25, f64::INFINITY] {
                assert_eq!(
                    at_once.nearest_within(&q, max_d2),
                    one_by_one.nearest_within(&q, max_d2)
                );
            }
        }
    }

    proptest::proptest! {
        /// A query anywhere within a certified query's margin has, by brute force, the
        /// nearest point (or none) the certified query found, at the distance `again` gives.
        #[test]
        fn a_certified_nearest_stays_the_nearest_within_its_margin(
            raw in proptest::collection::vec((-3.0f64..3.0, -3.0f64..3.0), 1..120),
            queries in proptest::collection::vec(
                (-4.0f64..4.0, -4.0f64..4.0, 0.0f64..1.0, 0.0f64..std::f64::consts::TAU),
                1..30,
            ),
            cell in proptest::sample::select(vec![0.125, 0.25, 0.5]),
            max_d2 in proptest::sample::select(vec![0.01, 0.25, 0.33, f64::INFINITY]),
            dense in proptest::bool::ANY,
        ) {
            // Dense clusters too (a wall's voxels), where the margins are small.
            let points: Vec<Point2<f64>> = raw
                .iter()
                .map(|&(x, y)| if dense { Point2::new(x * 0.1, y * 0.1) } else { Point2::new(x, y) })
                .collect();
            let grid = PointGrid::from_points(cell, &points);
            for &(x, y, u, a) in &queries {
                let q = if dense { Point2::new(x * 0.1, y * 0.1) } else { Point2::new(x, y) };
                let (hit, margin) = grid.nearest_certified(&q, max_d2);
                proptest::prop_assert_eq!(hit, grid.nearest_within(&q, max_d2));
                proptest::prop_assert!(margin >= 0.0);
                let moved = Point2::new(q.x + u * margin * a.cos(), q.y + u * margin * a.sin());
                if (moved - q).norm_squared() >= margin * margin {
                    continue;
                }
                let want = brute(&points, &moved, max_d2);
                let got = hit.and_then(|h| PointGrid::again(&moved, max_d2, h.item, h.point));
                proptest::prop_assert_eq!(got.map(|h| (h.item, h.dist2)), want);
                proptest::prop_assert_eq!(got, grid.nearest_within(&moved, max_d2));
            }
        }
    }

    #[test]
    fn floor_i64_equals_floor() {
        let mut v = -3.0f64;
        while v <= 3.0 {
            for x in [v, v + 1e-12, v - 1e-12, v * 1e9, v * 1e17] {
                assert_eq!(floor_i64(x), x.floor() as i64, "{x}");
            }
            v += 0.125;
        }
        for x in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY, 1e300, -1e300] {
            assert_eq!(floor_i64(x), x.floor() as i64);
        }
    }

    #[test]
    fn floor_i32_equals_saturated_floor() {
        let edge = 2_147_483_647.0f64;
        let mut v = -3.0f64;
        while v <= 3.0 {
            for x in [v, v + 1e-12, v - 1e-12, v * 1e5, v * 7e8, v * 1e17] {
                assert_eq!(floor_i32(x), x.floor() as i32, "{x}");
            }
            v += 0.125;
        }
        for x in [
            f64::NAN,
            f64::INFINITY,
            f64::NEG_INFINITY,
            edge,
            edge - 0.5,
            -edge,
            -edge - 0.5,
            -edge - 1.0,
            -edge + 0.5,
            1e300,
            -1e300,
        ] {
            assert_eq!(floor_i32(x), x.floor() as i32, "{x}");
        }
    }

    #[test]
    fn just_above_is_the_next_float() {
        assert_eq!(just_above(1.0), 1.0 + f64::EPSILON);
        assert_eq!(just_above(-1.0), -1.0 + f64::EPSILON / 2.0);
        assert_eq!(just_above(0.0), f64::from_bits(1));
        assert_eq!(just_above(-0.0), f64::from_bits(1));
        assert_eq!(just_above(f64::NEG_INFINITY), f64::MIN);
        assert_eq!(just_above(f64::MAX), f64::INFINITY);
        assert_eq!(just_above(f64::INFINITY), f64::INFINITY);
        assert!(just_above(f64::NAN).is_nan());
    }

    #[test]
    fn empty_grid_finds_nothing() {
        let grid = PointGrid::default();
        assert!(
            grid.nearest_within(&Point2::origin(), f64::INFINITY)
                .is_none()
        );
    }
}
