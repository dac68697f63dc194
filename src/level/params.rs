//! Every tuning knob of level estimation in one place, per stage: [`LevelParams`] (what a
//! caller may set, each with its unit, default and why) and, in one module per stage below, the
//! fixed constants that are no parameters (each with its unit and the measurement that chose
//! it). The accept/reject rules they feed are listed in [`checks`](super::checks).

use super::Estimator;

/// Declares [`LevelParams`] and its [`Default`] from one list, so that each parameter's
/// default stands beside its unit and why.
macro_rules! level_params {
    ($($(#[$doc:meta])* $name:ident: $ty:ty = $default:expr,)*) => {
        /// Parameters of level estimation, grouped by the stage that reads them.
        #[derive(Clone, Debug, PartialEq)]
        pub struct LevelParams {
            $($(#[$doc])* pub $name: $ty,)*
        }

        impl Default for LevelParams {
            fn default() -> Self {
                Self {
                    $($name: $default,)*
                }
            }
        }
    };
}

level_params! {
    // ---- The pose as a whole: noise and estimator (sect. 5.1) ----
    /// Range noise sigma \[m\]. `None` (default): the scans' `readings_sigma`, else estimated
    /// from the data.
    sigma: Option<f64> = None,
    /// Up-vector estimator. Default: robust.
    estimator: Estimator = Estimator::Robust,
    /// Floor on the noise sigma used for tolerances \[m\], so noise-free data still has one.
    /// Default 0.001.
    min_sigma: f64 = 0.001,
    // ---- Quads (sect. 5.2, `polygons`) ----
    /// Quad height in scans (rows). Default 3 (the paper's).
    quad_rows: usize = 3,
    /// Quad width in rays (columns). Default 5 (the paper's).
    quad_cols: usize = 5,
    /// Coplanarity tolerance of a quad, in range-noise sigmas. Default 3.5.
    coplanar_k: f64 = 3.5,
    /// A plane is a wall when its normal is more than this from the robot's up \[deg\].
    /// Default 45 (the paper's bound on floor slopes).
    wall_min_angle_deg: f64 = 45.0,
    /// A quad whose opposite sides differ by more than this ratio is near a triangle and
    /// dropped \[1\]. Default 0.3.
    min_edge_ratio: f64 = 0.3,
    // ---- Patches: growing, robust fits, splits and trims (after sect. 9, `patches`) ----
    /// Region growing admits points within this many sigmas of a patch's plane, each point's
    /// own range noise along the plane's normal, `sigma |d . n|`, rather than `sigma`: a floor
    /// seen at a grazing angle lies within centimetres of its plane even at 10 cm noise, and an
    /// isotropic tolerance lets floor patches run up the walls' feet. Walls grown this tightly
    /// keep the floor line at their foot only as a bend across rows, which
    /// `max_row_bend_sigmas` rejects; neither helps without the other. Default 3.
    grow_k: f64 = 3.0,
    /// Smallest share of sigma used for that tolerance, `|d . n|` floor \[1\]. Default 0.1.
    min_ray_share: f64 = 0.1,
    /// Floor on `|d . n|` in the ray weights of each patch's plane, `1 / (d . n)^2` \[1\].
    /// Default 0.2.
    ray_weight_floor: f64 = 0.2,
    /// Region-growing seeds span about this many range-noise sigmas sideways \[1\]. Default 6.
    seed_span_sigmas: f64 = 6.0,
    /// Widest seed \[columns\]. Default 25. (Floors and ceilings also seed from the paper's
    /// narrow quads when the seeds are wider: along a level surface's normal the grazing rays
    /// carry little noise.)
    max_seed_cols: usize = 25,
    /// Patches whose residuals exceed this multiple of what the noise explains are tested for
    /// being two planes \[1\]. Default 1.1.
    split_misfit: f64 = 1.1,
    /// F statistic above which two planes replace one \[1\]. Default 20.
    split_f: f64 = 20.0,
    /// Nested splits allowed per patch. Default 3.
    split_depth: usize = 3,
    /// Cauchy scale of the robust refit of each patch's plane, in sigmas of each point's noise along the normal \[1\].
    /// Default 2.5.
    plane_cauchy: f64 = 2.5,
    /// Height band around the floor and ceiling left out of walls in that pass, on top of
    /// three sigmas of the range noise along the vertical \[m\]. Default 0.02.
    flat_margin: f64 = 0.02,
    /// Smallest patch kept \[points\]. Default 20.
    min_patch_points: usize = 20,
    /// A patch too small to split is dropped when its residual variance exceeds the noise's by
    /// more than this many standard deviations of a true plane's ratio \[1\]. Default 4; 0 keeps
    /// every patch.
    max_misfit_sigmas: f64 = 4.0,
    /// A patch needs at least this share of its points in columns where it holds two rows or
    /// more \[1\]. Default 0.75; 0 accepts any patch over two rows.
    min_stacked_share: f64 = 0.75,
    /// A patch over three or more rows is dropped when its rows' mean residuals bend away from
    /// its plane by more than this many standard deviations of a true plane's chi-square per
    /// degree of freedom \[1\] (a wall line and a floor line at its foot). Default 4; 0 keeps
    /// every patch.
    max_row_bend_sigmas: f64 = 4.0,
    /// An edge row of a patch over four rows or more goes when its mean residual from the
    /// plane of the patch's other rows exceeds this many sigmas (its points' noise and that
    /// plane's uncertainty), as the floor line at a wall's foot does; 0 keeps every row.
    /// Default 5 (on three-row patches, which it would cut to two, it left wrong planes to
    /// decide a few poses at 10 cm noise).
    trim_sigmas: f64 = 5.0,
    /// A run of points at either end of a patch's row goes when it stands in front of the
    /// patch's plane (towards the scanner): the sum of its residuals beyond this many standard
    /// deviations of that sum, as the floor just in front of a wall's foot does; 0 keeps them.
    /// Default 3.
    front_end_sigmas: f64 = 3.0,
    // ---- Up, attitude and the first pass's level surfaces (sect. 5.3-5.4) ----
    /// Reweighting iterations of the robust estimator. Default 10.
    iterations: usize = 10,
    /// Factor on the propagated attitude sigmas \[1\]: the noise model does not see
    /// segmentation errors (a few floor points in a wall, a corner split a little off), which
    /// simulations show add about a fifth. Default 1.2.
    sigma_inflation: f64 = 1.2,
    /// Take the floor and ceiling planes seen as level, as extra evidence of up beside the
    /// walls (robust estimator). Default true: the contract's world has a level floor (z = 0)
    /// and ceiling, and the robot is tilted by what it stands on, not by the floor it sees
    /// metres away. The floor's grazing rays put their range noise almost along it, so it
    /// pins up down well even at 10 cm noise, and it still levels a robot that faces the floor
    /// or sees only parallel walls. Walls outvote a floor that disagrees (robust weights).
    /// Turn off where the visible floor itself slopes (long ramps, rubble).
    level_surfaces: bool = true,
    /// A floor or ceiling patch is used as level only with at least this many points.
    /// Default 30.
    min_level_points: usize = 30,
    /// ... and only when its points fit one plane within this multiple of the residual the
    /// noise explains \[1\]. Default 3. A patch that is no plane (a wall's strip seen through
    /// heavy noise, a wall foot) can fit a normal near the robot's own z axis; along that
    /// normal the grazing rays carry little noise, so its variance would claim a confidence
    /// it has not earned.
    max_level_misfit: f64 = 3.0,
    /// Factor on a level plane's normal variance \[1\]. The noise model does not see what
    /// cleaning leaves of a wall's foot in a floor patch; simulations at 1-10 cm noise show its
    /// sigmas about this much too small. Default 2 (measured with the per-ray growing tolerance
    /// of `grow_k`, which keeps the wall's foot out of floor patches; 4 without it).
    level_inflation: f64 = 2.0,
    /// A floor or ceiling patch is not used as level when it only spans two scans thanks to
    /// points whose range hardly changes to a neighbouring scan's point (member of the patch
    /// or not), i.e. points on a wall, and those are more than a fifth of it: a floor line and
    /// a wall's line at its foot, coplanar within high noise, gave planes 10 degrees off with
    /// sigmas under 1 degree (a box room and an angled room at 10 cm). That veto applies to
    /// every patch from range noise of this sigma \[m\], and below it for a patch on
    /// fewer than `LEVEL_MIN_ROWS_NOISY` scan lines. Default 0.03: at 1 cm noise the misfit
    /// test refuses most such planes, and the veto on every patch cost a thousandth of a
    /// degree in the 1 cm means (floor points just in front of a wall's foot). On two scan
    /// lines it does not: a wall's line parallel to the floor line below it always fits a
    /// plane, and one such "floor", 15 degrees off with a misfit of 0.9, leveled a 1 cm pose
    /// (an L-shaped room, facing a corner) 13 degrees off with a sigma of 0.5.
    level_steep_min_sigma: f64 = 0.03,
    // ---- Failure detection, the gate (sect. 5.5, `failure`) ----
    /// Fewer wall quads than this fails the pose (too_few_polygons / facing_floor /
    /// facing_ceiling). Default 3.
    min_polygons: usize = 3,
    /// The pose fails as parallel_walls when the smaller eigenvalue of up's information
    /// matrix is below this fraction of the larger \[1\]. Default 0.01.
    parallel_ratio: f64 = 0.01,
    /// The pose fails as parallel_walls when either attitude sigma exceeds this \[deg\]: the
    /// walls seen do not pin the attitude down. Default 1.5, so that an accepted attitude is
    /// within 4.5 degrees at three sigmas (measured: no accepted pose off by more than 5).
    max_sigma_deg: f64 = 1.5,
    // ---- Re-segmentation in the level frame (after sect. 9, `resegment`, `refine`) ----
    /// Passes of re-segmentation in the provisional level frame ([`refine`], robust
    /// estimator): points re-assigned to the floor and ceiling by height and to walls as
    /// vertical planes, then up re-estimated from the refitted planes; the refined solution
    /// replaces the first when it passes the gate. 0 turns it off. Default 1 (measured on
    /// the example plans, seeds 1-3: more leveled and lower means in every cell at 1, 5 and
    /// 10 cm; a second pass changed nothing measurable).
    refine_passes: usize = 1,
    /// Re-segment only poses whose first solution failed or has an attitude sigma above this
    /// \[deg\]; 0 re-segments every pose. Default 0.6: re-segmenting a pose the first solution
    /// already pins down to a few tenths of a degree changes its error by hundredths, and
    /// skipping it makes `level` a third faster at 1 cm (example plans, seeds 1-3 and five
    /// unseen plans: the same poses leveled and none ok off by more than 5 degrees; at 1.0,
    /// one was).
    refine_above_sigma_deg: f64 = 0.6,
    /// Re-segmentation admits a point within this many sigmas of a model \[1\]. Default 3.
    refine_k: f64 = 3.0,
    /// A re-segmented wall is used only when at least this many scans hold 15% of its points
    /// each. Default 2 (the floor's points are kept out of walls, so two scan lines on a wall
    /// are a wall).
    refine_min_rows: usize = 2,
    /// Walls whose level-frame normals are within this angle \[deg\] and whose lines coincide
    /// within the tolerance are one wall. Default 10.
    refine_merge_deg: f64 = 10.0,
    /// Factor on a re-segmented floor's or ceiling's normal variance \[1\]. Default 4 (with 2,
    /// 3-sigma coverage fell to 96.8% at 3 scans and 10 cm, from 99.4%).
    refine_level_inflation: f64 = 4.0,
    /// Smallest up uncertainty assumed while assigning points \[deg\]. Default 0.2.
    refine_min_sigma_deg: f64 = 0.2,
    /// A re-segmented floor or ceiling must be within this angle of up \[deg\]. Default 10.
    refine_level_max_deg: f64 = 10.0,
    /// A point whose range steps to its neighbours in the adjacent scans like a level
    /// surface's (by more than `r de`, plus this many sigmas of the step's noise) joins no
    /// re-segmented wall \[1\]. Default 1.
    refine_step_k: f64 = 1.0,
    /// A re-segmented floor or ceiling is used only when its points fit one plane within this
    /// multiple of the residual the noise explains \[1\]. Default 1.5 (2 or 3 leveled a few more
    /// poses at 10 cm, but 3-sigma coverage fell to 92-94%: the extra floors were biased).
    refine_level_misfit: f64 = 1.5,
    // ---- Floor and ceiling lines (re-segmentation, `refine::lines`) ----
    /// Where re-segmentation finds no floor (or ceiling) plane, use each scan's floor points
    /// as a line that must be level ([`refine`], [`up::LevelLine`]): a scan's plane meets the
    /// floor in a line, and its grazing rays pin that line's slope down even at 10 cm noise.
    /// Default true: it levels poses that see the floor in one scan only (on the example
    /// plans, seeds 1-3, 1-3% more poses at 5 and 10 cm).
    level_lines: bool = true,
    /// Fewest points of a scan's floor or ceiling line. Default 10.
    level_line_min_points: usize = 10,
    /// A floor or ceiling line's points must fit it within this multiple of the residual the
    /// noise explains \[1\]. Default 1.5.
    level_line_misfit: f64 = 1.5,
    /// Factor on a floor or ceiling line's slope variance \[1\]. Default 4 (as
    /// `refine_level_inflation`).
    level_line_inflation: f64 = 4.0,
    /// A refined solution that uses floor or ceiling lines passes the gate only with both
    /// attitude sigmas below this \[deg\] (and `max_sigma_deg`). Default 1.0.
    level_line_max_sigma_deg: f64 = 1.0,
    // ---- The last stage: maximum likelihood on the chosen segmentation (`ml`) ----
    /// Up by maximum likelihood on the segmentation chosen ([`super::ml`]).
    ml: super::MlParams = super::MlParams::default(),
}

impl LevelParams {
    /// Cosine of `wall_min_angle_deg`: a plane whose normal's cosine to up is below it is a wall.
    pub fn wall_cos(&self) -> f64 {
        self.wall_min_angle_deg.to_radians().cos()
    }

    /// Cosine of `refine_level_max_deg`.
    pub fn refine_level_cos(&self) -> f64 {
        self.refine_level_max_deg.to_radians().cos()
    }
}

/// Fixed constants of range noise estimation (`noise`).
pub(crate) mod noise {
    /// The screen's ratio, below [`HETEROSCEDASTIC_RATIO`], since its split and cut differ from
    /// the halves' own: with it, `level` gave the same output as with no screen on 2700 poses
    /// under each of five noise models (constant, 1% and 2% of the range, 0.5 cm + 0.5%, given as
    /// `readings_sigma`).
    pub(crate) const SCREEN_RATIO: f64 = 1.2;

    /// How much noisier than the nearer half of the readings the farther half must be for the range
    /// noise to be taken as the farther half's
    /// ([`far_if_noisier`](crate::level::noise::far_if_noisier)).
    pub(crate) const HETEROSCEDASTIC_RATIO: f64 = 1.5;
}

/// Fixed constants of the quads (sect. 5.2, `polygons`).
pub(crate) mod quads {
    /// How far from the diagonals' plane, in coplanarity tolerances, a quad's point may lie before
    /// the quad is refused without a fit. At 1.5 rather than 3 it spares fits that the final test
    /// would refuse, 2.6% of `level`'s CPU time at 1 cm; the wall quads kept changed by 0.007% at
    /// 1 cm and 0.18% at 10 cm, and no accuracy statistic moved beyond its noise (148,500
    /// protocol poses, 1-10 cm).
    pub(crate) const DIAGONAL_PLANE_TOLERANCES: f64 = 1.5;
}

/// Fixed constants of the patches (region growing after sect. 9, `patches`).
pub(crate) mod patches {
    /// Floor on `|d . n|` in the Cauchy scale of a patch's robust refit
    /// (`patches::fit::cauchy_weight`): grazing points still get a third of sigma.
    pub(crate) const CAUCHY_RAY_SHARE: f64 = 0.3;

    /// Floor on `(d . n)^2` in the rows' noise of `bent_across_rows`, so a grazing row's
    /// variance is never zero.
    pub(crate) const ROW_BEND_DN2_FLOOR: f64 = 1e-4;

    /// Fewest points, as a share of the patch's, in each of three adjacent rows that a trimmed
    /// patch keeps.
    pub(crate) const MIN_TRIMMED_ROW_SHARE: f64 = 0.15;

    /// Shortest run at a row's end that `without_front_row_ends` tests: shorter ones are single
    /// noisy points rather than another surface.
    pub(crate) const MIN_FRONT_RUN: usize = 3;
}

/// Fixed constants of the up vector and attitude (sect. 5.3-5.4, `up`).
pub(crate) mod up {
    /// Pseudo degrees of freedom at a chi-square per degree of freedom of one, added to the
    /// weighted chi-square of [`solution_at`] before it scales the covariance. With a few planes
    /// (one to three degrees of freedom) the chi-square per degree of freedom is a noisy estimate
    /// of the variance's scale: a true model exceeds one by chance a third of the time and often
    /// by a factor of two or more, so the raw ratio inflated many good poses' sigmas at random,
    /// and the gate turned them away. The prior (the scaled inverse chi-square's, Gelman et al.
    /// 2013, *Bayesian Data Analysis*, sect. 3.2) pulls small samples towards one while a model
    /// that misfits over many planes still scales by its own ratio. Measured over 561,600
    /// protocol poses at 5-10 cm (nine plans, seeds 1-8, 11-14, 21-32 and 101-180): leveled
    /// 73.50 -> 74.16%, poses ok and more than 5 degrees off 45 -> 45; loosening the gate
    /// instead (1.4 -> 1.5 degrees) bought 1.4 points for 18 more such poses. A prior of 10
    /// levels 0.15 points more, but also a traced pose 4.3 degrees off at 3.03 of its sigmas
    /// (`tests/level_refine.rs`, ceiling seed 6). At 1 cm it is unchanged (99.0%, none beyond 3
    /// degrees).
    pub(crate) const CHI2_PRIOR_DOF: f64 = 5.0;

    /// Walls (and level lines) whose normals' cross product is shorter than this (about 10
    /// degrees apart) propose no start for up's search: nearly parallel normals fix nothing.
    pub(crate) const PARALLEL_PROPOSAL_SIN: f64 = 0.17;

    /// Cauchy scale for the robust weights, in standard deviations.
    pub(crate) const CAUCHY_C: f64 = 2.385;

    /// Largest tilt of the robot considered \[deg\], the one place of this limit: the paper assumes
    /// floors below 45 degrees. The up search and the frameless level start
    /// ([`refine::level_start`](crate::level::refine::level_start)) keep a margin beyond that; the
    /// gate refuses an up past `wall_min_angle_deg`.
    pub(crate) const MAX_TILT_DEG: f64 = 50.0;

    /// [`MAX_TILT_DEG`] in radians, as the up search has always computed it (`50 pi / 180`, which
    /// can differ from `to_radians` in the last bit).
    pub(crate) const MAX_TILT: f64 = MAX_TILT_DEG * std::f64::consts::PI / 180.0;
}

/// Fixed constants of the first pass's level surfaces (sect. 5.3, `first_pass`).
pub(crate) mod first_pass {
    /// Share of a level plane's points each of its scan lines must hold (or half of an even
    /// split, `refine::supported_rows`) to count as one of the plane's lines: a level plane from
    /// one scan line is that scan's own plane, free to turn about the line. Used by the first
    /// pass and by re-segmentation (`level_support`).
    pub(crate) const LEVEL_ROW_SHARE: f64 = 0.2;

    /// Fewest scan-to-scan range steps inside a floor or ceiling patch to tell its prevailing
    /// step direction from (`first_pass::level_stepping_members`).
    pub(crate) const MIN_LEVEL_STEPS: usize = 10;

    /// A plane that only its points on a steep surface make is no
    /// floor when those are more than one in this many of its points (a fifth).
    pub(crate) const STEEP_SHARE_INV: usize = 5;

    /// Fewest scan lines, each with a fair share of its points, that a floor or ceiling patch needs
    /// to be a level plane of the first solution from `level_steep_min_sigma` (3 cm) of noise up.
    /// Two lines always lie in one plane, and a wall's line with the next scan's floor line made a
    /// "floor" 8 degrees off, which with one wall leveled a pose 7 degrees off with a sigma of 0.4
    /// degrees. Re-segmentation still takes such floors, checked against the provisional up. Over
    /// 172,800 protocol poses (two seed sets, nine plans) poses reported ok and more than 5 degrees
    /// off fell from 16 to 13 and those beyond 3 sigmas from 78 to 64 (seeds 1-16), for 0.4 points
    /// fewer leveled at 5-10 cm; 1 cm is unchanged.
    pub(crate) const LEVEL_MIN_ROWS_NOISY: usize = 3;
}

/// Fixed constants of re-segmentation's driver: starts, choice, widening (`resegment`).
pub(crate) mod resegment {
    /// Largest attitude sigma of any start of re-segmentation \[rad\] (11.5 degrees): at 0.2 it
    /// leveled 0.3 points fewer poses at 10 cm (3 scans), at 0.1 up to 0.7 points fewer.
    pub(crate) const START_MAX_SIGMA: f64 = 0.2;

    /// How many times tighter than the first solution a re-segmented one must be to stand without
    /// widening by their disagreement. Traced, 6 of 16 protocol poses that failed while their
    /// Cramér-Rao bounds were under 0.12 degree had a first solution 2-3 of its sigmas off and a
    /// re-segmented one 5-30 times tighter and within 0.1 degree of the truth. Over 432,000
    /// protocol poses at 5-10 cm (nine plans, seeds 101-180), leveled 74.71 -> 74.80% with the same
    /// 41 poses ok and more than 5 degrees off and 744 more than 3 (at 1.5, the more cautious 2's
    /// equal: 74.84%, the same counts, 3 more poses beyond 3 sigmas; never widening: 11 more poses
    /// more than 5 degrees off);
    /// over 129,600 more (seeds 1-8, 11-14, 21-32), 74.64 -> 74.76% with 4 and 4; at 1 cm, 99.12 ->
    /// 99.17%.
    pub(crate) const TIGHTER_THAN_FIRST: f64 = 2.0;

    /// How far apart, in joint sigmas, the first and the re-segmented solutions may lie before
    /// the kept one's covariance takes in their distance. The sum of the two covariances
    /// overstates their difference's (they share most of their data), so 2.5 of it is a stricter
    /// test than it looks. Over 145,800 poses of nine plans, it cut the poses reported ok and more
    /// than 5 degrees off from 22 to 17 for 0.25 points fewer leveled at 5-10 cm (3: 20 and 0.1;
    /// 2: 13 and 0.65).
    pub(crate) const DISAGREEMENT_SIGMAS: f64 = 2.5;

    /// How far, in the first solution's own sigmas, a re-segmentation that failed the gate may lie
    /// from it before its covariance takes in their distance (`widened_unconfirmed`). Over
    /// 75,600 protocol poses at 5-10 cm (nine plans, seeds 1-8 and 11-16), poses reported ok and
    /// more than 5 degrees off fell from 17 to 9 and those beyond 3 sigmas from 96 to 79, for 0.76
    /// points fewer leveled; over 97,200 more at 1-10 cm (seeds 21-28), from 16 to 10, for 0.77
    /// points. At 2.5: 8 and 7 such poses, for 1.1 points.
    pub(crate) const UNCONFIRMED_SIGMAS: f64 = 3.0;

    /// How far, in the start's sigmas, a refined solution that stands alone may lie from the
    /// solution its re-segmentation started from (`widened_from_start`). Over the same two sets
    /// (172,800 poses) poses reported ok and more than 5 degrees off fell from 19 to 16, and those
    /// more than 4 sigmas off from 23 to 20 (seeds 21-28), for 0.09 points fewer leveled; at 3
    /// sigmas the same, for 0.2 points.
    pub(crate) const FROM_START_SIGMAS: f64 = 4.0;
}

/// Fixed constants of re-segmentation's engine (`refine`).
pub(crate) mod refine {
    /// Sampled triples whose two edges' cross product is below this share of their lengths'
    /// product (nearly collinear: one scan line) propose no plane (`ransac::sampled_plane`).
    pub(crate) const COLLINEAR_SIN: f64 = 0.1;

    /// Level lines whose directions' cross product is shorter than this are parallel and can
    /// always lie in one plane (`lines::coplanar`).
    pub(crate) const PARALLEL_LINES_SIN: f64 = 0.05;

    /// The vertical tolerance of a typical grazing floor hit, which sizes the height windows
    /// of the floor and ceiling searches: its ray's share along the vertical \[1\] ...
    pub(crate) const GRAZING_RAY_DZ: f64 = 0.3;

    /// ... and its horizontal distance \[m\], the lever arm of an error in up.
    pub(crate) const GRAZING_LEVER: f64 = 2.0;

    /// Points beyond a level plane that `refine::opaque` lets pass: true planes have a few
    /// (allowing none leveled 7 points fewer poses at 5-10 cm noise, allowing two 0.4 points
    /// fewer).
    pub(crate) const MAX_BEYOND: usize = 5;

    /// Fewest points stepping as a ceiling does
    /// ([`LevelSteps::ceiling`](crate::level::refine::LevelSteps::ceiling)) among the highest
    /// points for these to stand for a ceiling in [`refine`](crate::level::refine::refine). Over
    /// 405,000 protocol poses at 1-10 cm (seeds 101-150, nine plans): poses more than 3 degrees off
    /// 498 -> 477, beyond 3 sigmas 409 -> 395, ok and more than 5 degrees off 28 -> 27, for 0.02
    /// points fewer leveled (at 15 the same within a few poses; with no such condition, a point
    /// fewer leveled).
    pub(crate) const CEILING_BAND_MIN_STEPS: usize = 5;

    /// Refit-and-reassign rounds when a floor or ceiling is first found.
    pub(crate) const LEVEL_ROUNDS: usize = 3;

    /// Floor or ceiling candidates must be this far from the scanner's height \[m\]: a level plane
    /// through the scanner is seen edge-on.
    pub(crate) const MIN_LEVEL_DISTANCE: f64 = 0.1;

    /// A wall's rows count towards `refine_min_rows` only with this share of its points each: a
    /// scan line plus a few stray points of another scan leaves the plane free to turn about the
    /// line.
    pub(crate) const WALL_ROW_SHARE: f64 = 0.15;

    /// Point triples tried by [`level_start`](crate::level::refine::level_start).
    pub(crate) const START_HYPOTHESES: usize = 48;

    /// Passes stop when up moves by less than this fraction of its uncertainty.
    pub(crate) const CONVERGED: f64 = 0.05;

    /// Largest up uncertainty used for assignment tolerances \[rad\].
    pub(crate) const MAX_SIGMA_UP: f64 = 0.06;

    /// Lines closer in direction than this \[deg\] are pieces of one wall when both reach a point.
    pub(crate) const SIMILAR_LINES_DEG: f64 = 20.0;

    /// Steps beyond this many standard deviations of the difference of two ranges count for
    /// [`LevelSteps::floor_line`](crate::level::refine::LevelSteps::floor_line) by their sign
    /// alone. Over 432,000 protocol poses at 5-10 cm (nine plans, seeds 101-180), leveled 74.16 ->
    /// 74.36% with 41 -> 40 poses ok and more than 5 degrees off, and 764 -> 752 more than 3
    /// degrees off (with floor and ceiling lines: at 1, 74.57% but 62 poses; at 3, 74.17% and 41);
    /// over 129,600 more (seeds 1-8, 11-14, 21-32), 74.15 -> 74.32% with 4 and 4; at 1 cm (seeds
    /// 1-8), 99.01 -> 99.09%.
    pub(crate) const LINE_STEP_SIGMAS: f64 = 2.0;

    /// Fewest points of a scan's floor line that joins a plane through another scan's line of
    /// `level_line_min_points` or more (`level_lines`): in the plane it adds its distance from
    /// the other line, a lever arm, not a direction of its own. Traced, floor points of 7 and 11
    /// in two scans beside a third scan's line of 15-18 were left out, and the poses (Cramér-Rao
    /// bounds under 0.1 degree) failed. Over 432,000 protocol poses at 5-10 cm (nine plans, seeds
    /// 101-180), leveled 74.36 -> 74.71% with 40 -> 41 poses ok and more than 5 degrees off and
    /// 752 -> 744 more than 3 degrees off (at 5 points: 74.62%, 41 and 745); over 129,600 more
    /// (seeds 1-8, 11-14, 21-32), 74.32 -> 74.64% with 4 and 4; at 1 cm, 99.09 -> 99.12%.
    pub(crate) const PLANE_LINE_MIN_POINTS: usize = 3;

    /// Largest misfit ratio of the plane through two or more level lines' points for the lines to
    /// stand as one floor or ceiling (`level_lines`).
    pub(crate) const LINES_PLANE_MISFIT: f64 = 3.0;

    /// Rounds of outlier removal of a level line.
    pub(crate) const LINE_ROUNDS: usize = 3;

    /// A seed's points must fit its line within this multiple of the residual their noise
    /// explains \[1\].
    pub(crate) const SEED_MISFIT: f64 = 2.0;

    /// Rays without a usable point that a growing line may step over.
    pub(crate) const MAX_GAP: usize = 2;
}
