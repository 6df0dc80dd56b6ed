//! Sampling and geometry of the walk: fast exponentials, a scatterer, an azimuth, a rotation,
//! a Lambertian direction, a flight's useful length and an emitted direction.

use std::f64::consts::PI;

use glam::DVec3;
use rand::RngExt;

use super::End;
use super::HORIZONTAL;
use crate::rng::Rng;
use crate::scene::BeamProfile;
use crate::transport::Setup;

/// 1 − e^{−τ} for τ ≥ 0, to a few ulps relative: expm1 only where the difference would cancel
/// (it costs about 3× exp in glibc, and this runs once per flight); exactly 1 beyond τ ≈ 37.
#[inline]
pub(super) fn one_minus_exp_neg(tau: f64) -> f64 {
    if tau > 40.0 {
        1.0
    } else if tau > 0.5 {
        1.0 - (-tau).exp()
    } else {
        -(-tau).exp_m1()
    }
}

/// A scatterer of the layer, chosen with probability σ_c/σ in channel `k` (σ: the layer's total
/// in that channel, > 0).
#[inline]
pub(super) fn pick_component(
    comps: &[crate::optics::Component],
    k: usize,
    sigma: f64,
    rng: &mut Rng,
) -> usize {
    if comps.len() == 1 {
        return 0;
    }
    // x starts ≥ 0 and only a scatterer with σ_c > 0 can take it below 0, so the one returned
    // scatters in this channel.
    let mut x = rng.random::<f64>() * sigma;
    for (j, comp) in comps.iter().enumerate() {
        x -= comp.sigma_s_per_m[k];
        if x < 0.0 {
            return j;
        }
    }
    // Rounding left x ≥ 0: the last scatterer that scatters in this channel.
    comps
        .iter()
        .rposition(|c| c.sigma_s_per_m[k] > 0.0)
        .unwrap_or(comps.len() - 1)
}

/// (cos φ, sin φ) of a uniform azimuth, by rejection from the unit disc and angle doubling
/// (von Neumann 1951): cheaper than a sine and a cosine.
#[inline]
pub(super) fn unit_azimuth(rng: &mut Rng) -> (f64, f64) {
    loop {
        let x = 2.0 * rng.random::<f64>() - 1.0;
        let y = 2.0 * rng.random::<f64>() - 1.0;
        let r2 = x * x + y * y;
        if r2 <= 1.0 && r2 > 1e-12 {
            let inv = 1.0 / r2;
            return ((x * x - y * y) * inv, 2.0 * x * y * inv);
        }
    }
}

/// Rotate the unit vector `dir` by a scattering angle with cosine `mu` and azimuth (cos φ, sin φ).
#[inline]
pub(crate) fn rotate(dir: DVec3, mu: f64, (cp, sp): (f64, f64)) -> DVec3 {
    let (e1, e2) = dir.any_orthonormal_pair();
    let sin_t = (1.0 - mu * mu).max(0.0).sqrt();
    let v = dir * mu + (e1 * cp + e2 * sp) * sin_t;
    // |v| = 1 to a few ulps: one Newton step for 1/|v| (1/√a ≈ (3 − a)/2 near a = 1) keeps
    // the length from drifting over thousands of scatterings, without a square root and a
    // division per scattering.
    v * (1.5 - 0.5 * v.length_squared())
}

/// Cosine-weighted (Lambertian) direction into the upper hemisphere.
#[inline]
pub(super) fn lambertian(u1: f64, u2: f64) -> DVec3 {
    let mu = u1.sqrt();
    let sin_t = (1.0 - u1).sqrt();
    let (sp, cp) = (2.0 * PI * u2).sin_cos();
    DVec3::new(sin_t * cp, sin_t * sp, mu.max(1e-300))
}

impl Setup<'_> {
    /// The useful part of a flight from `pos` along `dir` with `budget` = 2 r_end − path left,
    /// `(to_rx, d0)` = rx − pos and its length (d0 < budget), and where it ends: at the top of
    /// the atmosphere, its bottom or the surface, or on the ellipsoid with foci at the photon
    /// and the receiver beyond which no gate can receive it (path + s + |rx − x(s)| = 2 r_end).
    #[inline]
    pub(crate) fn useful_length(
        &self,
        pos: DVec3,
        dir: DVec3,
        budget: f64,
        (to_rx, d0): (DVec3, f64),
    ) -> (f64, End) {
        let mu = dir.z;
        let (s_bound, boundary) = if mu > HORIZONTAL {
            ((self.top_m - pos.z).max(0.0) / mu, End::Top)
        } else if mu < -HORIZONTAL {
            let end = if self.surface.is_some() {
                End::Surface
            } else {
                End::Bottom
            };
            ((self.bottom_m - pos.z).min(0.0) / mu, end)
        } else {
            (f64::INFINITY, End::Top)
        };
        // s = (b² − d0²)/(2(b − ω·(rx − x))), the denominator > 0 as b > d0: compared with the
        // boundary's distance before dividing, so that only flights the cut ends divide.
        let range_num = budget * budget - d0 * d0;
        let range_den = 2.0 * (budget - dir.dot(to_rx));
        if range_num < s_bound * range_den {
            (range_num / range_den, End::Cut)
        } else {
            (s_bound, boundary)
        }
    }

    /// A direction inside the beam's divergence around the axis.
    pub(crate) fn emit_direction(&self, u1: f64, u2: f64) -> DVec3 {
        if self.beam_half_angle_rad == 0.0 {
            return self.axis;
        }
        let theta = match self.beam_profile {
            BeamProfile::Uniform => {
                let cos_max = self.beam_half_angle_rad.cos();
                (1.0 - u1 * (1.0 - cos_max)).acos()
            }
            // Intensity ∝ exp(−2θ²/θ_e²) with θ_e the 1/e² half-angle: a 2-D Gaussian with
            // σ = θ_e/2 per axis, whose radial angle is Rayleigh distributed.
            BeamProfile::Gaussian => {
                0.5 * self.beam_half_angle_rad * (-2.0 * (1.0 - u1).ln()).sqrt()
            }
        };
        let (sp, cp) = (2.0 * PI * u2).sin_cos();
        let (st, ct) = theta.sin_cos();
        (self.axis * ct + (self.axis_e1 * cp + self.axis_e2 * sp) * st).normalize()
    }
}
