//! Rayleigh (molecular) scattering of air after Bucholtz (1995).
//!
//! σ(λ) = 24π³ (n_s² − 1)² / (λ⁴ N_s² (n_s² + 2)²) · F_k,  F_k = (6 + 3ρ_n)/(6 − 7ρ_n)
//! (Bucholtz 1995, Appl. Opt. 34, 2765, Eqs. 2 and 3), with the refractive index of standard air
//! n_s from Peck & Reeder (1972, J. Opt. Soc. Am. 62, 958, Eq. 2) and the depolarisation factor
//! ρ_n interpolated linearly in Bucholtz's Table 1 (0.2–1.0 µm; held at its 1.0 µm value beyond,
//! an extrapolation at 1.57 µm of about 0.1 % in σ). The volume scattering coefficient is
//! σ · N(z) with N the air number density; the phase function is
//! [`RayleighPhase`](super::phase::RayleighPhase) with γ = ρ_n/(2 − ρ_n).

use thiserror::Error;

/// Number density of standard air (288.15 K, 1013.25 hPa) that goes with n_s [1/m³]
/// (Bucholtz 1995, after Eq. 2: N_s = 2.54743e19 cm⁻³).
pub const STANDARD_AIR_NUMBER_DENSITY_PER_M3: f64 = 2.547_43e25;

/// Bucholtz (1995) Table 1: wavelength \[µm\] and depolarisation factor ρ_n [%].
const DEPOLARISATION_TABLE: [(f64, f64); 36] = [
    (0.200, 4.545),
    (0.205, 4.384),
    (0.210, 4.221),
    (0.215, 4.113),
    (0.220, 4.004),
    (0.225, 3.895),
    (0.230, 3.785),
    (0.240, 3.675),
    (0.250, 3.565),
    (0.260, 3.455),
    (0.270, 3.400),
    (0.280, 3.289),
    (0.290, 3.233),
    (0.300, 3.178),
    (0.310, 3.178),
    (0.320, 3.122),
    (0.330, 3.066),
    (0.340, 3.066),
    (0.350, 3.010),
    (0.360, 3.010),
    (0.370, 3.010),
    (0.380, 2.955),
    (0.390, 2.955),
    (0.400, 2.955),
    (0.450, 2.899),
    (0.500, 2.842),
    (0.550, 2.842),
    (0.600, 2.786),
    (0.650, 2.786),
    (0.700, 2.786),
    (0.750, 2.786),
    (0.800, 2.730),
    (0.850, 2.730),
    (0.900, 2.730),
    (0.950, 2.730),
    (1.000, 2.730),
];

/// A wavelength outside the range the formulas cover.
#[derive(Debug, Clone, PartialEq, Error)]
#[error(
    "Rayleigh scattering: wavelength {0} nm is outside {1}–2000 nm (Peck & Reeder's formula: from 230 nm; Bucholtz's table: from 200 nm)"
)]
pub struct RayleighError(pub f64, pub f64);

/// Wavelength in µm, if inside [min_nm, 2000 nm]. Peck & Reeder measured 230–1690 nm; their
/// dispersion formula is smooth and is used to 2000 nm (it covers the 1.57 µm CO2 band).
fn check(wavelength_nm: f64, min_nm: f64) -> Result<f64, RayleighError> {
    if (min_nm..=2000.0).contains(&wavelength_nm) {
        Ok(wavelength_nm * 1e-3)
    } else {
        Err(RayleighError(wavelength_nm, min_nm))
    }
}

/// n_s − 1 of standard air (15 °C, 101325 Pa, 300 ppm CO2), Peck & Reeder (1972), Eq. 2:
/// 10⁸ (n_s − 1) = 8060.51 + 2480990/(132.274 − ν²) + 17455.7/(39.32957 − ν²), ν = 1/λ\[µm\].
pub fn refractivity_standard_air(wavelength_nm: f64) -> Result<f64, RayleighError> {
    let lam_um = check(wavelength_nm, 230.0)?;
    let nu2 = 1.0 / (lam_um * lam_um);
    Ok((8060.51 + 2_480_990.0 / (132.274 - nu2) + 17_455.7 / (39.32957 - nu2)) * 1e-8)
}

