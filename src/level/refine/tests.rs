use super::*;
use crate::level::grid::GridPoint;

/// A level robot's grid of three rows with the given noise-free points per row.
fn grid_of(rows: [Vec<Vector3<f64>>; 3]) -> PoseGrid {
    let cols = rows.iter().map(Vec::len).max().unwrap_or(0);
    let mut points = Vec::new();
    for row in &rows {
        for c in 0..cols {
            points.push(row.get(c).map(|p| GridPoint {
                p: nalgebra::Point3::from(*p),
                dir: p.normalize(),
                range: p.norm(),
            }));
        }
    }
    PoseGrid {
        scan_index: vec![0, 1, 2],
        elevation: vec![-0.087, 0.0, 0.087],
        cols,
        points,
    }
}

/// `n` points from `a` to `b`.
fn run(a: Vector3<f64>, b: Vector3<f64>, n: usize) -> Vec<Vector3<f64>> {
    (0..n)
        .map(|k| a + (b - a) * (k as f64 / (n - 1) as f64))
        .collect()
}

/// `n` points across the robot's path, `x` ahead, from 1 m right to 1 m left, at
/// height `z`.
fn across(x: f64, z: f64, n: usize) -> Vec<Vector3<f64>> {
    run(Vector3::new(x, -1.0, z), Vector3::new(x, 1.0, z), n)
}

fn floor_evidence(grid: &PoseGrid) -> LevelEvidence {
    floor_evidence_within(grid, 0.2f64.to_radians())
}

/// [`level_lines`]' floor in the robot frame taken as level, up known within `sigma_up`.
fn floor_evidence_within(grid: &PoseGrid, sigma_up: f64) -> LevelEvidence {
    let all = vec![true; grid.points.len()];
    let none = vec![false; grid.points.len()];
    let params = LevelParams::default();
    let steps = LevelSteps {
        levelish: all.clone(),
        floor: all.clone(),
        ceiling: all.clone(),
        floor_line: all.clone(),
    };
    let f = Frame {
        grid,
        params: &params,
        steps: &steps,
        lv: leveled(grid, &Rotation3::identity()),
        level_from_robot: Rotation3::identity(),
        up: Vector3::z(),
        s: 0.01,
        sigma: 0.01,
        k: params.refine_k,
        sigma_up,
    };
    level_lines(&f, SurfaceKind::Floor, |i| all[i] && !none[i])
}

/// Two scans' floor lines stand only when their points fit one plane. From a loose start
/// (up known within `MAX_SIGMA_UP`) a wall's foot 10 cm up at another bearing passes for
/// floor by its height, but is skew to the floor line ahead (traced on a zigzag wall,
/// where such a pair leveled a pose 8 degrees off with a sigma of 0.4); one floor's two
/// lines make a plane.
#[test]
fn two_floor_lines_must_fit_one_plane() {
    let evidence = |side_z: f64| {
        let side = run(
            Vector3::new(0.5, -2.5, side_z),
            Vector3::new(2.5, -1.5, side_z),
            20,
        );
        let grid = grid_of([Vec::new(), across(2.0, -0.45, 20), side]);
        floor_evidence_within(&grid, MAX_SIGMA_UP)
    };
    assert!(matches!(evidence(-0.35), LevelEvidence::None));
    assert!(matches!(evidence(-0.45), LevelEvidence::Plane(..)));
}

/// A level plane's lean from up counts against the plane's own noise and up's: many
/// sigmas when up is known to 0.2 degrees, about one when up is as uncertain as the lean.
#[test]
fn level_z2_weighs_a_lean_against_both_uncertainties() {
    let grid = grid_of([across(2.0, -0.45, 21), across(3.0, -0.45, 21), vec![]]);
    let members: Vec<usize> = (0..42).collect();
    let fit = grid.accumulate(&members).fit(0.0).unwrap();
    let lean = 3f64.to_radians();
    let up = Vector3::new(lean.sin(), 0.0, lean.cos());
    let level = level_z2(&fit, &Vector3::z(), 0.01, 0.2f64.to_radians());
    assert!(level < 1e-12, "{level}");
    let tight = level_z2(&fit, &up, 0.01, 0.2f64.to_radians());
    let loose = level_z2(&fit, &up, 0.01, lean);
    assert!(tight > 200.0, "{tight}");
    assert!((0.9..1.0).contains(&loose), "{loose}");
}

