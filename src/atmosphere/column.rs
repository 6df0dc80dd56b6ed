//! Column amounts of a [`Profile`], rescaling of a gas to a target amount, and CO2 given as
//! a well-mixed dry-air mole fraction ([`Co2Scaling`]).
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

/// How a CO2 amount in ppm (`[atmosphere] co2_ppm`, `--co2-ppm`) is given to a profile
/// (`co2_scaling`, `--co2-scaling`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Co2Scaling {
    /// `well_mixed` (the default): CO2 is `ppm` of dry air at every level, the profile's own
    /// CO2 replaced (or added where it has none): x_CO2 = ppm·10⁻⁶·(1 − x_H2O) of moist air.
    /// The dry-air mole fraction is then the value at every level and between levels (the
    /// hydrostatic integration interpolates other gases in dry air), so XCO2 over any range is
    /// the value exactly: what a user setting "420 ppm" expects.
    #[default]
    WellMixed,
    /// `profile_shape`: the profile's own CO2 multiplied by one factor so that its dry-air
    /// column average is `ppm` ([`Profile::rescale_gas`]). With the AFGL tables (a constant
    /// moist-air mixing ratio) the dry-air mole fraction then rises toward a humid surface (408
    /// ppm at the tropical surface for 400 ppm). Needs CO2 in the profile.
    ProfileShape,
}

impl Co2Scaling {
    /// Every choice, in the order messages list them.
    pub const ALL: [Co2Scaling; 2] = [Co2Scaling::WellMixed, Co2Scaling::ProfileShape];

    /// The name a scene or the command line gives.
    pub fn name(self) -> &'static str {
        match self {
            Co2Scaling::WellMixed => "well_mixed",
            Co2Scaling::ProfileShape => "profile_shape",
        }
    }

    /// What it does, for run summaries and file attributes.
    pub fn describe(self, ppm: f64) -> String {
        match self {
            Co2Scaling::WellMixed => {
                format!(
                    "CO2 well mixed at {ppm} ppm of dry air at every level (co2_scaling = well_mixed)"
                )
            }
            Co2Scaling::ProfileShape => format!(
                "CO2 profile shape rescaled to a dry-air column average of {ppm} ppm (co2_scaling = profile_shape)"
            ),
        }
    }
}

impl std::fmt::Display for Co2Scaling {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for Co2Scaling {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        let norm = s.replace('-', "_");
        Co2Scaling::ALL
            .into_iter()
            .find(|c| c.name() == norm)
            .ok_or_else(|| {
                let known: Vec<&str> = Co2Scaling::ALL.iter().map(|c| c.name()).collect();
                format!("`{s}` is not a CO2 scaling (known: {})", known.join(", "))
            })
    }
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

    /// Set a gas to the dry-air mole fraction `x_dry` [mol/mol] at every level (added if the
    /// profile has none): its moist-air mixing ratio becomes x_dry·(1 − x_H2O). Errors: `x_dry`
    /// not in (0, 1).
    pub fn set_dry_mole_fraction(&mut self, gas: &str, x_dry: f64) -> Result<(), AtmosphereError> {
        if !(x_dry.is_finite() && x_dry > 0.0 && x_dry < 1.0) {
            return Err(AtmosphereError::InvalidArgument(format!(
                "dry-air mole fraction {x_dry} for `{gas}` is not in (0, 1)"
            )));
        }
        let h2o = self.gas("H2O").map(|v| v.to_vec());
        let vmr = (0..self.len())
            .map(|k| x_dry * (1.0 - h2o.as_ref().map_or(0.0, |h| h[k])))
            .collect();
        self.set_gas(gas, vmr)
    }

