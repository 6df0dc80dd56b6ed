//! Atmospheric state: profiles of pressure, temperature and gas mixing ratios on levels.
//!
//! Consumes built-in AFGL standard atmospheres (Anderson et al. 1986, AFGL-TR-86-0110), profile
//! files and perturbed ensembles; produces [`Profile`]s, the input of Rayleigh scattering and
//! line-by-line gas absorption.

use std::str::FromStr;

use crate::constants::BOLTZMANN_J_PER_K;
use crate::input::{CsvTable, InputError};

/// One atmospheric column on levels ordered bottom to top.
///
/// All per-level vectors have the same length. Mixing ratios are volume mixing ratios
/// (mol/mol) of moist air.
#[derive(Debug, Clone, PartialEq)]
pub struct Profile {
    /// A name for messages and output (e.g. `afgl us_standard`, `ecmwf83 #12`).
    pub name: String,
    /// Geometric altitude of each level [m], strictly increasing.
    pub altitude_m: Vec<f64>,
    /// Pressure [Pa], strictly decreasing.
    pub pressure_pa: Vec<f64>,
    /// Temperature [K].
    pub temperature_k: Vec<f64>,
    /// Gases and their volume mixing ratios per level.
    pub gases: Vec<GasProfile>,
}

/// The volume mixing ratio profile of one gas.
#[derive(Debug, Clone, PartialEq)]
pub struct GasProfile {
    /// Chemical formula as HITRAN writes it: `H2O`, `CO2`, `O3`, `N2O`, `CO`, `CH4`, `O2`.
    pub name: String,
    /// Volume mixing ratio [mol/mol] per level.
    pub vmr: Vec<f64>,
}

impl Profile {
    /// Number of levels.
    pub fn len(&self) -> usize {
        self.altitude_m.len()
    }

    /// True for a profile without levels.
    pub fn is_empty(&self) -> bool {
        self.altitude_m.is_empty()
    }

    /// Total (moist) air number density at each level, n = p/(k T) [1/m³].
    pub fn air_number_density_per_m3(&self) -> Vec<f64> {
        self.pressure_pa
            .iter()
            .zip(&self.temperature_k)
            .map(|(p, t)| p / (BOLTZMANN_J_PER_K * t))
            .collect()
    }

    /// The mixing-ratio profile of a gas, if the profile carries it.
    pub fn gas(&self, name: &str) -> Option<&[f64]> {
        self.gases
            .iter()
            .find(|g| g.name == name)
            .map(|g| g.vmr.as_slice())
    }
}

/// The six AFGL standard atmospheres (Anderson et al. 1986).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StandardAtmosphere {
    /// Tropical (15° N, annual).
    Tropical,
    /// Mid-latitude summer (45° N, July).
    MidlatitudeSummer,
    /// Mid-latitude winter (45° N, January).
    MidlatitudeWinter,
    /// Sub-arctic summer (60° N, July).
    SubarcticSummer,
    /// Sub-arctic winter (60° N, January).
    SubarcticWinter,
    /// US Standard 1976, with the USSA-76 p and T at 32.5 and 37.5 km.
    UsStandard,
}

impl StandardAtmosphere {
    /// All six, in the report's order.
    pub const ALL: [StandardAtmosphere; 6] = [
        Self::Tropical,
        Self::MidlatitudeSummer,
        Self::MidlatitudeWinter,
        Self::SubarcticSummer,
        Self::SubarcticWinter,
        Self::UsStandard,
    ];

    /// The name used in scenes and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Self::Tropical => "tropical",
            Self::MidlatitudeSummer => "midlatitude_summer",
            Self::MidlatitudeWinter => "midlatitude_winter",
            Self::SubarcticSummer => "subarctic_summer",
            Self::SubarcticWinter => "subarctic_winter",
            Self::UsStandard => "us_standard",
        }
    }

    fn embedded_csv(self) -> &'static str {
        match self {
            Self::Tropical => include_str!("../../data/afgl/afgl_tropical.csv"),
            Self::MidlatitudeSummer => include_str!("../../data/afgl/afgl_midlatitude_summer.csv"),
            Self::MidlatitudeWinter => include_str!("../../data/afgl/afgl_midlatitude_winter.csv"),
            Self::SubarcticSummer => include_str!("../../data/afgl/afgl_subarctic_summer.csv"),
            Self::SubarcticWinter => include_str!("../../data/afgl/afgl_subarctic_winter.csv"),
            Self::UsStandard => include_str!("../../data/afgl/afgl_us_standard_ussa76fix.csv"),
        }
    }

    /// The atmosphere as a [`Profile`] (AFGL 1986 values: CO2 330 ppmv; rescale as needed).
    pub fn profile(self) -> Profile {
        let path = format!("<embedded AFGL {}>", self.name());
        // The embedded tables are part of the build and are checked by tests.
        parse_afgl(&path, self.embedded_csv()).expect("embedded AFGL table parses")
    }
}

impl FromStr for StandardAtmosphere {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        Self::ALL
            .iter()
            .copied()
            .find(|a| a.name() == s)
            .ok_or_else(|| {
                let names: Vec<_> = Self::ALL.iter().map(|a| a.name()).collect();
                format!(
                    "unknown standard atmosphere `{s}` (known: {})",
                    names.join(", ")
                )
            })
    }
}

/// Parse an AFGL table as shipped in `data/afgl/` (z_km, p_hPa, T_K, n_air, gases in ppmv).
pub fn parse_afgl(path: &str, text: &str) -> Result<Profile, InputError> {
    let t = CsvTable::parse(path, text)?;
    let altitude_m = t.f64_column("z_km")?.iter().map(|z| z * 1e3).collect();
    let pressure_pa = t.f64_column("p_hPa")?.iter().map(|p| p * 100.0).collect();
    let temperature_k = t.f64_column("T_K")?;
    let mut gases = Vec::new();
    for h in t.header() {
        if let Some(name) = h.strip_suffix("_ppmv") {
            let vmr = t.f64_column(h)?.iter().map(|v| v * 1e-6).collect();
            gases.push(GasProfile {
                name: name.to_string(),
                vmr,
            });
        }
    }
    Ok(Profile {
        name: format!("afgl {path}"),
        altitude_m,
        pressure_pa,
        temperature_k,
        gases,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn all_standard_atmospheres_load_with_consistent_levels() {
        for a in StandardAtmosphere::ALL {
            let p = a.profile();
            assert_eq!(p.len(), 50, "{}", a.name());
            assert!(p.altitude_m.windows(2).all(|w| w[1] > w[0]));
            assert!(p.pressure_pa.windows(2).all(|w| w[1] < w[0]));
            assert!(p.gas("CO2").is_some() && p.gas("H2O").is_some());
        }
    }
}