/// A level start from floor points in two scans only is loose (any two scan lines that
/// meet are coplanar); from three it is as tight as its fit.
#[test]
fn a_level_start_over_two_scans_is_loose() {
    let params = LevelParams::default();
    let floor = |x: f64| across(x, -0.45, 41);
    let two = grid_of([floor(2.0), floor(3.0), vec![]]);
    let three = grid_of([floor(2.0), floor(3.0), floor(4.5)]);
    let sigma_of = |grid: &PoseGrid| {
        let steps = level_steps(grid, &params, 0.01);
        level_start(grid, &steps, &params, 0.01)
            .expect("a level start")
            .max_attitude_sigma()
    };
    let (two, three) = (sigma_of(&two), sigma_of(&three));
    assert!(two >= MAX_SIGMA_UP, "{two}");
    assert!(three < 0.1f64.to_radians(), "{three}");
}

/// The floor just in front of a wall's foot steps less than `r de` to the wall above it:
/// no `floor` point, but a `floor_line` candidate by its step's sign; the wall is neither.
#[test]
fn the_floor_in_front_of_a_wall_foot_is_a_floor_line_candidate() {
    let wall = across(3.0, 0.0, 21);
    let grid = grid_of([wall.clone(), wall, across(2.8, -0.45, 21)]);
    let steps = level_steps(&grid, &LevelParams::default(), 0.01);
    let row = |mask: &[bool], r: usize| mask[r * 21..(r + 1) * 21].to_vec();
    let (all, none) = (vec![true; 21], vec![false; 21]);
    assert_eq!(row(&steps.floor, 2), none);
    assert_eq!(row(&steps.floor_line, 2), all);
    assert_eq!(row(&steps.ceiling, 2), none);
    assert_eq!(row(&steps.floor_line, 0), none);
    assert_eq!(row(&steps.floor_line, 1), none);
    // Within the noise of two ranges the sign says nothing.
    let grid = grid_of([
        across(3.0, 0.0, 21),
        across(3.0, 0.0, 21),
        across(2.99, -0.2, 21),
    ]);
    let steps = level_steps(&grid, &LevelParams::default(), 0.01);
    assert_eq!(row(&steps.floor_line, 2), none);
}

/// A scan's few floor points join the plane through another scan's floor line (their lever
/// arm pins its tilt); alone, so few points are no line.
#[test]
fn a_short_floor_line_joins_a_full_one_in_a_plane() {
    let short = || {
        run(
            Vector3::new(3.5, -0.2, -0.45),
            Vector3::new(3.5, 0.2, -0.45),
            5,
        )
    };
    let grid = grid_of([Vec::new(), across(2.0, -0.45, 20), short()]);
    let LevelEvidence::Plane(fit, members) = floor_evidence(&grid) else {
        panic!("expected a floor plane");
    };
    assert_eq!(members.len(), 25);
    // Within a hundredth of a degree of level (the fit takes the noise's bias out of
    // noise-free points).
    assert!(
        fit.normal.z.abs() > 0.01f64.to_radians().cos(),
        "{:?}",
        fit.normal
    );
    let grid = grid_of([Vec::new(), Vec::new(), short()]);
    assert!(matches!(floor_evidence(&grid), LevelEvidence::None));
}

#[test]
fn level_lines_take_the_floor_not_a_raised_box_top() {
    // A box top 25 cm above the floor holds twice the floor's points; the floor is the
    // lowest level surface.
    let box_top = run(
        Vector3::new(1.5, -0.4, -0.2),
        Vector3::new(1.5, 0.4, -0.2),
        40,
    );
    let floor = across(1.2, -0.45, 20);
    let grid = grid_of([Vec::new(), box_top, floor]);
    let LevelEvidence::Lines(lines) = floor_evidence(&grid) else {
        panic!("expected one floor line");
    };
    assert_eq!(lines.len(), 1);
    assert_eq!(lines[0].n, 20);
    assert!((lines[0].centroid.z + 0.45).abs() < 1e-9);
    assert!(lines[0].dir.z.abs() < 1e-9);
}

