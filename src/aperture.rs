//! The receiver's aperture seen from close by: what the point-receiver estimate leaves out.
//!
//! The local estimate of the Monte Carlo and the analytic lidar equation both treat the
//! telescope as a point: the energy a scatterer at distance d sends into an aperture of area A
//! is taken as P(Θ)/(4π) · A cos θ_r/d² (Θ the scattering angle toward the telescope's centre,
//! θ_r the angle to its axis), and a Lambertian surface's as ρ cos θ_s/π · A cos θ_r/d². That is
//! the first term of an expansion in the aperture's angular radius α = atan(a/d) (a its
//! radius), right while neither the phase function nor 1/d² changes across the aperture. It
//! fails in two ways, both of which create energy:
//!
//! * **geometry**: A/d² grows without bound as d → 0, while the solid angle of a disk never
//!   exceeds 2π (a lidar 1 mm above a bright surface received more than it sent);
//! * **peaks narrower than α**: P(Θ) at one angle is not the mean of P over the aperture when
//!   P changes across it (a Henyey-Greenstein backscatter peak of g = −0.99999999, 1e-8 rad
//!   wide, is 2e16 at 180°: the lidar equation returned 5e7 J from a 1 J pulse).
//!
//! Where the point value could be off by more than [`POINT_TOLERANCE`], the estimators use
//! instead the energy the aperture actually collects, under two exact statements about a disk:
//! its solid angle seen from a point on its axis, Ω = 2π(1 − d/√(d² + a²)), and the cosine-
//! weighted one, ∫ cos θ dΩ = π a²/(d² + a²) (which is what a Lambertian surface sends into it);
//! off the axis both are taken times cos θ_r. The phase function becomes its mean over the band
//! of scattering angles Θ₀ ± α ([`crate::particles::phase::PhaseFunction::band_mean`]): exact
//! for the cap about either pole (where every single-scattering return and every peak lies)
//! and, because the band holds the cone the aperture spans, never more than the energy the
//! scatterer sends there. Hence no estimate from one scattering can exceed the weight scattered,
//! and a surface returns at most ρ of what reaches it. Far from the receiver nothing changes: the
//! point value is used, bit for bit as before.
//!
//! Both the Monte Carlo (`transport`) and the lidar equation (`lidar_eq`) take their factors
//! from here, so that their single scattering stays one quantity.

use crate::optics::OpticalAtmosphere;
use crate::particles::phase::PhaseFunction;

/// Largest relative error allowed to the point-receiver estimate: where the aperture average
/// could differ from it by more (its curvature term κα²/4, or the solid angle's 3ρ²/4, ρ = a/d),
/// the aperture average is used.
pub const POINT_TOLERANCE: f64 = 1e-3;

/// Where each layer's estimates need the aperture: the squared distances below which the
/// point-receiver estimate is replaced, per layer of the optical atmosphere, and for the
/// surface. A distance d needs it when the aperture's half-angle α ≈ a/d exceeds
/// √(4ε/κ) for the largest relative curvature κ of any phase function in the layer
/// ([`PhaseFunction::curvature`]), or when the solid angle's own correction 3a²/(4d²) exceeds ε
/// (ε = [`POINT_TOLERANCE`]).
#[derive(Debug, Clone, PartialEq)]
pub struct Aperture {
    /// The aperture's radius a \[m\].
    pub radius_m: f64,
    /// Per layer, d² \[m²\] below which the aperture average replaces the point value.
    pub near_d2: Vec<f64>,
    /// The same for a Lambertian surface (geometry only).
    pub surface_near_d2: f64,
}

impl Aperture {
    /// For a telescope of diameter `diameter_m` looking at `atm`.
    pub fn new(diameter_m: f64, atm: &OpticalAtmosphere) -> Self {
        let a = 0.5 * diameter_m;
        // Geometry: 3ρ²/4 ≤ ε, ρ = a/d.
        let geometric = a * a * 0.75 / POINT_TOLERANCE;
        let kappa: Vec<f64> = atm.phases.iter().map(|p| p.curvature()).collect();
        let near_d2 = atm
            .components
            .iter()
            .map(|comps| {
                let k = comps
                    .iter()
                    .flat_map(|c| c.phase.iter().map(|&i| kappa[i as usize]))
                    .fold(0.0f64, f64::max);
                // α = a/d > √(4ε/κ)  ⇔  d² < a²κ/(4ε).
                geometric.max(a * a * k / (4.0 * POINT_TOLERANCE))
            })
            .collect();
        Aperture {
            radius_m: a,
            near_d2,
            surface_near_d2: geometric,
        }
    }

    /// The aperture's half-angle seen from distance d on its axis, atan(a/d) \[rad\].
    #[inline]
    pub fn half_angle(&self, d: f64) -> f64 {
        self.radius_m.atan2(d)
    }

