//! Column amounts of a [`Profile`] and rescaling of a gas to a target amount.
//!
//! Columns integrate number densities over altitude between levels by the one hydrostatic
//! integration of [`super::hydrostatic::HydrostaticProfile`] (T linear in z, the pressure from
//! the hydrostatic equation, n = p/(kT), mixing ratios log-linear), the same that gives the
//! Curtis-Godson layers of the line-by-line stage and the weighting function's pressure
//! thickness. Exact for an isothermal layer with constant mixing ratio; within 1e-4 of the
//! log-linear rule of the AFGL column checks (`../shared/data/afgl/afgl_column_checks.csv`),
//! which it replaced.

use super::hydrostatic::HydrostaticProfile;
use super::{AtmosphereError, Profile};
use crate::constants::{AVOGADRO_PER_MOL, MOLAR_MASS_WATER_KG_PER_MOL};

/// How [`Profile::rescale_gas_with`] reads the target mixing ratio.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RescaleBasis {
    /// The dry-air column-averaged mixing ratio (X_gas = N_gas / N_dry air, the quantity an
    /// IPDA lidar or a TCCON/OCO-2 retrieval reports) becomes the target.
    DryColumnAverage,
    /// The value at the lowest level (the surface) becomes the target.
    Surface,
}

/// Columns of the whole profile, lowest to highest level.
fn whole(p: &Profile) -> super::hydrostatic::ColumnIntegrals {
    let z = &p.altitude_m;
    let (bottom, top) = (z.first().copied(), z.last().copied());
    match (bottom, top) {
        (Some(a), Some(b)) => HydrostaticProfile::new(p).integrate(a, b),
        _ => HydrostaticProfile::new(p).integrate(0.0, 0.0),
    }
}

impl Profile {
    /// Total (moist) air column from the lowest to the highest level [molecules/m²],
    /// ∫ n dz with n = p/(kT) between levels by the hydrostatic integration (module docs).
    pub fn air_column_per_m2(&self) -> f64 {
        whole(self).air_per_m2
    }

    /// Dry-air column [molecules/m²]: ∫ (1 − x_H2O) n dz (the total column without H2O).
    pub fn dry_air_column_per_m2(&self) -> f64 {
        let c = whole(self);
        match self.gases.iter().position(|g| g.name == "H2O") {
            Some(i) => c.air_per_m2 - c.gas_per_m2[i],
            None => c.air_per_m2,
        }
    }

    /// Column of one gas [molecules/m²]: ∫ x n dz.
    pub fn gas_column_per_m2(&self, gas: &str) -> Result<f64, AtmosphereError> {
        self.require_gas(gas)?;
        let i = self
            .gases
            .iter()
            .position(|g| g.name == gas)
            .unwrap_or_default();
        Ok(whole(self).gas_per_m2[i])
    }

    /// Precipitable water [kg/m², numerically equal to mm of liquid water]: the H2O column times
    /// M_w/N_A.
    pub fn precipitable_water_kg_per_m2(&self) -> Result<f64, AtmosphereError> {
        Ok(self.gas_column_per_m2("H2O")? * MOLAR_MASS_WATER_KG_PER_MOL / AVOGADRO_PER_MOL)
    }

    /// Dry-air column-averaged mixing ratio of a gas [mol/mol], X = N_gas / N_dry (for CO2 this
    /// is XCO2 as IPDA lidars and TCCON report it).
    pub fn column_average_dry_vmr(&self, gas: &str) -> Result<f64, AtmosphereError> {
        Ok(self.gas_column_per_m2(gas)? / self.dry_air_column_per_m2())
    }

    /// Scale a gas's mixing ratios by one factor so that its dry-air column-averaged mixing ratio
    /// becomes `target_vmr` (e.g. CO2 to 420e-6). Returns the factor applied.
    ///
    /// The shape of the profile is kept (for AFGL CO2: 330 ppmv to ~80 km, decreasing above).
    /// See [`Self::rescale_gas_with`] to scale to a surface value instead.
    pub fn rescale_gas(&mut self, gas: &str, target_vmr: f64) -> Result<f64, AtmosphereError> {
        self.rescale_gas_with(gas, target_vmr, RescaleBasis::DryColumnAverage)
    }

