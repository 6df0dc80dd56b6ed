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
//! | `profile` | yes | profile id (text; the rows of one profile are contiguous) |
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

use super::humidity::{vmr_from_dry_mole_ratio, vmr_from_specific_humidity};
use super::hydrostatic::hydrostatic_altitudes_m;
use super::interp::{HYBRID_TOP_PA, hybrid_shift_pa};
use super::{ALTITUDE_M, AtmosphereError, GasProfile, PRESSURE_PA, Profile, TEMPERATURE_K};
use crate::input::{Bounds, CsvTable, InputError, parse_f64, parse_f64_in, read_to_string};

/// Latitude classes of the seed paper: high (|φ| > 50°), mid (30° ≤ |φ| ≤ 50°), tropical
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
                    meta.id,
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

/// Check an ISO 8601 UTC time as the set format accepts it.
fn check_time(s: &str) -> Result<(), String> {
    if s.is_empty() {
        return Ok(());
    }
    let b = s.as_bytes();
    let digits = |r: std::ops::Range<usize>| {
        b.get(r.clone())
            .is_some_and(|x| x.iter().all(u8::is_ascii_digit))
    };
    let date_ok = b.len() >= 10
        && digits(0..4)
        && b[4] == b'-'
        && digits(5..7)
        && b[7] == b'-'
        && digits(8..10);
    let ok = date_ok
        && match b.len() {
            10 => true,
            17 => {
                b[10] == b'T' && digits(11..13) && b[13] == b':' && digits(14..16) && b[16] == b'Z'
            }
            20 => {
                b[10] == b'T'
                    && digits(11..13)
                    && b[13] == b':'
                    && digits(14..16)
                    && b[16] == b':'
                    && digits(17..19)
                    && b[19] == b'Z'
            }
            _ => false,
        };
    if ok {
        Ok(())
    } else {
        Err(format!(
            "time `{s}` is not ISO 8601 UTC (YYYY-MM-DD, YYYY-MM-DDTHH:MMZ or YYYY-MM-DDTHH:MM:SSZ)"
        ))
    }
}

/// Read a profile set in the lidarsim format (see the module documentation); errors name the
/// file, line and column.
pub fn read_profile_set(path: &Path) -> Result<ProfileSet, InputError> {
    parse_profile_set(path, &read_to_string(path)?)
}

/// How a gas column is given.
#[derive(Debug, Clone, Copy)]
struct GasUnit {
    factor: f64,
    dry: bool,
    specific_humidity: bool,
}

fn parse_gas_column(h: &str) -> Option<(String, GasUnit)> {
    if h == "q_kgkg" {
        return Some((
            "H2O".into(),
            GasUnit {
                factor: 1.0,
                dry: false,
                specific_humidity: true,
            },
        ));
    }
    let (rest, dry) = match h.strip_suffix("_dry") {
        Some(r) => (r, true),
        None => (h, false),
    };
    let (gas, unit) = rest.rsplit_once('_')?;
    let factor = match unit {
        "vmr" => 1.0,
        "ppmv" => 1e-6,
        "ppbv" => 1e-9,
        _ => return None,
    };
    let valid = gas.chars().next().is_some_and(|c| c.is_ascii_uppercase())
        && gas.chars().all(|c| c.is_ascii_alphanumeric());
    valid.then(|| {
        (
            gas.to_string(),
            GasUnit {
                factor,
                dry,
                specific_humidity: false,
            },
        )
    })
}

