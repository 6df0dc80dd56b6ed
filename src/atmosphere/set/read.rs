//! Reading the profile-set format ([`super`] module docs): columns, units, one member per
//! profile id, with errors that name the file, line and column.

use std::collections::BTreeSet;
use std::path::Path;

use super::{ProfileMeta, ProfileSet, SetMember, fmt_num};
use crate::atmosphere::humidity::{vmr_from_dry_mole_ratio, vmr_from_specific_humidity};
use crate::atmosphere::hydrostatic::hydrostatic_altitudes_m;
use crate::atmosphere::{ALTITUDE_M, GasProfile, PRESSURE_PA, Profile, TEMPERATURE_K};
use crate::input::{Bounds, CsvTable, InputError, parse_f64, parse_f64_in, read_to_string};

/// Check an ISO 8601 UTC time as the set format accepts it.
pub(super) fn check_time(s: &str) -> Result<(), String> {
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

/// The id a `profile` field holds: as written by [`crate::output::csv_field`] (the set's
/// writer), an RFC 4180 quoted field unquoted (a profile id holds no comma or line break, so
/// the plain comma split keeps it whole) and one leading apostrophe removed (`'1064` → `1064`).
/// A field written by hand without either is the id as it is.
fn profile_id(field: &str) -> String {
    let unquoted = match field.strip_prefix('"').and_then(|f| f.strip_suffix('"')) {
        Some(inner) if field.len() >= 2 => inner.replace("\"\"", "\""),
        _ => field.to_string(),
    };
    crate::output::csv_text_value(&unquoted).to_string()
}

/// Parse the text of a profile-set file (`path` for messages only).
pub fn parse_profile_set(path: &Path, text: &str) -> Result<ProfileSet, InputError> {
    let t = CsvTable::parse(path, text)?;
    let cols = columns(path, &t)?;
    let c_id = cols.c_id;
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
        let raw_id = &rows[r].1[c_id];
        let id = profile_id(raw_id);
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
        while end < nrows && rows[end].1[c_id] == *raw_id {
            end += 1;
        }
        let member = parse_member(path, &t, &rows[r..end], &id, &stem, &cols)?;
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

/// The columns of a profile-set file: where each quantity is, and the unit of each gas.
struct Columns {
    c_id: usize,
    c_lat: usize,
    c_lon: usize,
    c_time: Option<usize>,
    c_weight: Option<usize>,
    c_zs: Option<usize>,
    c_p: usize,
    /// Pa per unit of the pressure column.
    p_scale: f64,
    c_t: usize,
    /// The altitude column and its metres per unit.
    c_z: Option<(usize, f64)>,
    /// The gas columns, H2O first.
    gas_cols: Vec<(usize, String, GasUnit)>,
}

/// Find and check the columns of `t`; errors name the header line.
fn columns(path: &Path, t: &CsvTable) -> Result<Columns, InputError> {
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
    Ok(Columns {
        c_id,
        c_lat,
        c_lon,
        c_time,
        c_weight,
        c_zs,
        c_p,
        p_scale,
        c_t,
        c_z,
        gas_cols,
    })
}

/// One level of a profile as read.
struct Level {
    line: usize,
    p: f64,
    t: f64,
    z: Option<f64>,
    gas: Vec<f64>,
}

/// The metadata of one profile, from its first row (identical on all rows), and its surface
/// altitude.
fn member_meta(
    path: &Path,
    t: &CsvTable,
    all: &[(usize, &[String])],
    id: &str,
    cols: &Columns,
) -> Result<(ProfileMeta, f64), InputError> {
    let (c_lat, c_lon, c_time, c_weight, c_zs) = (
        cols.c_lat,
        cols.c_lon,
        cols.c_time,
        cols.c_weight,
        cols.c_zs,
    );
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
    let meta = ProfileMeta {
        id: id.to_string(),
        latitude_deg,
        longitude_deg,
        time_utc,
        weight,
    };
    Ok((meta, surface_altitude_m))
}

/// The levels of one profile, checked, bottom-up.
fn member_levels(
    path: &Path,
    t: &CsvTable,
    all: &[(usize, &[String])],
    id: &str,
    cols: &Columns,
) -> Result<Vec<Level>, InputError> {
    let (c_p, p_scale, c_t, c_z) = (cols.c_p, cols.p_scale, cols.c_t, cols.c_z);
    let gas_cols = &cols.gas_cols;
    let header = t.header();
    let line0 = all[0].0;
    let num = |line: usize, fields: &[String], col: usize, bounds: Bounds| {
        parse_f64_in(path, line, &header[col], &fields[col], bounds)
    };
    // Levels in file order, then bottom-up.
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
    Ok(levels)
}

/// One profile of the set: its rows `all`, with the columns `cols`.
fn parse_member(
    path: &Path,
    t: &CsvTable,
    all: &[(usize, &[String])],
    id: &str,
    stem: &str,
    cols: &Columns,
) -> Result<SetMember, InputError> {
    let header = t.header();
    let line0 = all[0].0;
    let (meta, surface_altitude_m) = member_meta(path, t, all, id, cols)?;
    let levels = member_levels(path, t, all, id, cols)?;
    let (c_z, gas_cols) = (cols.c_z, &cols.gas_cols);
    let latitude_deg = meta.latitude_deg;
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
    Ok(SetMember { meta, profile })
}