    /// Scale a gas's mixing ratios by one factor so that the quantity `basis` names equals
    /// `target_vmr` [mol/mol]. Returns the factor. Errors: the gas is absent, the target is not
    /// finite and positive, the current amount is zero, or a scaled value would exceed 1.
    ///
    /// Other gases are left as they are (their moist-air mixing ratios do not change when, e.g.,
    /// H2O is rescaled; the induced change of the dry-air fraction is below 1e-3 for CO2 work).
    pub fn rescale_gas_with(
        &mut self,
        gas: &str,
        target_vmr: f64,
        basis: RescaleBasis,
    ) -> Result<f64, AtmosphereError> {
        if !(target_vmr.is_finite() && target_vmr > 0.0 && target_vmr <= 1.0) {
            return Err(AtmosphereError::InvalidArgument(format!(
                "target mixing ratio {target_vmr} for `{gas}` is not in (0, 1]"
            )));
        }
        let current = match basis {
            RescaleBasis::DryColumnAverage => self.column_average_dry_vmr(gas)?,
            RescaleBasis::Surface => self.require_gas(gas)?[0],
        };
        if !(current > 0.0) {
            return Err(AtmosphereError::InvalidProfile {
                profile: self.name.clone(),
                message: format!("`{gas}` is zero; it cannot be rescaled by a factor"),
            });
        }
        let factor = target_vmr / current;
        let name = self.name.clone();
        let g = self
            .gases
            .iter_mut()
            .find(|g| g.name == gas)
            .expect("gas present (checked above)");
        if let Some(v) = g.vmr.iter().find(|v| **v * factor > 1.0) {
            return Err(AtmosphereError::InvalidProfile {
                profile: name,
                message: format!("rescaling `{gas}` by {factor} takes {v} above 1"),
            });
        }
        g.vmr.iter_mut().for_each(|v| *v *= factor);
        Ok(factor)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::atmosphere::StandardAtmosphere;

    /// An isothermal layer with constant mixing ratio in hydrostatic balance with normal
    /// gravity, p = p0 e^{−Γ(z)/H} (Γ = ∫ g/g(0) dz, the geopotential over surface gravity):
    /// the column against ∫ p/(kT) dz by Simpson's rule (20 000 intervals), to 1e-12; the gas
    /// column is x times it.
    #[test]
    fn isothermal_columns_are_exact() {
        use crate::atmosphere::hydrostatic::{
            geopotential_m2_per_s2, normal_gravity_surface_m_per_s2,
        };
        let (t, dz, h): (f64, f64, f64) = (250.0, 3000.0, 8000.0);
        let gamma_integral =
            |z: f64| geopotential_m2_per_s2(45.0, z) / normal_gravity_surface_m_per_s2(45.0);
        let pressure = |z: f64| 1e5 * (-gamma_integral(z) / h).exp();
        let p = Profile {
            name: "iso".into(),
            altitude_m: vec![0.0, dz],
            pressure_pa: vec![pressure(0.0), pressure(dz)],
            temperature_k: vec![t, t],
            gases: vec![crate::atmosphere::GasProfile {
                name: "CO2".into(),
                vmr: vec![4e-4, 4e-4],
            }],
        };
        let kt = crate::constants::BOLTZMANN_J_PER_K * t;
        let n = 20_000;
        let step = dz / n as f64;
        let exact: f64 = (0..=n)
            .map(|k| {
                let w = if k == 0 || k == n {
                    1.0
                } else if k % 2 == 1 {
                    4.0
                } else {
                    2.0
                };
                w * pressure(k as f64 * step) / kt
            })
            .sum::<f64>()
            * step
            / 3.0;
        assert!((p.air_column_per_m2() / exact - 1.0).abs() < 1e-12);
        assert!((p.gas_column_per_m2("CO2").unwrap() / (4e-4 * exact) - 1.0).abs() < 1e-12);
    }

    #[test]
    fn rescale_to_column_average_and_surface() {
        let mut p = StandardAtmosphere::UsStandard.profile();
        p.rescale_gas("CO2", 420e-6).unwrap();
        assert!((p.column_average_dry_vmr("CO2").unwrap() / 420e-6 - 1.0).abs() < 1e-12);
        p.rescale_gas_with("CO2", 410e-6, RescaleBasis::Surface)
            .unwrap();
        assert!((p.gas("CO2").unwrap()[0] - 410e-6).abs() < 1e-18);
        assert!(p.rescale_gas("XX", 1e-6).is_err());
        assert!(p.rescale_gas("CO2", -1.0).is_err());
    }
}
