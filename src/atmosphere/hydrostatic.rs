//! Hydrostatic altitudes from pressure, temperature and humidity, with normal gravity.
//!
//! For profiles given on pressure levels (NWP and reanalysis sets) the geometric altitude of each
//! level follows from the hydrostatic equation with the ideal gas law for moist air,
//!
//! `dΦ = g(z) dz = −(R/M_d) T_v d ln p`   (Φ geopotential, T_v virtual temperature),
//!
//! integrated level by level with T_v linear in ln p between levels (the trapezoid in ln p is then
//! exact), and inverted for z with the WGS 84 normal gravity and its second-order height
//! expansion.
//!
//! # Between levels: one integration for pressure and columns
//!
//! [`HydrostaticProfile`] gives a profile's state between its levels, and every column and
//! pressure thickness lidarsim takes between levels comes from it (the Curtis-Godson layers of
//! the line-by-line stage, the profile's columns, the weighting function's Δp). Within a level
//! interval [z_i, z_{i+1}]: T is linear in z; the water vapour mixing ratio x_w is log-linear,
//! and every other gas's mixing ratio in dry air, x/(1 − x_w), too (linear where a level has
//! none), so that a gas well mixed in dry air keeps its dry-air column average exactly; and the
//! pressure follows the hydrostatic equation for moist air,
//!
//! ```text
//! d ln p/dz = −(g(z) M_d/R) / T_v(z)   ⇒   ln p(z) = ln p_i − ln(p_i/p_{i+1}) · J_i(z)/J_i(z_{i+1}),
//! J_i(z) = ∫_{z_i}^{z} γ(z')/T_v(z') dz',   n = p/(kT)
//! ```
//!
//! with g(z) = g₀ γ(z), γ normal gravity's height factor and g₀ the value that takes the
//! pressure from p_i to p_{i+1} (a hydrostatic profile's own gravity). So the air column between
//! two altitudes of one interval is ∫ n dz = ∫ dp/(m(x_w) g(z)): the pressure thickness over
//! the mass of a molecule of moist air and gravity, the hydrostatic equation itself. Taking the
//! pressure with ln p linear in z instead, as a plain interpolation does, assumes T_v constant
//! over the interval while the columns use T linear: the column per unit pressure then varies
//! by ΔT/T (±1 % over a 1 km interval of the tropical troposphere), the IPDA weighting function
//! carried that sawtooth, and it set the reported peak (819 hPa where the weighting function of
//! the hydrostatic equation peaks at 760 hPa, tropical, R16e + 2.1 GHz). Holding g constant
//! over an interval left ±1.5e-4 of it, enough to move the peak of a flat weighting function
//! by 150 hPa.

use super::humidity::virtual_temperature_k;
use super::{AtmosphereError, Profile};
use crate::constants::{AVOGADRO_PER_MOL, BOLTZMANN_J_PER_K, MOLAR_MASS_DRY_AIR_KG_PER_MOL};

/// Gauss-Legendre nodes and weights on [−1, 1], 8 points (exact to rounding for the smooth
/// integrands between levels: 1/T_v, and p/(kT) with its mixing ratios).
pub(crate) const GL8: [(f64, f64); 8] = [
    (-0.960_289_856_497_536_2, 0.101_228_536_290_376_26),
    (-0.796_666_477_413_626_7, 0.222_381_034_453_374_48),
    (-0.525_532_409_916_329, 0.313_706_645_877_887_3),
    (-0.183_434_642_495_649_8, 0.362_683_783_378_362),
    (0.183_434_642_495_649_8, 0.362_683_783_378_362),
    (0.525_532_409_916_329, 0.313_706_645_877_887_3),
    (0.796_666_477_413_626_7, 0.222_381_034_453_374_48),
    (0.960_289_856_497_536_2, 0.101_228_536_290_376_26),
];