/// Two floor lines at different azimuths lie in one plane; a far wall's line at the
/// scanner's height with a floor line does not (the pose that set a start 8 degrees off:
/// 14 cm out of one plane over 4 m).
#[test]
fn floor_lines_are_coplanar_and_a_far_wall_line_is_not() {
    let line = |a: Vector3<f64>, b: Vector3<f64>| {
        let pts: Vec<_> = run(a, b, 30)
            .into_iter()
            .map(|p| (nalgebra::Point3::from(p), p.normalize()))
            .collect();
        LevelLine::fit(&pts, 0.05, 0.001).unwrap()
    };
    let floor_ahead = line(
        Vector3::new(2.0, -1.0, -0.45),
        Vector3::new(2.0, 1.0, -0.45),
    );
    let floor_side = line(
        Vector3::new(0.5, -2.5, -0.45),
        Vector3::new(2.5, -1.5, -0.45),
    );
    let far_wall = line(Vector3::new(2.0, 5.0, 0.0), Vector3::new(4.0, 6.0, 0.0));
    let params = LevelParams::default();
    assert!(coplanar(&floor_ahead, &floor_side, 0.05, &params));
    assert!(!coplanar(&floor_ahead, &far_wall, 0.05, &params));
    // Parallel lines always lie in one plane.
    let floor_far = line(
        Vector3::new(3.0, -1.0, -0.45),
        Vector3::new(3.0, 1.0, -0.45),
    );
    assert!(coplanar(&floor_ahead, &floor_far, 0.05, &params));
}

/// A line on its own that slopes in the provisional frame beyond that frame's uncertainty
/// is no floor line, whatever its height: a far wall met near its foot by the level scan
/// (a 4.6 degree slope against a frame good to 0.86 degrees) once set a pose 6 degrees off.
#[test]
fn a_sloping_line_is_no_floor_line() {
    let line = |slope_deg: f64| {
        let rise = 2.0 * slope_deg.to_radians().tan();
        grid_of([
            Vec::new(),
            Vec::new(),
            run(
                Vector3::new(2.0, -1.0, -0.45 - rise / 2.0),
                Vector3::new(2.0, 1.0, -0.45 + rise / 2.0),
                30,
            ),
        ])
    };
    let frame = 0.86f64.to_radians();
    let fitted = |grid: &PoseGrid| {
        let idx: Vec<usize> = (0..grid.points.len())
            .filter(|&i| grid.points[i].is_some())
            .collect();
        fit_line(
            grid,
            idx,
            &Vector3::z(),
            Some(frame),
            0.01,
            &LevelParams::default(),
            10,
        )
    };
    assert!(fitted(&line(0.0)).is_some());
    assert!(fitted(&line(1.0)).is_some());
    assert!(fitted(&line(4.6)).is_none());
}

/// Floor lines 2 and 3 m ahead, 0.45 m down, 30 points each, over `third` as the last row.
fn two_floor_rows_and(third: Vec<Vector3<f64>>) -> PoseGrid {
    grid_of([across(2.0, -0.45, 30), across(3.0, -0.45, 30), third])
}

/// Two lines of points in one level plane, `x` and `x + 1.5` m ahead at height `z`, as one
/// row of a grid (a band of wall points at one height looks like this).
fn band(x: f64, z: f64) -> Vec<Vector3<f64>> {
    let mut pts = across(x, z, 30);
    pts.extend(across(x + 1.5, z, 30));
    pts
}

