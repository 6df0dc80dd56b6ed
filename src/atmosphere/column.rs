//! Column amounts of a [`Profile`] and rescaling of a gas to a target amount.
//!
//! Columns integrate number densities over altitude with the densities log-linear between
//! levels (exact for an isothermal layer with constant mixing ratio):
//! `∫ n dz = (n_k − n_{k+1}) Δz / ln(n_k/n_{k+1})` per layer, the trapezoid where the two
//! densities are equal or one is zero. This is the scheme of the AFGL column checks
//! (`../shared/data/afgl/afgl_column_checks.csv`).

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

/// ∫ n dz over one layer with n log-linear in z.
fn log_linear_layer(n0: f64, n1: f64, dz: f64) -> f64 {
    if n0 > 0.0 && n1 > 0.0 {
        let r = n0 / n1;
        if (r - 1.0).abs() > 1e-8 {
            return (n0 - n1) * dz / r.ln();
        }
    }
    0.5 * (n0 + n1) * dz
}

fn integrate(z: &[f64], n: &[f64]) -> f64 {
    (0..z.len().saturating_sub(1))
        .map(|k| log_linear_layer(n[k], n[k + 1], z[k + 1] - z[k]))
        .sum()
}

impl Profile {
    /// Total (moist) air column from the lowest to the highest level [molecules/m²],
    /// ∫ n dz with n = p/(kT) log-linear between levels.
    pub fn air_column_per_m2(&self) -> f64 {
        integrate(&self.altitude_m, &self.air_number_density_per_m3())
    }

    /// Dry-air column [molecules/m²]: ∫ (1 − x_H2O) n dz (the total column without H2O).
    pub fn dry_air_column_per_m2(&self) -> f64 {
        let n = self.air_number_density_per_m3();
        match self.gas("H2O") {
            Some(h) => {
                let nd: Vec<f64> = n.iter().zip(h).map(|(n, x)| n * (1.0 - x)).collect();
                integrate(&self.altitude_m, &nd)
            }
            None => integrate(&self.altitude_m, &n),
        }
    }

    /// Column of one gas [molecules/m²]: ∫ x n dz with the partial density x n log-linear.
    pub fn gas_column_per_m2(&self, gas: &str) -> Result<f64, AtmosphereError> {
        let x = self.require_gas(gas)?;
        let n: Vec<f64> = self
            .air_number_density_per_m3()
            .iter()
            .zip(x)
            .map(|(n, x)| n * x)
            .collect();
        Ok(integrate(&self.altitude_m, &n))
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

    /// An isothermal layer with constant mixing ratio: n is exactly exponential in z, so the
    /// log-linear rule is exact: ∫ n dz = n0 H (1 − e^{−Δz/H}).
    #[test]
    fn log_linear_rule_is_exact_for_exponential() {
        let (n0, h, dz): (f64, f64, f64) = (2.5e25, 8000.0, 3000.0);
        let n1 = n0 * (-dz / h).exp();
        let exact = n0 * h * (1.0 - (-dz / h).exp());
        assert!((log_linear_layer(n0, n1, dz) / exact - 1.0).abs() < 1e-12);
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