/// A profile between its levels by one hydrostatic integration (module docs, "Between
/// levels"). Built on a valid profile ([`Profile::validate`]: altitudes increasing, pressures
/// decreasing and positive, temperatures positive); with fewer than two levels every integral
/// is 0.
#[derive(Debug, Clone)]
pub struct HydrostaticProfile<'a> {
    profile: &'a Profile,
    h2o: Option<&'a [f64]>,
    /// J_i(z_{i+1}) = ∫ dz/T_v over each level interval \[m/K\].
    j_full: Vec<f64>,
    /// Per level interval: the pressure's log-linear interpolant, the water vapour's, and
    /// each gas's (the rule of [`Self::gas_vmr`]), with their logarithms worked out once: the
    /// columns evaluate them at every node of two nested quadratures, and a power per node
    /// was most of a Curtis-Godson layer's cost.
    pressure: Vec<LogLinear>,
    h2o_interp: Vec<LogLinear>,
    gases: Vec<Vec<(LogLinear, bool)>>,
    /// The height factor of normal gravity at 45° ([`Self::j`]).
    height: (f64, f64),
}

/// a (b/a)^t on one interval as a e^{t ln(b/a)}, with ln(b/a) computed once (within a few
/// ulps of the power), or linearly where either end is not positive.
#[derive(Debug, Clone, Copy)]
struct LogLinear {
    a: f64,
    b: f64,
    ln_ratio: f64,
    log: bool,
}

impl LogLinear {
    fn new(a: f64, b: f64) -> Self {
        let log = a > 0.0 && b > 0.0;
        LogLinear {
            a,
            b,
            ln_ratio: if log { (b / a).ln() } else { 0.0 },
            log,
        }
    }

    #[inline]
    fn at(&self, t: f64) -> f64 {
        if self.log {
            self.a * (t * self.ln_ratio).exp()
        } else {
            self.a + (self.b - self.a) * t
        }
    }
}

/// The state at one altitude.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HydrostaticState {
    /// Pressure \[Pa\].
    pub pressure_pa: f64,
    /// Temperature \[K\].
    pub temperature_k: f64,
    /// Air (moist) number density p/(kT) \[1/m³\].
    pub air_number_density_per_m3: f64,
}

/// Integrals over an altitude range, per unit area.
#[derive(Debug, Clone, PartialEq)]
pub struct ColumnIntegrals {
    /// Air column ∫ n dz \[1/m²\].
    pub air_per_m2: f64,
    /// Column of each gas of the profile, in its order, ∫ x n dz \[1/m²\].
    pub gas_per_m2: Vec<f64>,
    /// ∫ p n dz \[Pa/m²\] (the Curtis-Godson pressure is this over the air column).
    pub pressure_weighted: f64,
    /// ∫ T n dz \[K/m²\].
    pub temperature_weighted: f64,
}

impl<'a> HydrostaticProfile<'a> {
    /// The integration of `profile` (its level intervals' ∫ dz/T_v worked out once).
    pub fn new(profile: &'a Profile) -> Self {
        let mut h = HydrostaticProfile {
            profile,
            h2o: profile.gas("H2O"),
            j_full: Vec::new(),
            pressure: Vec::new(),
            h2o_interp: Vec::new(),
            gases: Vec::new(),
            height: height_coefficients(45.0),
        };
        let n = profile
            .altitude_m
            .len()
            .min(profile.pressure_pa.len())
            .min(profile.temperature_k.len());
        let intervals = n.saturating_sub(1);
        let p = &profile.pressure_pa;
        h.pressure = (0..intervals)
            .map(|i| LogLinear::new(p[i], p[i + 1]))
            .collect();
        if let Some(w) = h.h2o {
            h.h2o_interp = (0..intervals.min(w.len().saturating_sub(1)))
                .map(|i| LogLinear::new(w[i], w[i + 1]))
                .collect();
        }
        h.gases = profile
            .gases
            .iter()
            .map(|g| {
                let vmr = &g.vmr[..];
                (0..intervals.min(vmr.len().saturating_sub(1)))
                    .map(|i| match h.h2o {
                        Some(w) if !std::ptr::eq(w, vmr) && w[i] < 1.0 && w[i + 1] < 1.0 => (
                            LogLinear::new(vmr[i] / (1.0 - w[i]), vmr[i + 1] / (1.0 - w[i + 1])),
                            true,
                        ),
                        _ => (LogLinear::new(vmr[i], vmr[i + 1]), false),
                    })
                    .collect()
            })
            .collect();
        h.j_full = (0..n.saturating_sub(1))
            .map(|i| h.j(i, profile.altitude_m[i + 1]))
            .collect();
        h
    }

    /// The level interval holding `z` (the lowest or highest one beyond the profile).
    pub fn interval(&self, z: f64) -> usize {
        let z_levels = &self.profile.altitude_m;
        z_levels
            .partition_point(|&zi| zi <= z)
            .saturating_sub(1)
            .min(self.j_full.len().saturating_sub(1))
    }