/// A plane through the scanner is a scan's own plane, no floor, however level; one at the
/// scanner's height below it is.
#[test]
fn a_level_plane_must_pass_clear_of_the_scanner() {
    let fit_of = |grid: &PoseGrid| {
        let all: Vec<usize> = (0..grid.points.len()).collect();
        grid.accumulate(&all).fit(0.0).unwrap()
    };
    let floor = grid_of([across(2.0, -0.45, 21), across(3.0, -0.45, 21), vec![]]);
    let through = grid_of([band(2.0, 0.0), vec![], vec![]]);
    let clear = |f: PlaneFit| clear_of_scanner(&f.normal, &f.centroid);
    assert!(clear(fit_of(&floor)));
    assert!(!clear(fit_of(&through)));
}

proptest::proptest! {
    /// The early exit changes nothing: a count beats `best` exactly when the full count
    /// does, and is then the full count.
    #[test]
    fn counting_with_an_early_exit_agrees_with_a_full_count(
        on in proptest::collection::vec(proptest::bool::ANY, 0..80),
        best in proptest::option::of(0usize..90),
    ) {
        let idx: Vec<usize> = (0..on.len()).collect();
        let full = on.iter().filter(|&&b| b).count();
        let expected = best.is_none_or(|b| full > b).then_some(full);
        proptest::prop_assert_eq!(count_beating(&idx, |i| on[i], best), expected);
    }
}

/// The sample finds the plane of most points among those it samples from, passing clear
/// of the scanner: a band of 60 wall points 15 cm below the scanner beats 40 floor points
/// when sampled, not when only the floor's points (those stepping like a floor) are; a
/// band through the scanner never wins.
#[test]
fn sampled_planes_come_from_the_sample_and_pass_clear_of_the_scanner() {
    let params = LevelParams::default();
    let level = |n: &Vector3<f64>| n.z.abs() > 5f64.to_radians().cos();
    let floor_rows = || [across(2.0, -0.45, 20), across(3.0, -0.45, 20)];
    let [f1, f2] = floor_rows();
    let grid = grid_of([band(3.0, -0.15), f1, f2]);
    let all: Vec<usize> = (0..grid.points.len())
        .filter(|&i| grid.points[i].is_some())
        .collect();
    let floor: Vec<usize> = all.iter().copied().filter(|&i| i >= grid.cols).collect();
    let from_all = sampled_plane(&grid, &all, &all, level, 0.01, &params).unwrap();
    assert_eq!(from_all.len(), 60);
    let from_floor = sampled_plane(&grid, &all, &floor, level, 0.01, &params).unwrap();
    assert_eq!(from_floor, floor);
    let [f1, f2] = floor_rows();
    let grid = grid_of([band(3.0, 0.0), f1, f2]);
    let got = sampled_plane(&grid, &all, &all, level, 0.01, &params).unwrap();
    assert_eq!(got, floor);
}

/// Three floor lines in one plane are one floor; a wall's line 14 cm above its foot with
/// two floor lines is not, though it is parallel to (so coplanar with) each of them.
#[test]
fn three_lines_must_share_one_plane() {
    let params = LevelParams::default();
    let lines_of = |third: f64| {
        let grid = two_floor_rows_and(across(4.5, third, 30));
        let lines: Vec<(LevelLine, Vec<usize>)> = (0..3)
            .map(|r| {
                let idx: Vec<usize> = (r * grid.cols..(r + 1) * grid.cols).collect();
                fit_line(&grid, idx, &Vector3::z(), None, 0.01, &params, 10).unwrap()
            })
            .collect();
        (grid, lines)
    };
    let (grid, lines) = lines_of(-0.45);
    assert!(one_plane(&grid, &lines, 0.01, &params));
    let (grid, lines) = lines_of(-0.31);
    assert!(coplanar(&lines[0].0, &lines[2].0, 0.01, &params));
    assert!(!one_plane(&grid, &lines, 0.01, &params));
    assert!(one_plane(&grid, &lines[..2], 0.01, &params));
}