    /// Solid angle of the aperture per unit area seen from distance d on its axis, Ω/A =
    /// 2/(s (s + d)) with s = √(d² + a²) (Ω = 2π(1 − d/s), written without cancellation); 1/d²
    /// far away, 2/a² at d = 0.
    #[inline]
    pub fn solid_angle_per_area(&self, d: f64) -> f64 {
        let s = (d * d + self.radius_m * self.radius_m).sqrt();
        2.0 / (s * (s + d))
    }

    /// Cosine-weighted solid angle per unit area over π, what a Lambertian emitter at distance
    /// d on the axis sends into the aperture per unit area and albedo: 1/(d² + a²).
    #[inline]
    pub fn lambertian_per_area(&self, d: f64) -> f64 {
        1.0 / (d * d + self.radius_m * self.radius_m)
    }
}

/// The band of scattering angles the aperture spans from a scatterer at distance d, for light
/// arriving along `dir` and leaving toward the aperture's centre along `omega` (unit vectors):
/// Θ₀ ± α clipped to [0, π], with Θ₀ the angle between them (from atan2, accurate at the
/// poles) and α the aperture's half-angle.
#[inline]
pub fn band(dir: glam::DVec3, omega: glam::DVec3, half_angle: f64) -> (f64, f64) {
    let theta0 = dir.cross(omega).length().atan2(dir.dot(omega));
    (
        (theta0 - half_angle).max(0.0),
        (theta0 + half_angle).min(std::f64::consts::PI),
    )
}

/// The phase function of a mixture of scatterers (weights `w_i`, summing to `total`) averaged
/// over a band of scattering angles.
pub fn mixture_band_mean<'a>(
    parts: impl Iterator<Item = (f64, &'a PhaseFunction)>,
    total: f64,
    (lo, hi): (f64, f64),
) -> f64 {
    if !(total > 0.0) {
        return 0.0;
    }
    parts.map(|(w, p)| w * p.band_mean(lo, hi)).sum::<f64>() / total
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::PI;

    /// A mixture that scatters nothing (every class absorbing only, as in a layer of
    /// single-scattering albedo 0) has a band mean of 0, not 0/0: the lidar equation multiplies
    /// it by the layer's scattering coefficient, 0, and a NaN would survive that.
    #[test]
    fn a_mixture_without_scattering_has_no_band_mean() {
        let iso = PhaseFunction::Isotropic;
        let parts = || [(0.0, &iso), (0.0, &iso)].into_iter();
        assert_eq!(mixture_band_mean(parts(), 0.0, (PI - 1e-3, PI)), 0.0);
        let hg = PhaseFunction::HenyeyGreenstein(
            crate::particles::phase::HenyeyGreenstein::new(0.5).unwrap(),
        );
        let mixed = mixture_band_mean([(1.0, &iso), (3.0, &hg)].into_iter(), 4.0, (0.0, PI));
        // Over the whole sphere every normalised phase function averages to 1.
        assert!((mixed - 1.0).abs() < 1e-12, "{mixed}");
    }

    /// The solid angle of a disk seen from its axis, against 2π(1 − cos α) from its half-angle.
    #[test]
    fn solid_angle_of_a_disk() {
        let ap = Aperture {
            radius_m: 0.15,
            near_d2: Vec::new(),
            surface_near_d2: 0.0,
        };
        for d in [0.0, 1e-3, 0.15, 1.0, 100.0, 1e5] {
            let alpha = ap.half_angle(d);
            // 2π(1 − cos α) = 4π sin²(α/2), without cancellation.
            let omega = 4.0 * PI * (0.5 * alpha).sin().powi(2);
            let area = PI * 0.15 * 0.15;
            let got = ap.solid_angle_per_area(d) * area;
            assert!((got / omega - 1.0).abs() < 1e-9, "d {d}: {got} vs {omega}");
            assert!(got <= 2.0 * PI * (1.0 + 1e-15));
            // Cosine-weighted: π sin²α.
            let cw = ap.lambertian_per_area(d) * area;
            assert!((cw / (PI * alpha.sin().powi(2)) - 1.0).abs() < 1e-9);
        }
        // Far away: A/d² to the next order, 1 − 3ρ²/4.
        let d = 1000.0;
        let rho2 = (0.15f64 / d).powi(2);
        let ratio = ap.solid_angle_per_area(d) * d * d;
        assert!((ratio - (1.0 - 0.75 * rho2)).abs() < 1e-12, "{ratio}");
    }

    /// The band about a pole is the cap: its angle from the vectors is exact there.
    #[test]
    fn band_of_exact_backscatter_is_the_cap() {
        let dir = glam::DVec3::Z;
        let (lo, hi) = band(dir, -dir, 1e-6);
        assert_eq!(hi, PI);
        assert!((lo - (PI - 1e-6)).abs() < 1e-15);
        let (lo, hi) = band(dir, dir, 1e-6);
        assert_eq!(lo, 0.0);
        assert!((hi - 1e-6).abs() < 1e-21);
    }
}
