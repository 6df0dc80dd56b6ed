//! Profile sets: many profiles with their location and time, the lidarsim long-table format,
//! latitude classes and class means.
//!
//! # The profile-set format (written by `lidarsim profiles generate`, read by everything)
//!
//! A comma-separated long table, one row per level, `#` comment lines anywhere, units in the
//! column names (full description in `docs/atmosphere.md`):
//!
//! ```text
//! # lidarsim profile set
//! profile,latitude_deg,longitude_deg,time_utc,level,altitude_m,pressure_hPa,temperature_K,H2O_ppmv,CO2_ppmv
//! trop-0001,15,0,2007-02-20T12:00Z,1,0,1013,299.7,25900,420.1
//! ...
//! ```
//!
//! | column | required | meaning |
//! |---|---|---|
//! | `profile` | yes | profile id (text; the rows of one profile are contiguous; written by the house rule of [`crate::output::csv_field`], `'1064` for an id that reads as a number, and read back by [`crate::output::csv_text_value`]) |
//! | `latitude_deg`, `longitude_deg` | yes | location [°N, °E] |
//! | `time_utc` | no | `YYYY-MM-DD` or `YYYY-MM-DDTHH:MM[:SS]Z`, or empty (unknown) |
//! | `weight` | no | a profile weight (e.g. RFMIP's), kept and written back |
//! | `level` | no | a level label, not used |
//! | `pressure_hPa` or `pressure_Pa` | one of them | pressure |
//! | `temperature_K` | yes | temperature |
//! | `altitude_m` or `altitude_km` | no | geometric altitude; hydrostatic from p, T, H2O when absent |
//! | `surface_altitude_m` | no | altitude of the lowest level when `altitude_*` is absent (0 if not given) |
//! | `<GAS>_vmr`, `<GAS>_ppmv`, `<GAS>_ppbv` | no | mole fraction of moist air (mol/mol, 1e-6, 1e-9) |
//! | `<GAS>_vmr_dry`, `<GAS>_ppmv_dry`, `<GAS>_ppbv_dry` | no | the same per dry air |
//! | `q_kgkg` | no | specific humidity (kg water per kg moist air), instead of an H2O column |
//!
//! Any other column is an error. Levels may be listed top-down or bottom-up (monotonic in
//! pressure); lidarsim stores them bottom-up.

use std::collections::BTreeSet;
use std::fmt::Write as _;
use std::path::Path;
use std::str::FromStr;

use super::hydrostatic::hydrostatic_altitudes_m;
use super::interp::{HYBRID_TOP_PA, hybrid_shift_pa};
use super::{AtmosphereError, GasProfile, Profile};

mod read;

use read::check_time;
pub use read::{parse_profile_set, read_profile_set};

/// Latitude classes of the reference study: high (|φ| > 50°), mid (30° ≤ |φ| ≤ 50°), tropical
/// (|φ| < 30°).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum LatitudeClass {
    /// |latitude| < 30°.
    Tropical,
    /// 30° ≤ |latitude| ≤ 50°.
    Mid,
    /// |latitude| > 50°.
    High,
}

impl LatitudeClass {
    /// The three classes, equator to pole.
    pub const ALL: [LatitudeClass; 3] = [Self::Tropical, Self::Mid, Self::High];

    /// The class of a latitude [°] (either hemisphere). Boundaries 30° and 50° belong to `Mid`.
    pub fn of_latitude_deg(latitude_deg: f64) -> LatitudeClass {
        let a = latitude_deg.abs();
        if a > 50.0 {
            Self::High
        } else if a >= 30.0 {
            Self::Mid
        } else {
            Self::Tropical
        }
    }

    /// Name on the command line and in files: `tropical`, `mid`, `high`.
    pub fn name(self) -> &'static str {
        match self {
            Self::Tropical => "tropical",
            Self::Mid => "mid",
            Self::High => "high",
        }
    }

    /// The AFGL atmospheres of the class (tropical; mid-latitude summer and winter; sub-arctic
    /// summer and winter), whose mean stands for the class when no profile set is given.
    pub fn afgl_atmospheres(self) -> &'static [super::StandardAtmosphere] {
        use super::StandardAtmosphere as S;
        match self {
            Self::Tropical => &[S::Tropical],
            Self::Mid => &[S::MidlatitudeSummer, S::MidlatitudeWinter],
            Self::High => &[S::SubarcticSummer, S::SubarcticWinter],
        }
    }
}