/// A floor's edge row 6 cm above the plane of its other rows (the walls' feet seen by the
/// scan above the floor) is trimmed; a floor's own rows, or two rows alone, are kept.
#[test]
fn an_edge_row_above_the_floor_is_trimmed() {
    let params = LevelParams::default();
    let trimmed = |rows: [Vec<Vector3<f64>>; 3]| {
        let grid = grid_of(rows);
        let all: Vec<usize> = (0..grid.points.len())
            .filter(|&i| grid.points[i].is_some())
            .collect();
        let kept = without_standing_rows(&grid, all.clone(), 0.01, &params);
        (all.len(), kept.len())
    };
    let floor = |x: f64| across(x, -0.45, 30);
    assert_eq!(trimmed([floor(2.0), floor(3.0), floor(4.5)]), (90, 90));
    assert_eq!(
        trimmed([across(4.5, -0.39, 30), floor(3.0), floor(2.0)]),
        (90, 60)
    );
    assert_eq!(
        trimmed([floor(2.0), floor(3.0), across(4.5, -0.39, 30)]),
        (90, 60)
    );
    assert_eq!(
        trimmed([floor(2.0), across(4.5, -0.39, 30), vec![]]),
        (60, 60)
    );
}

/// Five rows of one floor, a fifth each give or take, all count; so do three rows of
/// seven; a line of a tenth of the points beside another line does not.
#[test]
fn rows_with_a_fair_share_support_a_plane() {
    assert_eq!(supported_rows(&[72, 72, 73, 88, 69], 0.2), 5);
    assert_eq!(supported_rows(&[10, 10, 10, 10, 10, 10, 10], 0.15), 7);
    assert_eq!(supported_rows(&[0, 90, 10], 0.2), 1);
    assert_eq!(supported_rows(&[0, 0, 0], 0.2), 0);
}

/// Nothing is seen through a floor: a plane with ten points 20 cm beneath it is no floor;
/// the same plane with the points above it (a box on the floor) is.
#[test]
fn a_floor_with_points_beneath_it_is_no_floor() {
    let params = LevelParams::default();
    let fit_and_grid = |third: f64| {
        let grid = two_floor_rows_and(across(2.5, third, 10));
        let floor: Vec<usize> = (0..2 * grid.cols).collect();
        let fit = grid.accumulate(&floor).fit(0.01).unwrap();
        (grid, fit)
    };
    let (grid, fit) = fit_and_grid(-0.65);
    assert!(!opaque(&grid, &fit, 0.01, &params));
    let (grid, fit) = fit_and_grid(-0.25);
    assert!(opaque(&grid, &fit, 0.01, &params));
}

#[test]
fn level_lines_refuse_a_wall_line_near_its_foot() {
    // Two floor lines 0.8 m apart, and a wall's line 3 m ahead, 3 cm above the floor: at
    // the floor's height within the tolerance and level, but not in the plane of the other
    // two. Which line is wrong is not known, so none is used.
    let wall = across(3.0, -0.42, 30);
    let near = across(1.2, -0.45, 30);
    let far = across(2.0, -0.45, 30);
    let grid = grid_of([wall, far.clone(), near.clone()]);
    assert!(matches!(floor_evidence(&grid), LevelEvidence::None));
    // A wall's line that rises along the wall (from 1.5 to 4.5 cm above the floor) is no
    // level line at all: the floor lines alone are the floor.
    let rising = run(
        Vector3::new(3.0, -1.0, -0.435),
        Vector3::new(3.0, 1.0, -0.405),
        30,
    );
    let floor_plane = |grid: &PoseGrid| {
        let LevelEvidence::Plane(fit, members) = floor_evidence(grid) else {
            panic!("expected the floor plane");
        };
        assert_eq!(members.len(), 60);
        // (The fit removes range noise that these exact points do not have.)
        assert!(fit.normal.z.abs() > 1.0 - 1e-6);
        assert!((fit.centroid.z + 0.45).abs() < 1e-9);
    };
    floor_plane(&grid_of([rising, far.clone(), near.clone()]));
    // Without the wall's line, the two floor lines are one level plane.
    floor_plane(&grid_of([Vec::new(), far, near]));
}