    /// Give the profile `ppm` of CO2 the way `scaling` says ([`Co2Scaling`]). Errors: `ppm` not
    /// in (0, 10⁶), or (`profile_shape`) a profile without CO2.
    pub fn set_co2_ppm(&mut self, ppm: f64, scaling: Co2Scaling) -> Result<(), AtmosphereError> {
        if !(ppm.is_finite() && ppm > 0.0 && ppm < 1e6) {
            return Err(AtmosphereError::InvalidArgument(format!(
                "CO2 {ppm} ppm must be positive and below 1e6"
            )));
        }
        match scaling {
            Co2Scaling::WellMixed => self.set_dry_mole_fraction("CO2", ppm * 1e-6),
            Co2Scaling::ProfileShape => self.rescale_gas("CO2", ppm * 1e-6).map(|_| ()),
        }
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

    /// A well-mixed 420 ppm in the humid tropical atmosphere: the dry-air mole fraction
    /// x_CO2/(1 − x_H2O) is 420 ppm at every level, and the column average N_CO2/N_dry is 420
    /// ppm to 1e-9 over the whole profile and over ranges that cut level intervals (by
    /// definition, whatever the quadrature, since the integrand ratio is 420 ppm everywhere).
    #[test]
    fn well_mixed_co2_is_the_dry_mole_fraction_everywhere() {
        use super::super::hydrostatic::HydrostaticProfile;
        let mut p = StandardAtmosphere::Tropical.profile();
        p.set_co2_ppm(420.0, Co2Scaling::WellMixed).unwrap();
        let (co2, h2o) = (p.gas("CO2").unwrap(), p.gas("H2O").unwrap());
        for (c, h) in co2.iter().zip(h2o) {
            assert!((c / (1.0 - h) / 420e-6 - 1.0).abs() < 1e-12);
        }
        let x = p.column_average_dry_vmr("CO2").unwrap();
        assert!((x / 420e-6 - 1.0).abs() < 1e-9, "{}", x * 1e6);
        let k = p.gases.iter().position(|g| g.name == "CO2").unwrap();
        let w = p.gases.iter().position(|g| g.name == "H2O").unwrap();
        for (za, zb) in [(0.0, 1234.5), (333.0, 8765.0), (2500.0, 60_000.0)] {
            let c = HydrostaticProfile::new(&p).integrate(za, zb);
            let dry = c.air_per_m2 - c.gas_per_m2[w];
            assert!((c.gas_per_m2[k] / dry / 420e-6 - 1.0).abs() < 1e-9);
        }
        // A profile without CO2 gets it; a bad value is refused.
        p.gases.retain(|g| g.name != "CO2");
        p.set_co2_ppm(400.0, Co2Scaling::WellMixed).unwrap();
        assert!((p.column_average_dry_vmr("CO2").unwrap() / 400e-6 - 1.0).abs() < 1e-9);
        assert!(p.set_co2_ppm(f64::NAN, Co2Scaling::WellMixed).is_err());
        assert!(p.set_co2_ppm(0.0, Co2Scaling::ProfileShape).is_err());
    }

    /// The profile-shape rescaling of the AFGL tropical CO2 (330 ppmv of moist air at every
    /// level) to a 400 ppm column average: the column average is 400 ppm, and the surface's
    /// dry-air mole fraction is 330·f/(1 − x_H2O(0)) with f = 400/XCO2 — 408 ppm (issue 42).
    #[test]
    fn profile_shape_keeps_the_moist_shape() {
        let mut p = StandardAtmosphere::Tropical.profile();
        let x0 = p.column_average_dry_vmr("CO2").unwrap();
        p.set_co2_ppm(400.0, Co2Scaling::ProfileShape).unwrap();
        assert!((p.column_average_dry_vmr("CO2").unwrap() / 400e-6 - 1.0).abs() < 1e-12);
        let surface_dry = p.gas("CO2").unwrap()[0] / (1.0 - p.gas("H2O").unwrap()[0]);
        let expected = 330e-6 * (400e-6 / x0) / (1.0 - 2.593e-2);
        assert!((surface_dry / expected - 1.0).abs() < 1e-3);
        assert!(
            (surface_dry * 1e6 - 408.0).abs() < 0.5,
            "{}",
            surface_dry * 1e6
        );
        p.gases.retain(|g| g.name != "CO2");
        assert!(p.set_co2_ppm(400.0, Co2Scaling::ProfileShape).is_err());
        assert_eq!(
            "well-mixed".parse::<Co2Scaling>(),
            Ok(Co2Scaling::WellMixed)
        );
        assert!(
            "column"
                .parse::<Co2Scaling>()
                .unwrap_err()
                .contains("well_mixed, profile_shape")
        );
    }
}