/// Parse the text of a profile-set file (`path` for messages only).
pub fn parse_profile_set(path: &Path, text: &str) -> Result<ProfileSet, InputError> {
    let t = CsvTable::parse(path, text)?;
    let header = t.header().to_vec();
    // Errors about columns name the header line.
    let col_err = |name: &str, msg: String| InputError {
        path: path.to_path_buf(),
        line: Some(t.header_line()),
        field: Some(name.to_string()),
        message: msg,
    };
    let mut seen = BTreeSet::new();
    for h in &header {
        if !seen.insert(h.as_str()) {
            return Err(col_err(h, "column appears twice".into()));
        }
    }
    let one_of = |a: &str, b: &str| -> Result<Option<(usize, f64)>, InputError> {
        match (t.column_opt(a), t.column_opt(b)) {
            (Some(_), Some(_)) => Err(col_err(b, format!("give `{a}` or `{b}`, not both"))),
            (Some(i), None) => Ok(Some((i, 0.0))),
            (None, Some(i)) => Ok(Some((i, 1.0))),
            (None, None) => Ok(None),
        }
    };
    let c_id = t.column("profile")?;
    let c_lat = t.column("latitude_deg")?;
    let c_lon = t.column("longitude_deg")?;
    let c_t = t.column("temperature_K")?;
    let (c_p, p_scale) = match one_of("pressure_hPa", "pressure_Pa")? {
        Some((i, 0.0)) => (i, 100.0),
        Some((i, _)) => (i, 1.0),
        None => {
            return Err(col_err(
                "pressure_hPa",
                "missing column (or `pressure_Pa`)".into(),
            ));
        }
    };
    let c_z =
        one_of("altitude_m", "altitude_km")?.map(|(i, k)| (i, if k == 0.0 { 1.0 } else { 1e3 }));
    let c_time = t.column_opt("time_utc");
    let c_weight = t.column_opt("weight");
    let c_zs = t.column_opt("surface_altitude_m");
    if let (Some(_), Some(_)) = (c_z, c_zs) {
        return Err(col_err(
            "surface_altitude_m",
            "give either level altitudes or a surface altitude, not both".into(),
        ));
    }
    let known = [
        "profile",
        "latitude_deg",
        "longitude_deg",
        "temperature_K",
        "pressure_hPa",
        "pressure_Pa",
        "altitude_m",
        "altitude_km",
        "time_utc",
        "weight",
        "surface_altitude_m",
        "level",
    ];
    let mut gas_cols: Vec<(usize, String, GasUnit)> = Vec::new();
    for (i, h) in header.iter().enumerate() {
        if known.contains(&h.as_str()) {
            continue;
        }
        match parse_gas_column(h) {
            Some((g, u)) => {
                if gas_cols.iter().any(|(_, g2, _)| *g2 == g) {
                    return Err(col_err(h, format!("a second column for gas `{g}`")));
                }
                gas_cols.push((i, g, u));
            }
            None => {
                return Err(col_err(
                    h,
                    "unknown column (expected profile, latitude_deg, longitude_deg, time_utc, weight, \
                     level, pressure_hPa|pressure_Pa, temperature_K, altitude_m|altitude_km, \
                     surface_altitude_m, q_kgkg, or <GAS>_vmr|_ppmv|_ppbv[_dry])"
                        .into(),
                ));
            }
        }
    }
    // H2O first: dry-air conversions of other gases need it.
    gas_cols.sort_by_key(|(_, g, _)| g != "H2O");
    let needs_h2o = gas_cols.iter().any(|(_, g, u)| u.dry && g != "H2O");
    if needs_h2o && !gas_cols.iter().any(|(_, g, _)| g == "H2O") {
        return Err(col_err(
            &header[gas_cols.iter().find(|c| c.2.dry).expect("some").0],
            "per-dry-air mixing ratios need a water vapour column to convert".into(),
        ));
    }

    let stem = path
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    let mut set = ProfileSet {
        name: path.display().to_string(),
        members: Vec::new(),
        notes: Vec::new(),
    };
    let mut ids_done: BTreeSet<String> = BTreeSet::new();
    let rows: Vec<(usize, &[String])> = t.rows().collect();
    let nrows = rows.len();
    let mut r = 0;
    while r < nrows {
        let line0 = rows[r].0;
        let id = rows[r].1[c_id].clone();
        if id.is_empty() {
            return Err(InputError::at(path, line0, "profile", "empty profile id"));
        }
        if ids_done.contains(&id) {
            return Err(InputError::at(
                path,
                line0,
                "profile",
                format!("rows of profile `{id}` are not contiguous (it appeared before)"),
            ));
        }
        let mut end = r;
        while end < nrows && rows[end].1[c_id] == id {
            end += 1;
        }
        let member = parse_member(
            path,
            &t,
            &rows[r..end],
            &id,
            &stem,
            c_lat,
            c_lon,
            c_time,
            c_weight,
            c_zs,
            c_p,
            p_scale,
            c_t,
            c_z,
            &gas_cols,
        )?;
        set.members.push(member);
        ids_done.insert(id);
        r = end;
    }
    if set.members.is_empty() {
        return Err(InputError::file(path, "no profiles (no data rows)"));
    }
    set.notes = t
        .comments
        .iter()
        .filter(|c| !c.starts_with("lidarsim profile set"))
        .cloned()
        .collect();
    Ok(set)
}

