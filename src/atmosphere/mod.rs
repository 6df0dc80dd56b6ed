//! Atmospheric state: profiles of pressure, temperature and gas mixing ratios on levels.
//!
//! Consumes built-in AFGL standard atmospheres (Anderson et al. 1986, AFGL-TR-86-0110), profile
//! files and perturbed ensembles; produces [`Profile`]s, the input of Rayleigh scattering and
//! line-by-line gas absorption.
//!
//! | what | where |
//! |---|---|
//! | one column on levels, columns, rescaling, interpolation | [`Profile`] (this file, [`column`](mod@column), [`interp`]) |
//! | hydrostatic altitudes, normal gravity | [`hydrostatic`] |
//! | saturation vapour pressure, humidity units | [`humidity`] |
//! | profile sets (the lidarsim long-table format), latitude classes, class means | [`set`] |
//! | readers for the ECMWF 83 / ECMWF 52 / RFMIP files as distributed | [`native`] |
//! | covariances (file, per-level error model, forecast − analysis pairs) | [`covariance`] |
//! | perturbed ensembles `x = x̄ + L z` | [`ensemble`] |
//!
//! Conventions: levels bottom to top; altitude strictly increasing, pressure strictly decreasing;
//! gas amounts are volume mixing ratios of moist air (mol/mol); SI units unless a name says
//! otherwise. The method and its citations are in `docs/atmosphere.md`.

// `!(x > 0.0)` is the NaN-rejecting form of a range check; keep it.
#![allow(clippy::neg_cmp_op_on_partial_ord)]
// Level loops index several parallel per-level vectors at once.
#![allow(clippy::needless_range_loop)]

use std::str::FromStr;

use crate::constants::BOLTZMANN_J_PER_K;
use crate::input::{Bounds, CsvTable, InputError};

/// Temperatures a profile may hold \[K\]: below the coldest mesopause (about 100 K) up to the
/// end of the embedded TIPS-2021 partition sums (1000 K), which also covers the thermosphere
/// to about 200 km. A file beyond is refused where the value stands.
pub const TEMPERATURE_K: Bounds = Bounds::closed(50.0, 1000.0);
/// Pressures a profile may hold \[Pa\]: above 0 and at most 1200 hPa (the highest surface
/// pressures on Earth are near 1085 hPa).
pub const PRESSURE_PA: Bounds = Bounds::positive(1.2e5);
/// Altitudes of profile levels \[m\].
pub const ALTITUDE_M: Bounds = Bounds::closed(-1e4, 1e6);

pub mod column;
pub mod covariance;
pub mod ensemble;
pub mod humidity;
pub mod hydrostatic;
pub mod interp;
pub mod native;
pub mod set;

pub use column::{Co2Scaling, RescaleBasis};
pub use covariance::{Covariance, ErrorModel, Factor, RepairReport, StateVariable};
pub use ensemble::{
    EnsembleConfig, EnsembleReport, StateShift, class_ensemble, generate_ensemble, shift_member,
};
pub use humidity::SaturationOver;
pub use set::{LatitudeClass, ProfileMeta, ProfileSet, SetMember, read_profile_set};

/// Errors of the atmosphere stage (bad profiles, missing gases, covariances that cannot be used).
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum AtmosphereError {
    /// A problem in an input file (file, line, field).
    #[error(transparent)]
    Input(#[from] InputError),
    /// A profile that breaks an invariant (levels, ordering, physical range).
    #[error("profile `{profile}`: {message}")]
    InvalidProfile {
        /// The profile's name.
        profile: String,
        /// What is wrong.
        message: String,
    },
    /// A gas asked for by name is not in the profile.
    #[error("profile `{profile}` has no gas `{gas}` (it has: {available})")]
    MissingGas {
        /// The profile's name.
        profile: String,
        /// The gas asked for.
        gas: String,
        /// The gases the profile carries, comma-separated.
        available: String,
    },
    /// A requested coordinate lies outside the profile (no extrapolation is done).
    #[error(
        "profile `{profile}`: requested {coordinate} {value} is outside the profile ({min} to {max}); \
         lidarsim does not extrapolate"
    )]
    OutOfRange {
        /// The profile's name.
        profile: String,
        /// `altitude_m` or `pressure_pa`.
        coordinate: &'static str,
        /// The offending value.
        value: f64,
        /// The profile's lower bound of that coordinate.
        min: f64,
        /// The profile's upper bound.
        max: f64,
    },
    /// An argument that is not a valid value (non-finite, negative, empty grid, ...).
    #[error("{0}")]
    InvalidArgument(String),
    /// An empty profile set where members are needed.
    #[error("profile set `{0}` has no profiles")]
    EmptySet(String),
    /// A covariance matrix that is not positive semi-definite beyond rounding.
    #[error(
        "the covariance is not positive semi-definite: {negative} of {dimension} eigenvalues are \
         negative, the smallest is {min_eigenvalue:.3e} (largest {max_eigenvalue:.3e}); fix the \
         covariance or allow repair (nearest positive semi-definite matrix, Higham 1988)"
    )]
    NotPositiveDefinite {
        /// Number of negative eigenvalues beyond the rounding threshold.
        negative: usize,
        /// Dimension of the (active part of the) matrix.
        dimension: usize,
        /// The most negative eigenvalue.
        min_eigenvalue: f64,
        /// The largest eigenvalue.
        max_eigenvalue: f64,
    },
    /// A covariance that does not fit the profile or the other inputs.
    #[error("covariance: {0}")]
    Covariance(String),
    /// An output file could not be written.
    #[error(transparent)]
    Write(#[from] crate::output::OutputError),
}

