//! The passes of [`super::evaluate`] against the model written point by point
//! ([`super::model`]): the same cost, normal equations and predictions.

use super::evaluate::{Evaluation, Frame, Ray, Residual, evaluate, huber_cost, huber_weight};
use super::model::{
    Linearized, Placement, Plane, Rotations, incidence_on, linearize_on, linearize_plane,
    plane_rho, predict,
};
use super::{LabelledPoint, Surface};
use nalgebra::{Matrix2, Point3, Vector2, Vector3};

/// Rays fanned over two walls and the floor, their ranges off the model by up to 5 sigmas (so
/// that the kernel clips some), with their surfaces' placements.
fn scene() -> (Vec<LabelledPoint>, Vec<Surface>, Vec<Placement>) {
    let surfaces = vec![Surface::Wall(0), Surface::Wall(3), Surface::Floor];
    let placements = vec![
        Placement {
            offset: 3.0,
            azimuth: 0.3,
        },
        Placement {
            offset: 2.5,
            azimuth: 1.9,
        },
        Placement {
            offset: -0.45,
            azimuth: 0.0,
        },
    ];
    let rot = Rotations::at(&Vector2::new(0.05, -0.08));
    let mut points = Vec::new();
    for i in 0..60 {
        let slot = i % 3;
        let t = i as f64 * 0.37;
        let dir = Vector3::new(t.cos(), t.sin(), -0.3 + 0.01 * i as f64).normalize();
        let origin = Point3::new(0.01 * (i % 5) as f64, -0.02, 0.1);
        let point = LabelledPoint {
            origin,
            dir,
            range: 1.0,
            sigma: 0.01,
            surface: surfaces[slot],
        };
        let plane = Plane::at(&placements[slot], surfaces[slot]);
        let (r, _) = predict(&point, &plane, &rot);
        let off = 5.0 * ((i * 7919) % 101) as f64 / 100.0 - 2.5;
        points.push(LabelledPoint {
            range: r.abs() + off * 0.01 * 2.0,
            ..point
        });
    }
    (points, surfaces, placements)
}

fn assert_close(a: f64, b: f64, what: &str) {
    assert!(
        (a - b).abs() <= 1e-9 * (1.0 + a.abs().max(b.abs())),
        "{what}: {a} vs {b}"
    );
}

/// The cost, `H_aa`, `g_a` and per surface `(H_as, H_ss, g_s)`.
type Sums = (
    f64,
    Matrix2<f64>,
    Vector2<f64>,
    Vec<(Matrix2<f64>, Matrix2<f64>, Vector2<f64>)>,
);

/// The reference sums from the model's own residuals and derivatives.
fn reference(lins: &[(usize, Linearized)], blocks: usize, level: &[bool], k: f64) -> Sums {
    let (mut cost, mut h_aa, mut g_a) = (0.0, Matrix2::zeros(), Vector2::zeros());
    let mut per = vec![(Matrix2::zeros(), Matrix2::zeros(), Vector2::zeros()); blocks];
    for (s, lin) in lins {
        let w = huber_weight(lin.rho, k);
        let (ja, js) = (lin.by_attitude, lin.by_placement);
        cost += huber_cost(lin.rho, k);
        h_aa += ja * ja.transpose() * w;
        g_a += ja * (lin.rho * w);
        per[*s].0 += ja * js.transpose() * w;
        per[*s].1 += js * js.transpose() * w;
        per[*s].2 += js * (lin.rho * w);
    }
    for (p, &l) in per.iter_mut().zip(level) {
        if l {
            p.1[(1, 1)] = 1.0;
        }
    }
    (cost, h_aa, g_a, per)
}

#[test]
fn passes_match_the_model_point_by_point() {
    let (points, surfaces, placements) = scene();
    let rot = Rotations::at(&Vector2::new(0.06, -0.07));
    let planes: Vec<Plane> = surfaces
        .iter()
        .zip(&placements)
        .map(|(&s, p)| Plane::at(p, s))
        .collect();
    let frames: Vec<Frame> = planes.iter().map(|p| Frame::at(p, &rot)).collect();
    let slot = |p: &LabelledPoint| surfaces.iter().position(|&s| s == p.surface).unwrap();
    let mut rays: Vec<Ray> = points
        .iter()
        .enumerate()
        .map(|(index, p)| {
            let s = slot(p);
            let incidence = incidence_on(p, &planes[s].normal, &rot);
            assert_close(frames[s].incidence(&p.dir), incidence, "incidence");
            Ray::new(index, s, p, incidence)
        })
        .collect();
    rays.sort_by_key(|r| r.slot);
    let level = [false, false, true];
    for residual in [Residual::Range, Residual::Plane] {
        let k = 3.0;
        let mut out = Evaluation::default();
        evaluate(&rays, &frames, residual, k, true, &mut out);
        let lins: Vec<(usize, Linearized)> = rays
            .iter()
            .map(|r| {
                let p = &points[r.index];
                let plane = &planes[r.slot];
                let lin = match residual {
                    Residual::Range => linearize_on(p, plane, &rot),
                    Residual::Plane => {
                        let b = incidence_on(p, &plane.normal, &rot);
                        assert_close(
                            plane_rho(p, plane, &rot, b),
                            linearize_plane(p, plane, &rot, b).rho,
                            "plane rho",
                        );
                        linearize_plane(p, plane, &rot, b)
                    }
                };
                (r.slot, lin)
            })
            .collect();
        let clipped = lins.iter().filter(|(_, l)| l.rho.abs() > k).count();
        assert!(clipped > 0 && clipped < lins.len(), "the kernel clips some");
        let (cost, h_aa, g_a, per) = reference(&lins, frames.len(), &level, k);
        assert_close(out.cost, cost, "cost");
        for i in 0..4 {
            assert_close(out.arrow.h_aa[i], h_aa[i], "H_aa");
            for (b, p) in out.arrow.blocks.iter().zip(&per) {
                assert_close(b.0[i], p.0[i], "H_as");
                assert_close(b.1[i], p.1[i], "H_ss");
            }
        }
        for (b, p) in out.arrow.blocks.iter().zip(&per) {
            assert_close(b.2.x, p.2.x, "g_s");
            assert_close(b.2.y, p.2.y, "g_s");
        }
        assert_close(out.arrow.g_a.x, g_a.x, "g_a");
        assert_close(out.arrow.g_a.y, g_a.y, "g_a");
        if residual == Residual::Range {
            for (r, &predicted) in rays.iter().zip(&out.predicted) {
                let want = predict(&points[r.index], &planes[r.slot], &rot).0;
                assert_close(predicted, want, "prediction");
            }
        }
        // Without the normal equations: the same cost.
        let mut cost_only = Evaluation::default();
        evaluate(&rays, &frames, residual, k, false, &mut cost_only);
        assert_close(cost_only.cost, cost, "cost alone");
    }
}