    /// Fraction of interval `i` at `z`.
    #[inline]
    fn fraction(&self, i: usize, z: f64) -> f64 {
        let z_levels = &self.profile.altitude_m;
        (z - z_levels[i]) / (z_levels[i + 1] - z_levels[i])
    }

    /// T at `z` in interval `i` (linear in z).
    #[inline]
    fn temperature(&self, i: usize, t: f64) -> f64 {
        let tk = &self.profile.temperature_k;
        tk[i] + (tk[i + 1] - tk[i]) * t
    }

    /// Mixing ratio (of moist air) of gas `g` at fraction `t` of interval `i`, `x_w` the water
    /// vapour's there (module docs): log-linear in dry air.
    #[inline]
    fn gas_vmr(&self, g: usize, i: usize, t: f64, x_w: f64) -> f64 {
        let (interp, dry) = self.gases[g][i];
        if dry {
            interp.at(t) * (1.0 - x_w)
        } else {
            interp.at(t)
        }
    }

    /// The water vapour's mixing ratio at fraction `t` of interval `i` (0 without it).
    #[inline]
    fn h2o_vmr(&self, i: usize, t: f64) -> f64 {
        self.h2o_interp.get(i).map_or(0.0, |w| w.at(t))
    }

    /// J_i(z) = ∫_{z_i}^{z} γ(z')/T_v(z') dz' (8-point Gauss-Legendre), γ the height factor
    /// of normal gravity, 1 − c₁z + c₂z² ([`normal_gravity_m_per_s2`]; at 45°: its latitude
    /// dependence changes c₁ by 3e-3 of itself, 1e-9 of γ over a kilometre).
    fn j(&self, i: usize, z: f64) -> f64 {
        let (c1, c2) = self.height;
        let z0 = self.profile.altitude_m[i];
        let (mid, half) = (0.5 * (z0 + z), 0.5 * (z - z0));
        GL8.iter()
            .map(|(x, w)| {
                let zz = mid + half * x;
                let t = self.fraction(i, zz);
                let x_w = self.h2o_vmr(i, t);
                let gamma = 1.0 - c1 * zz + c2 * zz * zz;
                w * half * gamma / virtual_temperature_k(self.temperature(i, t), x_w)
            })
            .sum()
    }

    /// Pressure, temperature and air number density at `z` in level interval `i`.
    pub fn state_in(&self, i: usize, z: f64) -> HydrostaticState {
        let t = self.fraction(i, z);
        let share = if self.j_full[i] != 0.0 {
            self.j(i, z) / self.j_full[i]
        } else {
            t
        };
        let pressure_pa = self.pressure[i].at(share);
        let temperature_k = self.temperature(i, t);
        HydrostaticState {
            pressure_pa,
            temperature_k,
            air_number_density_per_m3: pressure_pa / (BOLTZMANN_J_PER_K * temperature_k),
        }
    }

    /// Pressure \[Pa\] at `z` (inside the profile; at its levels, their pressures exactly).
    pub fn pressure_pa(&self, z: f64) -> f64 {
        if self.j_full.is_empty() {
            return self
                .profile
                .pressure_pa
                .first()
                .copied()
                .unwrap_or(f64::NAN);
        }
        let i = self.interval(z);
        if z == self.profile.altitude_m[i + 1] {
            return self.profile.pressure_pa[i + 1];
        }
        self.state_in(i, z).pressure_pa
    }

    /// Columns and Curtis-Godson weights between `z_a` < `z_b` (inside the profile): 8-point
    /// Gauss-Legendre on each piece between levels.
    pub fn integrate(&self, z_a: f64, z_b: f64) -> ColumnIntegrals {
        let gases = &self.profile.gases;
        let mut out = ColumnIntegrals {
            air_per_m2: 0.0,
            gas_per_m2: vec![0.0; gases.len()],
            pressure_weighted: 0.0,
            temperature_weighted: 0.0,
        };
        if self.j_full.is_empty() {
            return out;
        }
        let z = &self.profile.altitude_m;
        let mut i = self.interval(z_a);
        let mut a = z_a;
        while a < z_b {
            let b = z[i + 1].min(z_b);
            let (mid, half) = (0.5 * (a + b), 0.5 * (b - a));
            for (x, wq) in GL8 {
                let zz = mid + half * x;
                let s = self.state_in(i, zz);
                let t = self.fraction(i, zz);
                let x_w = self.h2o_vmr(i, t);
                let wn = wq * half * s.air_number_density_per_m3;
                out.air_per_m2 += wn;
                out.pressure_weighted += wn * s.pressure_pa;
                out.temperature_weighted += wn * s.temperature_k;
                for (g, u) in out.gas_per_m2.iter_mut().enumerate() {
                    *u += wn * self.gas_vmr(g, i, t, x_w);
                }
            }
            a = b;
            i += 1;
            if i >= self.j_full.len() {
                break;
            }
        }
        out
    }
}