/// Depolarisation factor ρ_n of air (Bucholtz 1995, Table 1), as a fraction.
pub fn depolarisation_factor(wavelength_nm: f64) -> Result<f64, RayleighError> {
    let lam_um = check(wavelength_nm, 200.0)?;
    let t = &DEPOLARISATION_TABLE;
    let percent = if lam_um <= t[0].0 {
        t[0].1
    } else if lam_um >= t[t.len() - 1].0 {
        t[t.len() - 1].1
    } else {
        let i = t.partition_point(|(l, _)| *l <= lam_um) - 1;
        let (l0, r0) = t[i];
        let (l1, r1) = t[i + 1];
        r0 + (r1 - r0) * (lam_um - l0) / (l1 - l0)
    };
    Ok(percent * 1e-2)
}

/// Total Rayleigh scattering cross-section per molecule of air \[m²\] (Bucholtz 1995, Eq. 2).
pub fn cross_section_m2(wavelength_nm: f64) -> Result<f64, RayleighError> {
    let lam_m = check(wavelength_nm, 230.0)? * 1e-6;
    let n = 1.0 + refractivity_standard_air(wavelength_nm)?;
    let rho = depolarisation_factor(wavelength_nm)?;
    let king = (6.0 + 3.0 * rho) / (6.0 - 7.0 * rho);
    let n2 = n * n;
    let ns = STANDARD_AIR_NUMBER_DENSITY_PER_M3;
    let pi3 = std::f64::consts::PI.powi(3);
    Ok(24.0 * pi3 * (n2 - 1.0).powi(2) / (lam_m.powi(4) * ns * ns * (n2 + 2.0).powi(2)) * king)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// λ \[nm\], n_s − 1, ρ_n, σ [cm²] from shared/data/rayleigh/rayleigh_bucholtz.csv: the same
    /// formulas evaluated independently (Python), so agreement checks the transcription.
    const REFERENCE: [(f64, f64, f64, f64); 4] = [
        (355.0, 0.000285698, 0.0301, 2.75515e-26),
        (532.0, 0.000278195, 0.02842, 5.16483e-27),
        (1064.0, 0.000273971, 0.0273, 3.12479e-28),
        (1572.0, 0.000273229, 0.0273, 6.52263e-29),
    ];

    #[test]
    fn matches_independent_bucholtz_values() {
        for (lam, nm1, rho, sigma_cm2) in REFERENCE {
            assert!(
                (refractivity_standard_air(lam).unwrap() / nm1 - 1.0).abs() < 5e-6,
                "{lam}"
            );
            assert!(
                (depolarisation_factor(lam).unwrap() - rho).abs() < 1e-12,
                "{lam}"
            );
            let s = cross_section_m2(lam).unwrap() * 1e4;
            assert!(
                (s / sigma_cm2 - 1.0).abs() < 2e-5,
                "{lam}: {s} vs {sigma_cm2}"
            );
        }
    }

    #[test]
    fn bucholtz_fit_agrees_at_550nm() {
        // Bucholtz (1995) Eq. 8 fit, 0.5–1 µm: σ = A λ^−(B + Cλ + D/λ) with A = 4.01e-28 cm²,
        // B = 3.99, C = 1.1e-3, D = 2.71e-2 (λ in µm); the fit is good to about 0.3 %.
        let l: f64 = 0.55;
        let fit = 4.01e-28 * l.powf(-(3.99 + 1.1e-3 * l + 2.71e-2 / l));
        let s = cross_section_m2(550.0).unwrap() * 1e4;
        assert!((s / fit - 1.0).abs() < 5e-3, "{s} vs {fit}");
    }

    #[test]
    fn depolarisation_interpolates_table() {
        assert!((depolarisation_factor(225.0).unwrap() - 0.03895).abs() < 1e-12);
        assert!((depolarisation_factor(425.0).unwrap() - 0.02927).abs() < 1e-12);
        assert!(depolarisation_factor(100.0).is_err());
        assert!(cross_section_m2(2500.0).is_err());
    }
}
