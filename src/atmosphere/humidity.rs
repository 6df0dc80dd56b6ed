//! Water vapour: saturation vapour pressure and conversions between humidity units.
//!
//! lidarsim stores water vapour as a volume mixing ratio of moist air, x = e/p (e the partial
//! pressure of water vapour). Profile files may give specific humidity q (kg water per kg moist
//! air) or mixing ratios per dry air; the conversions here are exact for an ideal-gas mixture of
//! dry air (molar mass M_d) and water vapour (M_w), ε = M_w/M_d.

use crate::constants::{MOLAR_MASS_DRY_AIR_KG_PER_MOL, MOLAR_MASS_WATER_KG_PER_MOL};

/// Temperature of the triple point of water \[K\].
pub const TRIPLE_POINT_K: f64 = 273.16;

/// Which phase saturation refers to.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SaturationOver {
    /// Liquid water at every temperature (supercooled below 273.16 K). Capping relative
    /// humidity at 100 % over water still allows the ice supersaturation observed in cirrus
    /// regions (up to water saturation).
    Water,
    /// Liquid water at and above the triple point, ice below.
    IceBelowTriplePoint,
}

/// Saturation vapour pressure over plane liquid water \[Pa\] (Murphy and Koop 2005, Eq. 10).
///
/// `ln e_w = 54.842763 − 6763.22/T − 4.210 ln T + 0.000367 T +
/// tanh(0.0415 (T − 218.8)) (53.878 − 1331.22/T − 9.44523 ln T + 0.014025 T)`, T in K.
/// Valid 123 K < T < 332 K (the authors' stated range; within 0.05 % of IAPWS above 273 K);
/// evaluated as is outside it.
///
/// [^1]: D. M. Murphy and T. Koop (2005), Review of the vapour pressures of ice and supercooled
/// water for atmospheric applications, Q. J. R. Meteorol. Soc. 131, 1539–1565, Eq. (10),
/// doi:10.1256/qj.04.94.
pub fn saturation_vapour_pressure_water_pa(temperature_k: f64) -> f64 {
    let t = temperature_k;
    let ln_t = t.ln();
    (54.842763 - 6763.22 / t - 4.210 * ln_t
        + 0.000367 * t
        + (0.0415 * (t - 218.8)).tanh() * (53.878 - 1331.22 / t - 9.44523 * ln_t + 0.014025 * t))
        .exp()
}

/// Saturation vapour pressure over plane ice \[Pa\] (Murphy and Koop 2005, Eq. 7).
///
/// `ln e_i = 9.550426 − 5723.265/T + 3.53068 ln T − 0.00728332 T`, T in K, valid T > 110 K
/// (up to the triple point).
///
/// [^1]: Murphy and Koop (2005), Q. J. R. Meteorol. Soc. 131, 1539–1565, Eq. (7).
pub fn saturation_vapour_pressure_ice_pa(temperature_k: f64) -> f64 {
    let t = temperature_k;
    (9.550426 - 5723.265 / t + 3.53068 * t.ln() - 0.00728332 * t).exp()
}

/// Saturation vapour pressure \[Pa\] over the phase `over` selects.
pub fn saturation_vapour_pressure_pa(temperature_k: f64, over: SaturationOver) -> f64 {
    match over {
        SaturationOver::Water => saturation_vapour_pressure_water_pa(temperature_k),
        SaturationOver::IceBelowTriplePoint if temperature_k < TRIPLE_POINT_K => {
            saturation_vapour_pressure_ice_pa(temperature_k)
        }
        SaturationOver::IceBelowTriplePoint => saturation_vapour_pressure_water_pa(temperature_k),
    }
}

/// Relative humidity (fraction, 1 = saturation) of water vapour at volume mixing ratio
/// `h2o_vmr` (moist air), pressure `pressure_pa` and temperature `temperature_k`:
/// RH = x p / e_s(T) (WMO definition with e = x p; the enhancement factor, < 0.5 %, is neglected).
pub fn relative_humidity(
    h2o_vmr: f64,
    pressure_pa: f64,
    temperature_k: f64,
    over: SaturationOver,
) -> f64 {
    h2o_vmr * pressure_pa / saturation_vapour_pressure_pa(temperature_k, over)
}