/// WGS 84 semi-major axis a \[m\] (NIMA TR8350.2, 2000, Table 3.1).
const WGS84_A_M: f64 = 6_378_137.0;
/// WGS 84 flattening f.
const WGS84_F: f64 = 1.0 / 298.257_223_563;
/// WGS 84 m = ω² a² b / GM.
const WGS84_M: f64 = 0.003_449_786_506_84;
/// WGS 84 normal gravity at the equator [m/s²].
const WGS84_GAMMA_E: f64 = 9.780_325_335_9;
/// WGS 84 Somigliana constant k.
const WGS84_K: f64 = 0.001_931_852_652_41;
/// WGS 84 first eccentricity squared.
const WGS84_E2: f64 = 0.006_694_379_990_14;

/// Normal gravity on the WGS 84 ellipsoid [m/s²] at geodetic latitude φ (Somigliana's formula):
/// `γ(φ) = γ_e (1 + k sin²φ) / sqrt(1 − e² sin²φ)`.
///
/// [^1]: NIMA (2000), Department of Defense World Geodetic System 1984, TR8350.2 3rd ed.,
/// Eq. (4-1).
pub fn normal_gravity_surface_m_per_s2(latitude_deg: f64) -> f64 {
    let s2 = latitude_deg.to_radians().sin().powi(2);
    WGS84_GAMMA_E * (1.0 + WGS84_K * s2) / (1.0 - WGS84_E2 * s2).sqrt()
}

/// Normal gravity [m/s²] at height h \[m\] above the ellipsoid (second-order expansion):
/// `γ_h = γ(φ) [1 − (2/a)(1 + f + m − 2 f sin²φ) h + 3 h²/a²]`.
///
/// Valid for |h| ≪ a: against the closed form of the ellipsoid's normal field (TR8350.2
/// Eq. 4-5) it is within 1.5e-7 relative up to 20 km, 2e-6 at 50 km and 3e-5 at 120 km (the
/// neglected third-order term, ≈ 4 h³/a³).
///
/// [^1]: NIMA (2000), TR8350.2, Eq. (4-3).
pub fn normal_gravity_m_per_s2(latitude_deg: f64, height_m: f64) -> f64 {
    let (c1, c2) = height_coefficients(latitude_deg);
    normal_gravity_surface_m_per_s2(latitude_deg) * (1.0 - c1 * height_m + c2 * height_m * height_m)
}

fn height_coefficients(latitude_deg: f64) -> (f64, f64) {
    let s2 = latitude_deg.to_radians().sin().powi(2);
    let c1 = 2.0 / WGS84_A_M * (1.0 + WGS84_F + WGS84_M - 2.0 * WGS84_F * s2);
    let c2 = 3.0 / (WGS84_A_M * WGS84_A_M);
    (c1, c2)
}

/// Geopotential Φ(h) = ∫₀ʰ γ dh' [m²/s²] of [`normal_gravity_m_per_s2`].
pub fn geopotential_m2_per_s2(latitude_deg: f64, height_m: f64) -> f64 {
    let (c1, c2) = height_coefficients(latitude_deg);
    let h = height_m;
    normal_gravity_surface_m_per_s2(latitude_deg) * (h - 0.5 * c1 * h * h + c2 * h * h * h / 3.0)
}

/// Height \[m\] whose geopotential is `phi` (Newton iteration on [`geopotential_m2_per_s2`]).
pub fn height_from_geopotential_m(latitude_deg: f64, phi: f64) -> f64 {
    let g0 = normal_gravity_surface_m_per_s2(latitude_deg);
    let mut h = phi / g0;
    for _ in 0..50 {
        let step = (geopotential_m2_per_s2(latitude_deg, h) - phi)
            / normal_gravity_m_per_s2(latitude_deg, h);
        h -= step;
        if step.abs() < 1e-7 {
            break;
        }
    }
    h
}

