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

use super::AtmosphereError;
use super::humidity::virtual_temperature_k;
use crate::constants::{AVOGADRO_PER_MOL, BOLTZMANN_J_PER_K, MOLAR_MASS_DRY_AIR_KG_PER_MOL};

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