/// One atmospheric column on levels ordered bottom to top.
///
/// All per-level vectors have the same length. Mixing ratios are volume mixing ratios
/// (mol/mol) of moist air.
#[derive(Debug, Clone, PartialEq)]
pub struct Profile {
    /// A name for messages and output (e.g. `afgl us_standard`, `ecmwf83 #12`).
    pub name: String,
    /// Geometric altitude of each level \[m\], strictly increasing.
    pub altitude_m: Vec<f64>,
    /// Pressure \[Pa\], strictly decreasing.
    pub pressure_pa: Vec<f64>,
    /// Temperature \[K\].
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

    /// The mixing-ratio profile of a gas, or [`AtmosphereError::MissingGas`].
    pub fn require_gas(&self, name: &str) -> Result<&[f64], AtmosphereError> {
        self.gas(name).ok_or_else(|| AtmosphereError::MissingGas {
            profile: self.name.clone(),
            gas: name.to_string(),
            available: self.gas_names().join(", "),
        })
    }

    /// Names of the gases carried, in order.
    pub fn gas_names(&self) -> Vec<&str> {
        self.gases.iter().map(|g| g.name.as_str()).collect()
    }

    /// Pressure at the lowest level (the surface) \[Pa\].
    pub fn surface_pressure_pa(&self) -> f64 {
        self.pressure_pa.first().copied().unwrap_or(f64::NAN)
    }

    /// Set (add or replace) a gas's volume mixing ratio profile [mol/mol].
    ///
    /// The vector must have one finite value in [0, 1] per level.
    pub fn set_gas(&mut self, name: &str, vmr: Vec<f64>) -> Result<(), AtmosphereError> {
        if vmr.len() != self.len() {
            return Err(AtmosphereError::InvalidArgument(format!(
                "gas `{name}` has {} values, profile `{}` has {} levels",
                vmr.len(),
                self.name,
                self.len()
            )));
        }
        if let Some(v) = vmr
            .iter()
            .find(|v| !(v.is_finite() && (0.0..=1.0).contains(*v)))
        {
            return Err(AtmosphereError::InvalidArgument(format!(
                "gas `{name}`: volume mixing ratio {v} is not in [0, 1]"
            )));
        }
        match self.gases.iter_mut().find(|g| g.name == name) {
            Some(g) => g.vmr = vmr,
            None => self.gases.push(GasProfile {
                name: name.to_string(),
                vmr,
            }),
        }
        Ok(())
    }

    /// Check the invariants every profile handed out must hold: at least two levels, equal
    /// lengths, finite values, altitude strictly increasing, pressure strictly decreasing and
    /// positive, temperature positive, mixing ratios in [0, 1].
    pub fn validate(&self) -> Result<(), AtmosphereError> {
        let bad = |message: String| AtmosphereError::InvalidProfile {
            profile: self.name.clone(),
            message,
        };
        let n = self.len();
        if n < 2 {
            return Err(bad(format!("has {n} levels, at least 2 are needed")));
        }
        if self.pressure_pa.len() != n || self.temperature_k.len() != n {
            return Err(bad(format!(
                "level vectors differ in length (altitude {n}, pressure {}, temperature {})",
                self.pressure_pa.len(),
                self.temperature_k.len()
            )));
        }
        for (k, w) in self.altitude_m.windows(2).enumerate() {
            if !(w[1] > w[0]) || !w[0].is_finite() || !w[1].is_finite() {
                return Err(bad(format!(
                    "altitude is not strictly increasing at levels {k}–{} ({} m, {} m)",
                    k + 1,
                    w[0],
                    w[1]
                )));
            }
        }
        for (k, w) in self.pressure_pa.windows(2).enumerate() {
            if !(w[1] < w[0]) || !(w[1] > 0.0) || !w[0].is_finite() {
                return Err(bad(format!(
                    "pressure is not strictly decreasing and positive at levels {k}–{} ({} Pa, {} Pa)",
                    k + 1,
                    w[0],
                    w[1]
                )));
            }
        }
        if let Some((k, t)) = self
            .temperature_k
            .iter()
            .enumerate()
            .find(|(_, t)| !TEMPERATURE_K.contains(**t))
        {
            return Err(bad(format!(
                "temperature {t} K at level {k} is outside {TEMPERATURE_K} K"
            )));
        }
        for g in &self.gases {
            if g.vmr.len() != n {
                return Err(bad(format!(
                    "gas `{}` has {} values for {n} levels",
                    g.name,
                    g.vmr.len()
                )));
            }
            if let Some((k, v)) = g
                .vmr
                .iter()
                .enumerate()
                .find(|(_, v)| !(v.is_finite() && (0.0..=1.0).contains(*v)))
            {
                return Err(bad(format!(
                    "gas `{}` volume mixing ratio {v} at level {k} is not in [0, 1]",
                    g.name
                )));
            }
        }
        Ok(())
    }
}

