use super::*;

/// The short forms agree with the library's e^{−x} and expm1 to a couple of ulps over the
/// whole range, across both switch points.
#[test]
fn fast_exponentials_match_the_library() {
    let mut x: f64 = 1e-12;
    while x < 50.0 {
        let e = (-x).exp();
        assert!((exp_neg(x) - e).abs() <= 2.0 * f64::EPSILON * e, "e^-{x}");
        let m = -(-x).exp_m1();
        assert!(
            (one_minus_exp_neg(x) - m).abs() <= 2.0 * f64::EPSILON * m,
            "1 - e^-{x}"
        );
        x *= 1.01;
    }
    assert_eq!(exp_neg(0.0), 1.0);
    assert_eq!(one_minus_exp_neg(0.0), 0.0);
}

/// A direction rotated a million times stays a unit vector (no drift from skipping the
/// normalisation), and each rotation turns it by exactly the angle asked for.
#[test]
fn rotations_keep_unit_length_and_angle() {
    let mut d = DVec3::new(0.3, -0.4, 0.5).normalize();
    for i in 0..1_000_000u32 {
        let mu = ((i as f64) * 0.618_033_988_75).fract() * 2.0 - 1.0;
        let phi = (i as f64) * 2.399_963;
        let n = rotate(d, mu, (phi.cos(), phi.sin()));
        assert!((n.dot(d) - mu).abs() < 1e-12, "angle at step {i}");
        d = n;
    }
    assert!((d.length() - 1.0).abs() < 4.0 * f64::EPSILON);
}

/// Lambertian directions are cosine-weighted over the upper hemisphere, uniform in azimuth:
/// over a 400 × 400 midpoint grid of (u1, u2), the mean direction is (0, 0, 2/3) and the
/// second moments are ⟨μ²⟩ = 1/2, ⟨x²⟩ = ⟨y²⟩ = 1/4, ⟨xy⟩ = 0 (∫ μ^n 2μ dμ over [0, 1]).
#[test]
fn lambertian_directions_have_the_cosine_law_moments() {
    let n = 400;
    let (mut m1, mut xx, mut yy, mut xy, mut zz) = (DVec3::ZERO, 0.0, 0.0, 0.0, 0.0);
    for i in 0..n {
        for j in 0..n {
            let u1 = (i as f64 + 0.5) / n as f64;
            let u2 = (j as f64 + 0.5) / n as f64;
            let d = lambertian(u1, u2);
            assert!((d.length() - 1.0).abs() < 1e-12 && d.z > 0.0);
            m1 += d;
            xx += d.x * d.x;
            yy += d.y * d.y;
            xy += d.x * d.y;
            zz += d.z * d.z;
        }
    }
    let k = 1.0 / (n * n) as f64;
    let (m1, xx, yy, xy, zz) = (m1 * k, xx * k, yy * k, xy * k, zz * k);
    // Midpoint rule: errors O(1/n²) for the smooth moments, ~1e-5 at ⟨μ⟩ (√u1 at 0).
    assert!(m1.x.abs() < 1e-9 && m1.y.abs() < 1e-9, "{m1}");
    assert!((m1.z - 2.0 / 3.0).abs() < 1e-4, "{m1}");
    assert!((zz - 0.5).abs() < 1e-9, "⟨μ²⟩ = {zz}");
    assert!(
        (xx - 0.25).abs() < 1e-9 && (yy - 0.25).abs() < 1e-9,
        "{xx} {yy}"
    );
    assert!(xy.abs() < 1e-9, "⟨xy⟩ = {xy}");
}