/// ε = M_w / M_d (≈ 0.622).
pub fn epsilon() -> f64 {
    MOLAR_MASS_WATER_KG_PER_MOL / MOLAR_MASS_DRY_AIR_KG_PER_MOL
}

/// Volume mixing ratio of moist air from specific humidity q [kg/kg of moist air]:
/// x = (q/M_w) / (q/M_w + (1 − q)/M_d) = q / (q + ε (1 − q)).
pub fn vmr_from_specific_humidity(q: f64) -> f64 {
    q / (q + epsilon() * (1.0 - q))
}

/// Specific humidity [kg/kg of moist air] from the volume mixing ratio x of moist air:
/// q = ε x / (1 − x + ε x). Inverse of [`vmr_from_specific_humidity`].
pub fn specific_humidity_from_vmr(x: f64) -> f64 {
    let e = epsilon();
    e * x / (1.0 - x + e * x)
}

/// Volume mixing ratio of moist air from a mole ratio per dry air r (mol water / mol dry air):
/// x = r / (1 + r).
pub fn vmr_from_dry_mole_ratio(r: f64) -> f64 {
    r / (1.0 + r)
}

/// Molar mass of moist air [kg/mol] with water vapour volume mixing ratio x:
/// M = M_d (1 − x) + M_w x.
pub fn moist_air_molar_mass_kg_per_mol(h2o_vmr: f64) -> f64 {
    MOLAR_MASS_DRY_AIR_KG_PER_MOL * (1.0 - h2o_vmr) + MOLAR_MASS_WATER_KG_PER_MOL * h2o_vmr
}

/// Virtual temperature \[K\]: the temperature dry air would need to have the density of moist air
/// at the same pressure, T_v = T M_d / M(x).
pub fn virtual_temperature_k(temperature_k: f64, h2o_vmr: f64) -> f64 {
    temperature_k * MOLAR_MASS_DRY_AIR_KG_PER_MOL / moist_air_molar_mass_kg_per_mol(h2o_vmr)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// IAPWS-95 saturation pressure (Wagner and Pruss 2002, J. Phys. Chem. Ref. Data 31, 387,
    /// Table 13): 611.657 Pa at the triple point, 3536.81 Pa at 300 K, 12 351.8 Pa at 323.15 K.
    /// Murphy and Koop state agreement with IAPWS within 0.05 % in this range; tolerance 0.1 %.
    #[test]
    fn liquid_matches_iapws() {
        for (t, p) in [(273.16, 611.657), (300.0, 3536.81), (323.15, 12351.8)] {
            let e = saturation_vapour_pressure_water_pa(t);
            assert!((e / p - 1.0).abs() < 1e-3, "{t} K: {e} vs {p}");
        }
    }

    /// Ice at the triple point equals liquid (611.657 Pa, within 0.1 %); at 253.15 K the
    /// IAPWS-2011 sublimation pressure is 103.26 Pa (Wagner et al. 2011, J. Phys. Chem. Ref. Data
    /// 40, 043103, Table 3); below the triple point ice is lower than supercooled water.
    #[test]
    fn ice_matches_iapws_and_lies_below_water() {
        assert!((saturation_vapour_pressure_ice_pa(273.16) / 611.657 - 1.0).abs() < 1e-3);
        assert!((saturation_vapour_pressure_ice_pa(253.15) / 103.26 - 1.0).abs() < 2e-3);
        for t in [200.0, 230.0, 260.0, 273.0] {
            assert!(saturation_vapour_pressure_ice_pa(t) < saturation_vapour_pressure_water_pa(t));
        }
    }

    #[test]
    fn humidity_conversions_round_trip() {
        for x in [1e-6, 1e-3, 0.03] {
            let q = specific_humidity_from_vmr(x);
            assert!((vmr_from_specific_humidity(q) / x - 1.0).abs() < 1e-12);
        }
        // q = 0.01 kg/kg: x = 0.01/(0.01 + 0.622·0.99) ≈ 0.016 (textbook value, Wallace & Hobbs).
        let x = vmr_from_specific_humidity(0.01);
        assert!((x - 0.01597).abs() < 1e-4, "{x}");
    }
}