/// Molar mass [kg/mol] of the gases lidarsim knows by HITRAN formula (main isotopologue
/// abundance-weighted values, IUPAC 2013 atomic weights).
pub fn molar_mass_kg_per_mol(gas: &str) -> Option<f64> {
    Some(match gas {
        "H2O" => crate::constants::MOLAR_MASS_WATER_KG_PER_MOL,
        "CO2" => 0.044_009_5,
        "O3" => 0.047_998_2,
        "N2O" => 0.044_012_8,
        "CO" => 0.028_010_1,
        "CH4" => 0.016_042_5,
        "O2" => 0.031_998_8,
        "N2" => 0.028_013_4,
        _ => return None,
    })
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
        crate::input::names::STANDARD_ATMOSPHERES[self as usize]
    }

    /// The latitude the atmosphere represents [°N] (Anderson et al. 1986, Table 1): 15, 45, 60;
    /// 45 for the US standard.
    pub fn latitude_deg(self) -> f64 {
        match self {
            Self::Tropical => 15.0,
            Self::MidlatitudeSummer | Self::MidlatitudeWinter | Self::UsStandard => 45.0,
            Self::SubarcticSummer | Self::SubarcticWinter => 60.0,
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

    /// The atmosphere as a [`Profile`] (AFGL 1986 values: CO2 330 ppmv; rescale as needed with
    /// [`Profile::rescale_gas`]). 50 levels, 0–120 km, altitudes as tabulated.
    pub fn profile(self) -> Profile {
        let path = format!("<embedded AFGL {}>", self.name());
        // The embedded tables are part of the build and are checked by tests.
        let mut p = parse_afgl(&path, self.embedded_csv()).expect("embedded AFGL table parses");
        p.name = format!("afgl {}", self.name());
        p
    }

    /// The atmosphere as a one-member [`SetMember`] placed at its nominal latitude
    /// ([`Self::latitude_deg`]), longitude 0, time unknown.
    pub fn member(self) -> SetMember {
        SetMember {
            meta: ProfileMeta {
                id: self.name().to_string(),
                latitude_deg: self.latitude_deg(),
                longitude_deg: 0.0,
                time_utc: String::new(),
                weight: None,
            },
            profile: self.profile(),
        }
    }
}

impl FromStr for StandardAtmosphere {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        crate::input::names::standard_atmosphere(s).map(|i| Self::ALL[i])
    }
}

/// Parse an AFGL table as shipped in `data/afgl/` (z_km, p_hPa, T_K, n_air, gases in ppmv).
///
/// The tabulated `n_air_cm-3` column is not used: number densities are always p/(kT).
pub fn parse_afgl(path: &str, text: &str) -> Result<Profile, InputError> {
    let t = CsvTable::parse(path, text)?;
    // Each value in its range where it stands; `validate` then checks the order of levels.
    let altitude_m = t
        .f64_column_in("z_km", ALTITUDE_M.scaled(1e-3))?
        .iter()
        .map(|z| z * 1e3)
        .collect();
    let pressure_pa = t
        .f64_column_in("p_hPa", PRESSURE_PA.scaled(1e-2))?
        .iter()
        .map(|p| p * 100.0)
        .collect();
    let temperature_k = t.f64_column_in("T_K", TEMPERATURE_K)?;
    let mut gases = Vec::new();
    for h in t.header() {
        if let Some(name) = h.strip_suffix("_ppmv") {
            let vmr = t
                .f64_column_in(h, Bounds::closed(0.0, 1e6))?
                .iter()
                .map(|v| v * 1e-6)
                .collect();
            gases.push(GasProfile {
                name: name.to_string(),
                vmr,
            });
        }
    }
    let profile = Profile {
        name: format!("afgl {path}"),
        altitude_m,
        pressure_pa,
        temperature_k,
        gases,
    };
    profile
        .validate()
        .map_err(|e| InputError::file(path, e.to_string()))?;
    Ok(profile)
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
            p.validate().unwrap();
        }
    }

    #[test]
    fn validate_names_the_broken_invariant() {
        let mut p = StandardAtmosphere::UsStandard.profile();
        p.pressure_pa[3] = p.pressure_pa[2];
        let e = p.validate().unwrap_err().to_string();
        assert!(e.contains("pressure is not strictly decreasing"), "{e}");
        let mut p = StandardAtmosphere::UsStandard.profile();
        p.gases[0].vmr[1] = -1e-6;
        assert!(p.validate().is_err());
    }
}