impl FromStr for LatitudeClass {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "tropical" | "tropics" => Ok(Self::Tropical),
            "mid" | "mid_lat" | "midlatitude" => Ok(Self::Mid),
            "high" | "high_lat" | "polar" => Ok(Self::High),
            _ => Err(format!(
                "unknown latitude class `{s}` (known: tropical, mid, high)"
            )),
        }
    }
}

impl std::fmt::Display for LatitudeClass {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// Where and when a profile was taken.
#[derive(Debug, Clone, PartialEq)]
pub struct ProfileMeta {
    /// Profile id, unique in its set.
    pub id: String,
    /// Latitude [°N], −90 to 90.
    pub latitude_deg: f64,
    /// Longitude [°E].
    pub longitude_deg: f64,
    /// Time as ISO 8601 UTC (`YYYY-MM-DD` or `YYYY-MM-DDTHH:MM[:SS]Z`); empty when unknown.
    pub time_utc: String,
    /// A profile weight where the source gives one (RFMIP's global-mean weights).
    pub weight: Option<f64>,
}

impl ProfileMeta {
    /// The latitude class of this profile.
    pub fn class(&self) -> LatitudeClass {
        LatitudeClass::of_latitude_deg(self.latitude_deg)
    }
}

/// One profile of a set with its metadata.
#[derive(Debug, Clone, PartialEq)]
pub struct SetMember {
    /// Location, time, id.
    pub meta: ProfileMeta,
    /// The profile (altitudes from the surface of this profile up).
    pub profile: Profile,
}

/// A set of profiles (a file, a latitude class of it, an ensemble).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct ProfileSet {
    /// A name for messages (usually the file).
    pub name: String,
    /// The profiles, in file order.
    pub members: Vec<SetMember>,
    /// Free-text notes written as `#` comments (provenance, generation settings).
    pub notes: Vec<String>,
}

impl ProfileSet {
    /// Number of profiles.
    pub fn len(&self) -> usize {
        self.members.len()
    }

    /// True without profiles.
    pub fn is_empty(&self) -> bool {
        self.members.is_empty()
    }

    /// The profile with this id.
    pub fn get(&self, id: &str) -> Option<&Profile> {
        self.member(id).map(|m| &m.profile)
    }

    /// The member (profile and metadata) with this id.
    pub fn member(&self, id: &str) -> Option<&SetMember> {
        self.members.iter().find(|m| m.meta.id == id)
    }

    /// The profiles of one latitude class, as a new set (name suffixed with the class).
    pub fn class(&self, c: LatitudeClass) -> ProfileSet {
        ProfileSet {
            name: format!("{} [{}]", self.name, c.name()),
            members: self
                .members
                .iter()
                .filter(|m| m.meta.class() == c)
                .cloned()
                .collect(),
            notes: self.notes.clone(),
        }
    }

    /// Number of profiles per class, in the order of [`LatitudeClass::ALL`].
    pub fn class_counts(&self) -> [usize; 3] {
        let mut n = [0; 3];
        for m in &self.members {
            n[m.meta.class() as usize] += 1;
        }
        n
    }

    /// The mean profile of the set (see [`Self::mean_member`]).
    pub fn mean(&self) -> Result<Profile, AtmosphereError> {
        Ok(self.mean_member()?.profile)
    }