#[test]
fn line2_fits_points_on_a_line_exactly() {
    // The line x cos(a) + y sin(a) = 2.
    let a: f64 = 0.7;
    let n = Vector2::new(a.cos(), a.sin());
    let t = Vector2::new(-a.sin(), a.cos());
    let mut acc = Line2::default();
    for k in 0..10 {
        let p = n * 2.0 + t * (k as f64 * 0.3 - 1.0);
        acc.add(&p, &p.normalize(), 0.1 * k as f64);
    }
    let l = acc.line().unwrap();
    let sign = l.normal.dot(&n).signum();
    assert!((l.normal * sign - n).norm() < 1e-12);
    assert!((l.offset * sign - 2.0).abs() < 1e-12);
    assert!((l.z - 0.45).abs() < 1e-12);
    assert!(acc.misfit(&l, 0.01, 0.001) < 1e-12);
}

#[test]
fn merge_lines_joins_pieces_of_one_wall_but_not_a_corner() {
    let line = |deg: f64, offset: f64, weight: f64| {
        let a = deg.to_radians();
        Line {
            normal: Vector2::new(a.cos(), a.sin()),
            offset,
            z: 0.0,
            weight,
        }
    };
    let params = LevelParams::default();
    // Two pieces of the wall x = 3 (one with the opposite normal), and the wall y = 3.
    let mut lines = vec![
        line(0.0, 3.0, 100.0),
        line(182.0, -3.02, 50.0),
        line(90.0, 3.0, 80.0),
    ];
    merge_lines(&mut lines, &params, 0.01);
    assert_eq!(lines.len(), 2);
    let x_wall = lines.iter().find(|l| l.normal.x.abs() > 0.9).unwrap();
    assert_eq!(x_wall.weight, 150.0);
    assert!((x_wall.offset.abs() - 3.0).abs() < 0.02);
}

/// A level robot's floor line across its path `x` ahead at height `z`, of 30 points.
fn flat_line(x: f64, z: f64, kind: SurfaceKind) -> FlatLine {
    let pts: Vec<_> = across(x, z, 30)
        .into_iter()
        .map(|p| (nalgebra::Point3::from(p), p.normalize()))
        .collect();
    FlatLine {
        line: LevelLine::fit(&pts, 0.01, 0.001).unwrap(),
        kind,
    }
}

/// Floor lines of two scans at one height are one floor; a line 0.4 m higher is not, nor
/// is a "floor" above the scanner or a "ceiling" below it (the traced pose: a wall's run in a
/// tilted-up scan taken as a second floor line 0.33 m above the scanner).
#[test]
fn floor_and_ceiling_lines_lie_at_one_height_on_their_side() {
    let params = LevelParams::default();
    let level = crate::level::failure::tests::solution(0.0, 0.2f64.to_radians(), (1.0, 1.0));
    let floor = |x, z| flat_line(x, z, SurfaceKind::Floor);
    let agree = |lines: &[FlatLine]| lines_at_one_height(lines, &level, 0.01, &params);
    assert!(agree(&[floor(1.5, -0.4), floor(2.5, -0.4)]));
    // Within the noise and the solution's tilt over the 1 m between them: 3 mm.
    assert!(agree(&[floor(1.5, -0.4), floor(2.5, -0.397)]));
    assert!(!agree(&[floor(1.5, -0.4), floor(2.5, 0.0)]));
    assert!(!agree(&[floor(2.2, -0.19), floor(3.8, 0.33)]));
    assert!(!agree(&[floor(3.8, 0.33)]));
    assert!(!agree(&[flat_line(2.0, -0.4, SurfaceKind::Ceiling)]));
    // A floor and a ceiling are two surfaces: each at its own height.
    assert!(agree(&[
        floor(1.5, -0.4),
        flat_line(2.0, 2.1, SurfaceKind::Ceiling)
    ]));
    // A wider solution takes in more: 1.5 degrees over the 1.6 m between the traced pair's
    // ends is 4 cm, not 0.4 m.
    let loose = crate::level::failure::tests::solution(0.0, 1.5f64.to_radians(), (1.0, 1.0));
    let pair = [floor(2.2, -0.19), floor(3.8, 0.33)];
    assert!(!lines_at_one_height(&pair, &loose, 0.01, &params));
}