/// Specific gas constant of dry air R_d = N_A k / M_d [J/(kg K)].
pub fn dry_air_gas_constant_j_per_kg_k() -> f64 {
    AVOGADRO_PER_MOL * BOLTZMANN_J_PER_K / MOLAR_MASS_DRY_AIR_KG_PER_MOL
}

/// Geometric altitudes \[m\] of pressure levels (bottom to top) from the hydrostatic equation.
///
/// `Φ_{k+1} = Φ_k + R_d (T_v,k + T_v,k+1)/2 · ln(p_k/p_{k+1})`, then z_k = h(Φ_k) with
/// Φ_0 = Φ(`surface_altitude_m`); T_v from T and the water vapour volume mixing ratio
/// (`h2o_vmr`, moist air; dry air when `None`). Gravity: WGS 84 normal gravity at
/// `latitude_deg` and its height dependence. The molar mass of dry air is constant (valid below
/// the homopause, ≈ 90 km; above, the US standard 1976 lets it decrease and its altitudes differ).
///
/// Errors: vectors of different length, fewer than two levels, pressures not strictly
/// decreasing and positive, temperatures not positive.
pub fn hydrostatic_altitudes_m(
    pressure_pa: &[f64],
    temperature_k: &[f64],
    h2o_vmr: Option<&[f64]>,
    surface_altitude_m: f64,
    latitude_deg: f64,
) -> Result<Vec<f64>, AtmosphereError> {
    let n = pressure_pa.len();
    let bad = |m: String| AtmosphereError::InvalidArgument(format!("hydrostatic altitudes: {m}"));
    if n < 2 || temperature_k.len() != n || h2o_vmr.is_some_and(|h| h.len() != n) {
        return Err(bad(format!(
            "need at least 2 levels and equal lengths (pressure {n}, temperature {})",
            temperature_k.len()
        )));
    }
    if !(surface_altitude_m.is_finite() && latitude_deg.is_finite() && latitude_deg.abs() <= 90.0) {
        return Err(bad(format!(
            "surface altitude {surface_altitude_m} m or latitude {latitude_deg}° is not valid"
        )));
    }
    if pressure_pa
        .windows(2)
        .any(|w| !(w[1] < w[0] && w[1] > 0.0 && w[0].is_finite()))
    {
        return Err(bad(
            "pressures are not strictly decreasing and positive".into()
        ));
    }
    if temperature_k.iter().any(|t| !(t.is_finite() && *t > 0.0)) {
        return Err(bad("a temperature is not positive".into()));
    }
    let r_d = dry_air_gas_constant_j_per_kg_k();
    let tv: Vec<f64> = (0..n)
        .map(|k| virtual_temperature_k(temperature_k[k], h2o_vmr.map_or(0.0, |h| h[k])))
        .collect();
    let mut phi = geopotential_m2_per_s2(latitude_deg, surface_altitude_m);
    let mut z = Vec::with_capacity(n);
    z.push(surface_altitude_m);
    for k in 0..n - 1 {
        phi += r_d * 0.5 * (tv[k] + tv[k + 1]) * (pressure_pa[k] / pressure_pa[k + 1]).ln();
        z.push(height_from_geopotential_m(latitude_deg, phi));
    }
    Ok(z)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// WGS 84 normal gravity: 9.7803253359 at the equator, 9.8321849378 at the poles
    /// (TR8350.2 Table 3.4); 9.8061978 at 45° (the closed form evaluated by hand; series approximations of GRS 80 give 9.80620).
    #[test]
    fn normal_gravity_matches_wgs84() {
        assert!((normal_gravity_surface_m_per_s2(0.0) - 9.780_325_335_9).abs() < 1e-9);
        assert!((normal_gravity_surface_m_per_s2(90.0) - 9.832_184_937_8).abs() < 1e-8);
        assert!((normal_gravity_surface_m_per_s2(45.0) - 9.806_197_8).abs() < 1e-6);
    }

    #[test]
    fn geopotential_inverts() {
        for h in [-400.0, 0.0, 1e4, 8e4, 1.2e5] {
            let phi = geopotential_m2_per_s2(30.0, h);
            assert!((height_from_geopotential_m(30.0, phi) - h).abs() < 1e-6);
        }
    }

    /// Normal gravity of the WGS 84 ellipsoid in closed form, at geodetic latitude φ and
    /// height h, from its ellipsoidal-harmonic field (NIMA TR8350.2 Eqs. 4-4 to 4-5;
    /// Hofmann-Wellenhof & Moritz 2005, Physical Geodesy §2.8): the truth the height series
    /// is checked against. Constants from TR8350.2 Table 3.1 (a, 1/f, GM, ω).
    fn closed_form_gravity(latitude_deg: f64, height_m: f64) -> f64 {
        let (a, f, gm, omega): (f64, f64, f64, f64) = (
            6_378_137.0,
            1.0 / 298.257_223_563,
            3.986_004_418e14,
            7.292_115e-5,
        );
        let b = a * (1.0 - f);
        let e_lin = (a * a - b * b).sqrt();
        let e2 = f * (2.0 - f);
        let phi = latitude_deg.to_radians();
        let n = a / (1.0 - e2 * phi.sin().powi(2)).sqrt();
        let (x, z) = (
            (n + height_m) * phi.cos(),
            (n * (1.0 - e2) + height_m) * phi.sin(),
        );
        let r2e = x * x + z * z - e_lin * e_lin;
        let u =
            (0.5 * r2e * (1.0 + (1.0 + 4.0 * e_lin * e_lin * z * z / (r2e * r2e)).sqrt())).sqrt();
        let beta = (z * (u * u + e_lin * e_lin).sqrt()).atan2(u * x);
        let q = |u: f64| {
            0.5 * ((1.0 + 3.0 * u * u / (e_lin * e_lin)) * (e_lin / u).atan() - 3.0 * u / e_lin)
        };
        let q0 = q(b);
        let q1 =
            3.0 * (1.0 + u * u / (e_lin * e_lin)) * (1.0 - u / e_lin * (e_lin / u).atan()) - 1.0;
        let ue2 = u * u + e_lin * e_lin;
        let w = ((u * u + e_lin * e_lin * beta.sin().powi(2)) / ue2).sqrt();
        let w2 = omega * omega;
        let g_u = -(gm / ue2
            + w2 * a * a * e_lin / ue2 * q1 / q0 * (0.5 * beta.sin().powi(2) - 1.0 / 6.0)
            - w2 * u * beta.cos().powi(2))
            / w;
        let g_beta =
            (-w2 * a * a / ue2.sqrt() * q(u) / q0 + w2 * ue2.sqrt()) * beta.sin() * beta.cos() / w;
        g_u.hypot(g_beta)
    }

    /// The height series against the closed form, at latitudes where the flattening term
    /// f(1 − 2 sin²φ) is not zero (it moves gravity at 10 km by ±2e-5 relative; the series is
    /// within 1.5e-7 below 20 km), and the closed form itself against Somigliana at h = 0.
    #[test]
    fn normal_gravity_with_height_matches_the_closed_form() {
        for lat in [0.0, 30.0, 60.0, 90.0, -75.0] {
            let g0 = closed_form_gravity(lat, 0.0);
            assert!(
                (g0 / normal_gravity_surface_m_per_s2(lat) - 1.0).abs() < 1e-11,
                "{lat}"
            );
            for (h, tol) in [
                (5e3, 1.5e-7),
                (1e4, 1.5e-7),
                (2e4, 2e-7),
                (5e4, 3e-6),
                (1.2e5, 3.5e-5),
            ] {
                let rel = normal_gravity_m_per_s2(lat, h) / closed_form_gravity(lat, h) - 1.0;
                assert!(rel.abs() < tol, "φ {lat}°, h {h} m: {rel:e}");
            }
        }
    }

    /// The geopotential against the closed-form gravity integrated by Gauss–Legendre (its
    /// height term is ∫ of a quadratic, so the quadrature differs only by the series' own
    /// error), and its inverse, at the equator and the pole.
    #[test]
    fn geopotential_is_the_integral_of_gravity() {
        // 5-point Gauss–Legendre nodes and weights on [−1, 1] (Abramowitz & Stegun 25.4.30).
        let nodes = [
            0.0,
            0.538_469_310_105_683_1,
            -0.538_469_310_105_683_1,
            0.906_179_845_938_664,
            -0.906_179_845_938_664,
        ];
        let weights = [
            0.568_888_888_888_888_9,
            0.478_628_670_499_366_5,
            0.478_628_670_499_366_5,
            0.236_926_885_056_189_1,
            0.236_926_885_056_189_1,
        ];
        for lat in [0.0, 90.0] {
            for h in [3e3, 1.5e4] {
                let exact: f64 = nodes
                    .iter()
                    .zip(weights)
                    .map(|(x, w)| w * 0.5 * h * closed_form_gravity(lat, 0.5 * h * (1.0 + x)))
                    .sum();
                let phi = geopotential_m2_per_s2(lat, h);
                assert!(
                    (phi / exact - 1.0).abs() < 1.5e-7,
                    "φ {lat}°, h {h}: {:e}",
                    phi / exact - 1.0
                );
                assert!((height_from_geopotential_m(lat, exact) - h).abs() < 2e-3 * h / 1e4);
            }
        }
    }

    /// An isothermal dry atmosphere has z = H ln(p0/p) with H = R_d T / g when gravity is
    /// constant; with height-dependent gravity the thickness grows by ≈ (1 + c1 z/2): checked
    /// against the closed form to 1e-9 relative at 10 km.
    #[test]
    fn isothermal_column_matches_closed_form() {
        let t = 250.0;
        let p = [1e5, 5e4, 2.5e4];
        let z = hydrostatic_altitudes_m(&p, &[t; 3], None, 0.0, 45.0).unwrap();
        let phi = dry_air_gas_constant_j_per_kg_k() * t * (1e5f64 / 2.5e4).ln();
        assert!((geopotential_m2_per_s2(45.0, z[2]) / phi - 1.0).abs() < 1e-9);
        let g = normal_gravity_surface_m_per_s2(45.0);
        // Within 0.3 % of the constant-gravity scale height at ~10 km (c1 z ≈ 3e-3).
        assert!((z[2] / (phi / g) - 1.0).abs() < 3e-3);
        // At the equator and the pole the altitude is where the closed-form gravity's
        // geopotential reaches R_d T ln(p0/p): 5-point Gauss–Legendre, as above.
        for lat in [0.0, 90.0] {
            let z = hydrostatic_altitudes_m(&p, &[t; 3], None, 0.0, lat).unwrap();
            let g_mid = closed_form_gravity(lat, 0.5 * z[2]);
            let g_mean =
                (closed_form_gravity(lat, 0.0) + 4.0 * g_mid + closed_form_gravity(lat, z[2]))
                    / 6.0;
            assert!(
                (g_mean * z[2] / phi - 1.0).abs() < 2e-7,
                "φ {lat}°: {:e}",
                g_mean * z[2] / phi - 1.0
            );
        }
    }

    /// A moist tropical-like column on levels made by [`hydrostatic_altitudes_m`] (normal
    /// gravity at 15°, 1 km apart near the surface): between levels, the pressure meets every
    /// level exactly, and the air column of any sub-layer is the hydrostatic equation's
    /// ∫ dp/(m(x_w) g(z)), m = (M_d (1 − x_w) + M_w x_w)/N_A, summed here in 1 Pa steps with
    /// x_w log-linear and z linear in ln p between levels, within 2e-4 (measured 1.1e-4, where
    /// x_w falls fastest: this sum interpolates it in ln p, the integration in z; with gravity
    /// held constant over each interval it was 2.3e-4). The dry-air column per unit pressure
    /// is constant within an interval up to the humidity's change: no sawtooth of ΔT/T (2 %
    /// across each interval here).
    #[test]
    fn columns_are_the_pressure_thickness_over_m_g() {
        use crate::atmosphere::{GasProfile, Profile};
        use crate::constants::{AVOGADRO_PER_MOL, MOLAR_MASS_WATER_KG_PER_MOL};
        let p_pa = vec![101_300.0, 90_400.0, 80_500.0, 71_500.0, 63_300.0, 55_900.0];
        let t_k = vec![299.7, 293.7, 287.7, 283.7, 277.0, 270.3];
        let x_w = vec![2.6e-2, 1.95e-2, 1.53e-2, 8.6e-3, 4.4e-3, 3.3e-3];
        let lat = 15.0;
        let z = hydrostatic_altitudes_m(&p_pa, &t_k, Some(&x_w), 0.0, lat).unwrap();
        let prof = Profile {
            name: "moist".into(),
            altitude_m: z.clone(),
            pressure_pa: p_pa.clone(),
            temperature_k: t_k,
            gases: vec![GasProfile {
                name: "H2O".into(),
                vmr: x_w.clone(),
            }],
        };
        let h = HydrostaticProfile::new(&prof);
        for (k, zk) in z.iter().enumerate() {
            assert_eq!(h.pressure_pa(*zk), p_pa[k]);
        }
        // The hydrostatic column between two pressures, in 1 Pa steps.
        let column = |p_hi: f64, p_lo: f64| -> f64 {
            let mut u = 0.0;
            let mut p = p_hi;
            while p > p_lo {
                let dp = (p - p_lo).min(1.0);
                let pm = p - 0.5 * dp;
                let i = p_pa.iter().position(|&q| q < pm).unwrap() - 1;
                let s = (p_pa[i] / pm).ln() / (p_pa[i] / p_pa[i + 1]).ln();
                let w = x_w[i] * (x_w[i + 1] / x_w[i]).powf(s);
                let zz = z[i] + s * (z[i + 1] - z[i]);
                let m = (MOLAR_MASS_DRY_AIR_KG_PER_MOL * (1.0 - w)
                    + MOLAR_MASS_WATER_KG_PER_MOL * w)
                    / AVOGADRO_PER_MOL;
                u += dp / (m * normal_gravity_m_per_s2(lat, zz));
                p -= dp;
            }
            u
        };
        let mut per_dp = Vec::new();
        for (a, b) in [
            (0.0, 250.0),
            (250.0, 500.0),
            (500.0, 750.0),
            (750.0, 1000.0),
            (300.0, 3700.0),
        ] {
            let c = h.integrate(a, b);
            let (pa, pb) = (h.pressure_pa(a), h.pressure_pa(b));
            let want = column(pa, pb);
            assert!(
                (c.air_per_m2 / want - 1.0).abs() < 2e-4,
                "[{a}, {b}] m: {:e}",
                c.air_per_m2 / want - 1.0
            );
            per_dp.push((c.air_per_m2 - c.gas_per_m2[0]) / (pa - pb));
        }
        // The four quarters of the lowest interval: dry air per unit pressure changes with the
        // humidity only (x_w from 2.6e-2 to 1.95e-2: (1 − x_w)/(1 − 0.38 x_w) by 4e-3).
        for q in per_dp[..4].windows(2) {
            assert!(q[1] > q[0] && q[1] / q[0] - 1.0 < 2e-3, "{per_dp:?}");
        }
    }

    /// Each documented refusal, and its boundary: equal pressures are not decreasing.
    #[test]
    fn bad_levels_are_refused() {
        let t = [250.0; 3];
        let ok = hydrostatic_altitudes_m(&[1e5, 9e4, 8e4], &t, None, 0.0, 10.0);
        assert!(ok.is_ok());
        for (p, t, what) in [
            (&[1e5, 9e4, 9e4][..], &t[..], "decreasing"),
            (&[1e5, 9e4, 9.5e4][..], &t[..], "decreasing"),
            (&[1e5, 9e4, 0.0][..], &t[..], "positive"),
            (&[f64::INFINITY, 9e4, 8e4][..], &t[..], "decreasing"),
            (
                &[1e5, 9e4, 8e4][..],
                &[250.0, 0.0, 250.0][..],
                "temperature",
            ),
            (
                &[1e5, 9e4, 8e4][..],
                &[250.0, f64::NAN, 250.0][..],
                "temperature",
            ),
            (&[1e5, 9e4, 8e4][..], &t[..2], "equal lengths"),
            (&[1e5][..], &t[..1], "at least 2"),
        ] {
            let e = hydrostatic_altitudes_m(p, t, None, 0.0, 10.0)
                .unwrap_err()
                .to_string();
            assert!(e.contains(what), "{p:?} {t:?}: {e}");
        }
        let h = [0.01, 0.01];
        assert!(hydrostatic_altitudes_m(&[1e5, 9e4, 8e4], &t, Some(&h), 0.0, 0.0).is_err());
        for lat in [90.5, f64::NAN] {
            assert!(hydrostatic_altitudes_m(&[1e5, 9e4], &t[..2], None, 0.0, lat).is_err());
        }
        assert!(hydrostatic_altitudes_m(&[1e5, 9e4], &t[..2], None, f64::NAN, 0.0).is_err());
        assert!(hydrostatic_altitudes_m(&[1e5, 9e4], &t[..2], None, 0.0, -90.0).is_ok());
    }
}