#[allow(clippy::too_many_arguments)]
fn parse_member(
    path: &Path,
    t: &CsvTable,
    all: &[(usize, &[String])],
    id: &str,
    stem: &str,
    c_lat: usize,
    c_lon: usize,
    c_time: Option<usize>,
    c_weight: Option<usize>,
    c_zs: Option<usize>,
    c_p: usize,
    p_scale: f64,
    c_t: usize,
    c_z: Option<(usize, f64)>,
    gas_cols: &[(usize, String, GasUnit)],
) -> Result<SetMember, InputError> {
    let header = t.header();
    let (line0, f0) = all[0];
    let num = |line: usize, fields: &[String], col: usize, bounds: Bounds| {
        parse_f64_in(path, line, &header[col], &fields[col], bounds)
    };
    // Per-profile metadata: from the first row, identical on all rows.
    for (line, f) in &all[1..] {
        for c in [Some(c_lat), Some(c_lon), c_time, c_weight, c_zs]
            .into_iter()
            .flatten()
        {
            if f[c] != f0[c] {
                return Err(InputError::at(
                    path,
                    *line,
                    &header[c],
                    format!(
                        "`{}` differs from `{}` on line {line0}, the first row of profile `{id}`",
                        f[c], f0[c]
                    ),
                ));
            }
        }
    }
    let latitude_deg = num(line0, f0, c_lat, Bounds::closed(-90.0, 90.0))?;
    let longitude_deg = num(line0, f0, c_lon, Bounds::closed(-360.0, 360.0))?;
    let time_utc = c_time.map(|c| f0[c].clone()).unwrap_or_default();
    check_time(&time_utc).map_err(|m| InputError::at(path, line0, "time_utc", m))?;
    let weight = c_weight
        .map(|c| num(line0, f0, c, Bounds::closed(0.0, 1e12)))
        .transpose()?;
    let surface_altitude_m = c_zs
        .map(|c| num(line0, f0, c, ALTITUDE_M))
        .transpose()?
        .unwrap_or(0.0);

    // Levels in file order, then bottom-up.
    struct Level {
        line: usize,
        p: f64,
        t: f64,
        z: Option<f64>,
        gas: Vec<f64>,
    }
    let mut levels = Vec::with_capacity(all.len());
    for (line, f) in all {
        let p = num(*line, f, c_p, PRESSURE_PA.scaled(1.0 / p_scale))? * p_scale;
        let temp = num(*line, f, c_t, TEMPERATURE_K)?;
        let z = c_z
            .map(|(c, s)| num(*line, f, c, ALTITUDE_M.scaled(1.0 / s)).map(|v| v * s))
            .transpose()?;
        let mut gas = Vec::with_capacity(gas_cols.len());
        let mut x_h2o = 0.0;
        for (c, g, u) in gas_cols {
            let v = parse_f64(path, *line, &header[*c], &f[*c])?;
            let x = if u.specific_humidity {
                if !(0.0..1.0).contains(&v) {
                    return Err(InputError::at(
                        path,
                        *line,
                        &header[*c],
                        "specific humidity must be in [0, 1)",
                    ));
                }
                vmr_from_specific_humidity(v)
            } else {
                let r = v * u.factor;
                if !(0.0..=1.0).contains(&r) {
                    return Err(InputError::at(
                        path,
                        *line,
                        &header[*c],
                        format!("{v} is not a mixing ratio in [0, 1] in this unit"),
                    ));
                }
                match (u.dry, g.as_str()) {
                    (true, "H2O") => vmr_from_dry_mole_ratio(r),
                    (true, _) => r * (1.0 - x_h2o),
                    (false, _) => r,
                }
            };
            if g == "H2O" {
                x_h2o = x;
            }
            gas.push(x);
        }
        levels.push(Level {
            line: *line,
            p,
            t: temp,
            z,
            gas,
        });
    }
    if levels.len() < 2 {
        return Err(InputError::at(
            path,
            line0,
            "profile",
            format!("profile `{id}` has fewer than 2 levels"),
        ));
    }
    let descending = levels[1].p < levels[0].p;
    for w in levels.windows(2) {
        let ok = if descending {
            w[1].p < w[0].p
        } else {
            w[1].p > w[0].p
        };
        if !ok {
            return Err(InputError::at(
                path,
                w[1].line,
                &header[c_p],
                format!(
                    "pressures of profile `{id}` are not strictly monotonic ({} then {})",
                    fmt_num(w[0].p / p_scale),
                    fmt_num(w[1].p / p_scale)
                ),
            ));
        }
    }
    if !descending {
        levels.reverse();
    }
    let pressure_pa: Vec<f64> = levels.iter().map(|l| l.p).collect();
    let temperature_k: Vec<f64> = levels.iter().map(|l| l.t).collect();
    let gases: Vec<GasProfile> = gas_cols
        .iter()
        .enumerate()
        .map(|(i, (_, g, _))| GasProfile {
            name: g.clone(),
            vmr: levels.iter().map(|l| l.gas[i]).collect(),
        })
        .collect();
    let altitude_m = match c_z {
        Some((c, _)) => {
            let z: Vec<f64> = levels
                .iter()
                .map(|l| l.z.expect("column present"))
                .collect();
            if let Some(k) = (1..z.len()).find(|&k| !(z[k] > z[k - 1])) {
                return Err(InputError::at(
                    path,
                    levels[k].line,
                    &header[c],
                    format!("altitude of profile `{id}` does not increase as pressure decreases"),
                ));
            }
            z
        }
        None => {
            let h2o = gases
                .iter()
                .find(|g| g.name == "H2O")
                .map(|g| g.vmr.as_slice());
            hydrostatic_altitudes_m(
                &pressure_pa,
                &temperature_k,
                h2o,
                surface_altitude_m,
                latitude_deg,
            )
            .map_err(|e| InputError::at(path, line0, "profile", e.to_string()))?
        }
    };
    let profile = Profile {
        name: format!("{stem} #{id}"),
        altitude_m,
        pressure_pa,
        temperature_k,
        gases,
    };
    profile
        .validate()
        .map_err(|e| InputError::at(path, line0, "profile", e.to_string()))?;
    Ok(SetMember {
        meta: ProfileMeta {
            id: id.to_string(),
            latitude_deg,
            longitude_deg,
            time_utc,
            weight,
        },
        profile,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn classes_follow_the_paper_boundaries() {
        use LatitudeClass::*;
        for (lat, c) in [
            (0.0, Tropical),
            (-29.9, Tropical),
            (30.0, Mid),
            (-50.0, Mid),
            (50.01, High),
            (-90.0, High),
        ] {
            assert_eq!(LatitudeClass::of_latitude_deg(lat), c, "{lat}");
        }
    }

    #[test]
    fn time_format() {
        for ok in [
            "",
            "2007-02-20",
            "2007-02-20T06:00Z",
            "2014-01-05T06:00:00Z",
        ] {
            assert!(check_time(ok).is_ok(), "{ok}");
        }
        for bad in ["2007-2-20", "20070220", "2007-02-20T06:00", "yesterday"] {
            assert!(check_time(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn number_format_is_short_and_exact_to_9_digits() {
        assert_eq!(fmt_num(1013.25), "1013.25");
        assert_eq!(fmt_num(0.1 + 0.2), "0.3");
        assert_eq!(fmt_num(-0.0), "0");
        assert_eq!(fmt_num(123456789.4), "123456789");
    }
}