    /// The mean of the set's profiles, with metadata.
    ///
    /// Method: the mean surface pressure p̄_s is the mean of the members' lowest-level
    /// pressures. The mean's levels are the first member's levels moved to p̄_s with
    /// [`hybrid_shift_pa`] (sigma-like near the surface, fixed pressure above 100 hPa), without
    /// levels above the lowest top of any member. Each member is interpolated (ln p) to the
    /// same hybrid levels moved to its own surface pressure, so every member contributes at every
    /// level, surface to top. Temperatures and mixing ratios are arithmetic means (the mean's
    /// gas columns are then close to the mean columns). Altitudes are hydrostatic from the mean
    /// state, starting at the mean surface altitude, at the mean absolute latitude.
    ///
    /// Errors: an empty set; members with different gases; a surface pressure below 100 hPa.
    pub fn mean_member(&self) -> Result<SetMember, AtmosphereError> {
        let first = self
            .members
            .first()
            .ok_or_else(|| AtmosphereError::EmptySet(self.name.clone()))?;
        let gas_names: BTreeSet<&str> = first.profile.gas_names().into_iter().collect();
        for m in &self.members {
            m.profile.validate()?;
            let g: BTreeSet<&str> = m.profile.gas_names().into_iter().collect();
            if g != gas_names {
                return Err(AtmosphereError::InvalidProfile {
                    profile: m.profile.name.clone(),
                    message: format!(
                        "its gases ({}) differ from those of `{}` ({}); a mean needs the same gases",
                        g.into_iter().collect::<Vec<_>>().join(", "),
                        first.profile.name,
                        gas_names.iter().copied().collect::<Vec<_>>().join(", ")
                    ),
                });
            }
            if m.profile.surface_pressure_pa() <= HYBRID_TOP_PA {
                return Err(AtmosphereError::InvalidProfile {
                    profile: m.profile.name.clone(),
                    message: format!(
                        "surface pressure {} Pa is not above {HYBRID_TOP_PA} Pa",
                        m.profile.surface_pressure_pa()
                    ),
                });
            }
        }
        let nm = self.members.len() as f64;
        let ps_mean = self
            .members
            .iter()
            .map(|m| m.profile.surface_pressure_pa())
            .sum::<f64>()
            / nm;
        let zs_mean = self
            .members
            .iter()
            .map(|m| m.profile.altitude_m[0])
            .sum::<f64>()
            / nm;
        let ps0 = first.profile.surface_pressure_pa();
        let mut grid: Vec<f64> = first
            .profile
            .pressure_pa
            .iter()
            .map(|&p| hybrid_shift_pa(p, ps0, ps_mean))
            .filter(|&p| {
                self.members.iter().all(|m| {
                    let top = *m.profile.pressure_pa.last().expect("validated");
                    hybrid_shift_pa(p, ps_mean, m.profile.surface_pressure_pa()) >= top
                })
            })
            .collect();
        grid[0] = ps_mean;
        if grid.len() < 2 {
            return Err(AtmosphereError::InvalidProfile {
                profile: first.profile.name.clone(),
                message: "fewer than 2 levels are common to all members".into(),
            });
        }
        let nl = grid.len();
        let mut t_sum = vec![0.0; nl];
        let gas_order: Vec<String> = first
            .profile
            .gas_names()
            .iter()
            .map(|s| s.to_string())
            .collect();
        let mut gas_sum = vec![vec![0.0; nl]; gas_order.len()];
        for m in &self.members {
            let prof = &m.profile;
            let ps = prof.surface_pressure_pa();
            let top = *prof.pressure_pa.last().expect("validated");
            let targets: Vec<f64> = grid
                .iter()
                .map(|&p| hybrid_shift_pa(p, ps_mean, ps).clamp(top, ps))
                .collect();
            let at = prof.interpolate_to_pressures(&targets)?;
            t_sum
                .iter_mut()
                .zip(&at.temperature_k)
                .for_each(|(s, t)| *s += t);
            for (g, sum) in gas_order.iter().zip(gas_sum.iter_mut()) {
                let v = at.gas(g).expect("same gases (checked)");
                sum.iter_mut().zip(v).for_each(|(s, x)| *s += x);
            }
        }
        let temperature_k: Vec<f64> = t_sum.iter().map(|t| t / nm).collect();
        let gases: Vec<GasProfile> = gas_order
            .iter()
            .zip(gas_sum)
            .map(|(g, s)| GasProfile {
                name: g.clone(),
                vmr: s.iter().map(|x| x / nm).collect(),
            })
            .collect();
        let abs_lat = self
            .members
            .iter()
            .map(|m| m.meta.latitude_deg.abs())
            .sum::<f64>()
            / nm;
        let sign = if self.members.iter().all(|m| m.meta.latitude_deg < 0.0) {
            -1.0
        } else {
            1.0
        };
        let h2o = gases
            .iter()
            .find(|g| g.name == "H2O")
            .map(|g| g.vmr.as_slice());
        let altitude_m = hydrostatic_altitudes_m(&grid, &temperature_k, h2o, zs_mean, abs_lat)?;
        let profile = Profile {
            name: format!("mean of {}", self.name),
            altitude_m,
            pressure_pa: grid,
            temperature_k,
            gases,
        };
        profile.validate()?;
        Ok(SetMember {
            meta: ProfileMeta {
                id: "mean".into(),
                latitude_deg: sign * abs_lat,
                longitude_deg: 0.0,
                time_utc: String::new(),
                weight: None,
            },
            profile,
        })
    }

    /// The set as text in the lidarsim profile-set format (canonical columns: altitude in m,
    /// pressure in hPa, gases in ppmv of moist air; 9 significant digits).
    pub fn to_csv(&self) -> Result<String, AtmosphereError> {
        let first = self
            .members
            .first()
            .ok_or_else(|| AtmosphereError::EmptySet(self.name.clone()))?;
        let gases: Vec<String> = first
            .profile
            .gas_names()
            .iter()
            .map(|s| s.to_string())
            .collect();
        let with_weight = first.meta.weight.is_some();
        let mut out = String::new();
        out.push_str("# lidarsim profile set (format: docs/atmosphere.md)\n");
        for n in &self.notes {
            for line in n.lines() {
                let _ = writeln!(out, "# {line}");
            }
        }
        out.push_str("profile,latitude_deg,longitude_deg,time_utc,");
        if with_weight {
            out.push_str("weight,");
        }
        out.push_str("level,altitude_m,pressure_hPa,temperature_K");
        for g in &gases {
            let _ = write!(out, ",{g}_ppmv");
        }
        out.push('\n');
        let mut ids = BTreeSet::new();
        for m in &self.members {
            m.profile.validate()?;
            let meta = &m.meta;
            let bad = |msg: String| AtmosphereError::InvalidProfile {
                profile: meta.id.clone(),
                message: msg,
            };
            if meta.id.is_empty() || meta.id.contains([',', '\n', '#']) || meta.id.trim() != meta.id
            {
                return Err(bad(
                    "the id must be non-empty without commas, `#` or surrounding blanks".into(),
                ));
            }
            if !ids.insert(meta.id.as_str()) {
                return Err(bad("the id appears twice".into()));
            }
            if meta.weight.is_some() != with_weight {
                return Err(bad("some profiles have a weight, others not".into()));
            }
            check_time(&meta.time_utc).map_err(bad)?;
            let names: BTreeSet<&str> = m.profile.gas_names().into_iter().collect();
            if names != gases.iter().map(|s| s.as_str()).collect() || names.len() != gases.len() {
                return Err(bad(format!(
                    "gases differ from the first profile's ({})",
                    gases.join(", ")
                )));
            }
            let cols: Vec<&[f64]> = gases
                .iter()
                .map(|g| m.profile.gas(g).expect("checked"))
                .collect();
            for k in 0..m.profile.len() {
                let _ = write!(
                    out,
                    "{},{},{},{},",
                    crate::output::csv_field(&meta.id),
                    fmt_num(meta.latitude_deg),
                    fmt_num(meta.longitude_deg),
                    meta.time_utc
                );
                if let Some(w) = meta.weight {
                    let _ = write!(out, "{},", fmt_num(w));
                }
                let _ = write!(
                    out,
                    "{},{},{},{}",
                    k + 1,
                    fmt_num(m.profile.altitude_m[k]),
                    fmt_num(m.profile.pressure_pa[k] / 100.0),
                    fmt_num(m.profile.temperature_k[k])
                );
                for c in &cols {
                    let _ = write!(out, ",{}", fmt_num(c[k] * 1e6));
                }
                out.push('\n');
            }
        }
        Ok(out)
    }

    /// Write the set to `path`, whole or not at all ([`crate::output`]).
    pub fn write(&self, path: &Path) -> Result<(), AtmosphereError> {
        Ok(crate::output::write_file(path, self.to_csv()?.as_bytes())?)
    }
}

/// A number with 9 significant digits, printed without exponent noise (`1013.25`, `0.000412`).
pub(crate) fn fmt_num(v: f64) -> String {
    let r: f64 = format!("{v:.8e}").parse().unwrap_or(v);
    let s = format!("{r}");
    if s == "-0" { "0".into() } else { s }
}

#[cfg(test)]
mod tests;
