//! Readers for profile sets in the formats they are distributed in (as saved under
//! `../shared/data/profiles`), converted to [`ProfileSet`]s; `lidarsim profiles convert` writes
//! them in the lidarsim format.
//!
//! | reader | source | levels | units in the source → lidarsim |
//! |---|---|---|---|
//! | [`read_ecmwf83`] | Matricardi (2008) 83 profiles, 101 RTTOV levels + meta file | levels below the surface dropped, a surface level interpolated (ln p) at p_s | ppmv per dry air (see below) → moist-air vmr |
//! | [`read_ecmwf52`] | Chevallier (2002) 52 profiles, 101 levels + meta file | as above | q and O3 in kg/kg of moist air → vmr |
//! | [`read_rfmip`] | RFMIP-IRF 100 sites (Pincus et al. 2016), 60 layers with edges + meta file | the 61 layer edges (edge T given); layer H2O and O3 interpolated to edges in ln p | mole ratios per dry air (RRTMGP convention) → moist vmr; CO2, CH4, N2O, CO, O2 from the global means in the meta header |
//!
//! ECMWF 83 units: the source says "ppmv" (RTTOV's default is ppmv over moist air). In the data,
//! CO2 is constant with height to 0.1 ppmv through moist boundary layers with 2–4 % water
//! vapour, which is what a dry-air mole fraction of a well-mixed gas does (over moist air it
//! would drop by the water fraction, 8–15 ppmv); CRTM's reader of the same file also converts
//! them as per-dry-air ppmv. lidarsim therefore reads them as ppmv per dry air.
//!
//! Altitudes: hydrostatic from the surface pressure, with the surface at altitude 0 (none of the
//! three sources gives the surface altitude), at each profile's latitude.

use std::collections::BTreeMap;
use std::path::Path;

use super::humidity::{
    moist_air_molar_mass_kg_per_mol, vmr_from_dry_mole_ratio, vmr_from_specific_humidity,
};
use super::hydrostatic::hydrostatic_altitudes_m;
use super::set::{ProfileMeta, ProfileSet, SetMember};
use super::{GasProfile, Profile, molar_mass_kg_per_mol};
use super::{PRESSURE_PA, TEMPERATURE_K};
use crate::input::{Bounds, CsvTable, InputError};

/// Rows of a native level file grouped by profile id, in file order: (line, fields).
type Grouped<'a> = BTreeMap<i64, Vec<(usize, &'a [String])>>;

fn group_by_profile<'a>(t: &'a CsvTable, id_col: &str) -> Result<Grouped<'a>, InputError> {
    let c = t.column(id_col)?;
    let mut g: Grouped = BTreeMap::new();
    for (line, f) in t.rows() {
        let id: i64 = f[c].parse().map_err(|_| {
            InputError::at(
                t.path(),
                line,
                id_col,
                format!("`{}` is not an integer", f[c]),
            )
        })?;
        g.entry(id).or_default().push((line, f));
    }
    Ok(g)
}

fn num(t: &CsvTable, line: usize, f: &[String], col: &str) -> Result<f64, InputError> {
    let c = t.column(col)?;
    crate::input::parse_f64(t.path(), line, col, &f[c])
}

/// A field inside its physical range, refused where it stands.
fn num_in(
    t: &CsvTable,
    line: usize,
    f: &[String],
    col: &str,
    bounds: Bounds,
) -> Result<f64, InputError> {
    let c = t.column(col)?;
    crate::input::parse_f64_in(t.path(), line, col, &f[c], bounds)
}

/// Latitude \[deg\].
const LATITUDE_DEG: Bounds = Bounds::closed(-90.0, 90.0);
/// Longitude \[deg\].
const LONGITUDE_DEG: Bounds = Bounds::closed(-360.0, 360.0);
/// A mole fraction or a mass fraction.
const FRACTION: Bounds = Bounds::closed(0.0, 1.0);

/// (pressure \[Pa\], temperature \[K\], per-quantity values), bottom-up.
type LevelColumns = (Vec<f64>, Vec<f64>, Vec<Vec<f64>>);

/// Levels of one profile on pressure levels (bottom-up after this call): keep the levels above
/// the surface and add the surface level, values interpolated linearly in ln p.
/// `rows`: (line, p_Pa, T, values...) in any monotonic order.
fn cut_at_surface(
    path: &Path,
    id: i64,
    mut levels: Vec<(usize, f64, f64, Vec<f64>)>,
    ps: f64,
) -> Result<LevelColumns, InputError> {
    levels.sort_by(|a, b| b.1.total_cmp(&a.1));
    if let Some(w) = levels.windows(2).find(|w| w[1].1 >= w[0].1) {
        return Err(InputError::at(
            path,
            w[1].0,
            "p_hPa",
            format!("profile {id}: repeated pressure"),
        ));
    }
    let bottom = levels[0].1;
    if ps > bottom || ps <= levels[levels.len() - 1].1 {
        return Err(InputError::at(
            path,
            levels[0].0,
            "p_hPa",
            format!("profile {id}: surface pressure {ps} Pa lies outside its levels"),
        ));
    }
    // First level strictly above the surface (p < ps).
    let k = levels.iter().position(|l| l.1 < ps).expect("checked");
    let (lo, hi) = (&levels[k - 1], &levels[k]);
    let w = (ps.ln() - lo.1.ln()) / (hi.1.ln() - lo.1.ln());
    let lerp = |a: f64, b: f64| a + w * (b - a);
    let mut p = vec![ps];
    let mut t = vec![lerp(lo.2, hi.2)];
    let mut v: Vec<Vec<f64>> =
        lo.3.iter()
            .zip(&hi.3)
            .map(|(a, b)| vec![lerp(*a, *b)])
            .collect();
    for l in &levels[k..] {
        p.push(l.1);
        t.push(l.2);
        v.iter_mut().zip(&l.3).for_each(|(c, x)| c.push(*x));
    }
    Ok((p, t, v))
}

fn finish(
    path: &Path,
    line: usize,
    name: String,
    meta: ProfileMeta,
    pressure_pa: Vec<f64>,
    temperature_k: Vec<f64>,
    gases: Vec<GasProfile>,
) -> Result<SetMember, InputError> {
    let h2o = gases
        .iter()
        .find(|g| g.name == "H2O")
        .map(|g| g.vmr.as_slice());
    let altitude_m =
        hydrostatic_altitudes_m(&pressure_pa, &temperature_k, h2o, 0.0, meta.latitude_deg)
            .map_err(|e| InputError::at(path, line, "profile", e.to_string()))?;
    let profile = Profile {
        name,
        altitude_m,
        pressure_pa,
        temperature_k,
        gases,
    };
    profile
        .validate()
        .map_err(|e| InputError::at(path, line, "profile", e.to_string()))?;
    Ok(SetMember { meta, profile })
}

/// Read the ECMWF 83-profile set (Matricardi 2008) as saved in `../shared/data/profiles`
/// (`ecmwf83_matricardi2008_101L.csv` and `_meta.csv`). The 80 located profiles are returned;
/// profiles 81–83 (minimum and maximum envelopes, mean) have no location and are left out.
pub fn read_ecmwf83(levels_path: &Path, meta_path: &Path) -> Result<ProfileSet, InputError> {
    let t = CsvTable::read(levels_path)?;
    let m = CsvTable::read(meta_path)?;
    let groups = group_by_profile(&t, "profile")?;
    let gases = ["H2O", "CO2", "O3", "N2O", "CO", "CH4"];
    let mut set = ProfileSet {
        name: "ecmwf83".into(),
        members: Vec::new(),
        notes: vec![
            "ECMWF 83 diverse profiles (Matricardi 2008, ECMWF Tech. Memo. 564), 80 located profiles; \
             gases read as ppmv per dry air, converted to moist-air mole fractions; altitudes \
             hydrostatic above a surface at 0 m"
                .into(),
        ],
    };
    let c_class = m.column("lat_class")?;
    for (line, f) in m.rows() {
        if f[c_class] == "envelope_or_mean" {
            continue;
        }
        let id: i64 = f[m.column("profile")?]
            .parse()
            .map_err(|_| InputError::at(meta_path, line, "profile", "not an integer"))?;
        let (y, mo, d) = (
            num(&m, line, f, "year")?,
            num(&m, line, f, "month")?,
            num(&m, line, f, "day")?,
        );
        let meta = ProfileMeta {
            id: id.to_string(),
            latitude_deg: num_in(&m, line, f, "lat_deg", LATITUDE_DEG)?,
            longitude_deg: num_in(&m, line, f, "lon_deg", LONGITUDE_DEG)?,
            time_utc: format!("{:04}-{:02}-{:02}", y as i64, mo as i64, d as i64),
            weight: None,
        };
        let ps = num_in(&m, line, f, "psurf_hPa", PRESSURE_PA.scaled(1e-2))? * 100.0;
        let rows = groups.get(&id).ok_or_else(|| {
            InputError::at(
                meta_path,
                line,
                "profile",
                format!("profile {id} has no levels in {}", levels_path.display()),
            )
        })?;
        let mut levels = Vec::with_capacity(rows.len());
        for (l, r) in rows {
            let mut v = Vec::with_capacity(gases.len());
            for g in gases {
                v.push(num_in(&t, *l, r, &format!("{g}_ppmv"), FRACTION.scaled(1e6))? * 1e-6);
            }
            levels.push((
                *l,
                num_in(&t, *l, r, "p_hPa", PRESSURE_PA.scaled(1e-2))? * 100.0,
                num_in(&t, *l, r, "T_K", TEMPERATURE_K)?,
                v,
            ));
        }
        let (p, temp, v) = cut_at_surface(levels_path, id, levels, ps)?;
        // Per dry air → moist air.
        let x_w: Vec<f64> = v[0].iter().map(|r| vmr_from_dry_mole_ratio(*r)).collect();
        let mut gas_profiles = vec![GasProfile {
            name: "H2O".into(),
            vmr: x_w.clone(),
        }];
        for (g, r) in gases.iter().zip(&v).skip(1) {
            gas_profiles.push(GasProfile {
                name: g.to_string(),
                vmr: r.iter().zip(&x_w).map(|(r, x)| r * (1.0 - x)).collect(),
            });
        }
        set.members.push(finish(
            levels_path,
            rows[0].0,
            format!("ecmwf83 #{id}"),
            meta,
            p,
            temp,
            gas_profiles,
        )?);
    }
    Ok(set)
}

/// Read the ECMWF 52-profile set (Chevallier 2002) as saved in `../shared/data/profiles`
/// (`ecmwf52_chevallier_101L.csv` and `_meta.csv`): T, specific humidity and ozone mass mixing
/// ratio (kg/kg of moist air). Profiles 50–52 (dry test, moist test, mean) have no location and
/// are left out. The set has no CO2: add it with [`Profile::set_gas`].
pub fn read_ecmwf52(levels_path: &Path, meta_path: &Path) -> Result<ProfileSet, InputError> {
    let t = CsvTable::read(levels_path)?;
    let m = CsvTable::read(meta_path)?;
    let groups = group_by_profile(&t, "profile")?;
    let mut set = ProfileSet {
        name: "ecmwf52".into(),
        members: Vec::new(),
        notes: vec![
            "ECMWF 52 diverse profiles (Chevallier 2002); q and O3 mass mixing ratios (kg/kg moist \
             air) converted to mole fractions; altitudes hydrostatic above a surface at 0 m"
                .into(),
        ],
    };
    let c_class = m.column("lat_class")?;
    let m_o3 = molar_mass_kg_per_mol("O3").expect("known gas");
    for (line, f) in m.rows() {
        if f[c_class] == "test_or_mean" {
            continue;
        }
        let id: i64 = f[m.column("profile")?]
            .parse()
            .map_err(|_| InputError::at(meta_path, line, "profile", "not an integer"))?;
        let dt = &f[m.column("datetime_yyyymmddhh")?];
        if dt.len() != 10 || !dt.bytes().all(|b| b.is_ascii_digit()) {
            return Err(InputError::at(
                meta_path,
                line,
                "datetime_yyyymmddhh",
                format!("`{dt}` is not yyyymmddhh"),
            ));
        }
        let meta = ProfileMeta {
            id: id.to_string(),
            latitude_deg: num_in(&m, line, f, "lat_deg", LATITUDE_DEG)?,
            longitude_deg: num_in(&m, line, f, "lon_deg", LONGITUDE_DEG)?,
            time_utc: format!(
                "{}-{}-{}T{}:00Z",
                &dt[0..4],
                &dt[4..6],
                &dt[6..8],
                &dt[8..10]
            ),
            weight: None,
        };
        let ps = num_in(&m, line, f, "psurf_hPa", PRESSURE_PA.scaled(1e-2))? * 100.0;
        let rows = groups.get(&id).ok_or_else(|| {
            InputError::at(
                meta_path,
                line,
                "profile",
                format!("profile {id} has no levels"),
            )
        })?;
        let mut levels = Vec::with_capacity(rows.len());
        for (l, r) in rows {
            let q = num_in(&t, *l, r, "q_kgkg", FRACTION)?;
            let o3 = num_in(&t, *l, r, "O3_kgkg", FRACTION)?;
            levels.push((
                *l,
                num_in(&t, *l, r, "p_hPa", PRESSURE_PA.scaled(1e-2))? * 100.0,
                num_in(&t, *l, r, "T_K", TEMPERATURE_K)?,
                vec![q, o3],
            ));
        }
        let (p, temp, v) = cut_at_surface(levels_path, id, levels, ps)?;
        let x_w: Vec<f64> = v[0]
            .iter()
            .map(|q| vmr_from_specific_humidity(*q))
            .collect();
        // Ozone: x = m_O3 · M_air(moist) / M_O3.
        let x_o3: Vec<f64> = v[1]
            .iter()
            .zip(&x_w)
            .map(|(mo3, xw)| mo3 * moist_air_molar_mass_kg_per_mol(*xw) / m_o3)
            .collect();
        let gases = vec![
            GasProfile {
                name: "H2O".into(),
                vmr: x_w,
            },
            GasProfile {
                name: "O3".into(),
                vmr: x_o3,
            },
        ];
        set.members.push(finish(
            levels_path,
            rows[0].0,
            format!("ecmwf52 #{id}"),
            meta,
            p,
            temp,
            gases,
        )?);
    }
    Ok(set)
}

/// The global-mean gases of the RFMIP meta header
/// (`# present-day global means (expt 0): CO2=397.547 ppm; CH4=1831.47 ppb; ...`): (gas, mole
/// fraction per dry air).
pub fn rfmip_global_means(meta: &CsvTable) -> Result<Vec<(String, f64)>, InputError> {
    let index = meta
        .comments
        .iter()
        .position(|c| c.contains("global means"))
        .ok_or_else(|| {
            InputError::file(
                meta.path(),
                "no `global means` comment line with the gas amounts",
            )
        })?;
    let (line, line_no) = (&meta.comments[index], meta.comment_line(index));
    let body = line.split_once(':').map(|(_, b)| b).unwrap_or("");
    let mut out = Vec::new();
    for item in body.split(';') {
        let item = item.trim();
        let Some((gas, rest)) = item.split_once('=') else {
            continue;
        };
        let mut words = rest.split_whitespace();
        let value: f64 = words.next().and_then(|v| v.parse().ok()).ok_or_else(|| {
            InputError::at(
                meta.path(),
                line_no,
                gas.trim(),
                format!("cannot read `{item}`"),
            )
        })?;
        let scale = match words.next() {
            Some("ppm") => 1e-6,
            Some("ppb") => 1e-9,
            None | Some("(stored") => 1.0,
            Some(u) => {
                return Err(InputError::at(
                    meta.path(),
                    line_no,
                    gas.trim(),
                    format!("unknown unit `{u}`"),
                ));
            }
        };
        let gas = gas.trim();
        // A mole fraction, checked here where it is read: later checks of the levels would
        // blame the levels file for it.
        let fraction = value * scale;
        if !(fraction.is_finite() && (0.0..=1.0).contains(&fraction)) {
            return Err(InputError::at(
                meta.path(),
                line_no,
                gas,
                format!("`{item}` is a mole fraction of {fraction:e}, not in [0, 1]"),
            ));
        }
        if gas != "N2" {
            out.push((gas.to_string(), fraction));
        }
    }
    Ok(out)
}

/// Read the RFMIP-IRF 100-site set (Pincus et al. 2016) as saved in `../shared/data/profiles`
/// (`rfmip_era_interim_100sites_layers.csv` and `_meta.csv`).
///
/// Levels are the 61 layer edges with their temperatures; the layer H2O and O3 are interpolated
/// to the edges linearly in ln p between layer pressures (held constant beyond the outermost
/// layer pressures), which keeps their columns within ~1 %. Mole fractions are read per dry air
/// (RRTMGP's convention for these files) and converted to moist air; the well-mixed gases take
/// the global means of the meta header at every level. The profile weight is kept.
pub fn read_rfmip(layers_path: &Path, meta_path: &Path) -> Result<ProfileSet, InputError> {
    let t = CsvTable::read(layers_path)?;
    let m = CsvTable::read(meta_path)?;
    let means = rfmip_global_means(&m)?;
    let groups = group_by_profile(&t, "site")?;
    let mut set = ProfileSet {
        name: "rfmip".into(),
        members: Vec::new(),
        notes: vec![format!(
            "RFMIP-IRF 100 sites (Pincus et al. 2016, GMD 9:3447), ERA-Interim 2014, present day; \
             levels = layer edges; H2O, O3 per dry air → moist; well-mixed gases from the global means ({})",
            means
                .iter()
                .map(|(g, v)| format!("{g} {v:e}"))
                .collect::<Vec<_>>()
                .join(", ")
        )],
    };
    let mut seen = std::collections::HashMap::new();
    for (line, f) in m.rows() {
        let id: i64 = f[m.column("site")?]
            .parse()
            .map_err(|_| InputError::at(meta_path, line, "site", "not an integer"))?;
        if let Some(first) = seen.insert(id, line) {
            return Err(InputError::at(
                meta_path,
                line,
                "site",
                format!("site {id} is given twice (first at line {first})"),
            ));
        }
        let day = num(&m, line, f, "day_of_2014")?;
        let meta = ProfileMeta {
            id: id.to_string(),
            latitude_deg: num_in(&m, line, f, "lat_deg", LATITUDE_DEG)?,
            longitude_deg: num_in(&m, line, f, "lon_deg", LONGITUDE_DEG)?,
            time_utc: time_from_days_2014(day),
            weight: Some(num_in(
                &m,
                line,
                f,
                "profile_weight",
                Bounds::closed(0.0, 1e12),
            )?),
        };
        let rows = groups.get(&id).ok_or_else(|| {
            InputError::at(meta_path, line, "site", format!("site {id} has no layers"))
        })?;
        // Layers bottom-up.
        let mut layers = Vec::with_capacity(rows.len());
        for (l, r) in rows {
            layers.push((
                *l,
                num_in(&t, *l, r, "p_layer_Pa", PRESSURE_PA)?,
                num_in(&t, *l, r, "H2O_molefrac", FRACTION)?,
                num_in(&t, *l, r, "O3_molefrac", FRACTION)?,
                num_in(&t, *l, r, "p_bottom_edge_Pa", PRESSURE_PA)?,
                num_in(&t, *l, r, "T_bottom_edge_K", TEMPERATURE_K)?,
                num_in(&t, *l, r, "p_top_edge_Pa", PRESSURE_PA)?,
                num_in(&t, *l, r, "T_top_edge_K", TEMPERATURE_K)?,
            ));
        }
        layers.sort_by(|a, b| b.1.total_cmp(&a.1));
        for w in layers.windows(2) {
            if (w[0].6 - w[1].4).abs() > 1e-6 * w[0].6 {
                return Err(InputError::at(
                    layers_path,
                    w[1].0,
                    "p_bottom_edge_Pa",
                    format!(
                        "site {id}: layer edges do not join ({} vs {} Pa)",
                        w[0].6, w[1].4
                    ),
                ));
            }
        }
        let mut p = vec![layers[0].4];
        let mut temp = vec![layers[0].5];
        for l in &layers {
            p.push(l.6);
            temp.push(l.7);
        }
        let lnpl: Vec<f64> = layers.iter().map(|l| -l.1.ln()).collect();
        let at_edges = |v: &dyn Fn(usize) -> f64| -> Vec<f64> {
            p.iter()
                .map(|pe| {
                    let s = -pe.ln();
                    let n = lnpl.len();
                    if s <= lnpl[0] {
                        return v(0);
                    }
                    if s >= lnpl[n - 1] {
                        return v(n - 1);
                    }
                    let k = lnpl.partition_point(|x| *x <= s) - 1;
                    let w = (s - lnpl[k]) / (lnpl[k + 1] - lnpl[k]);
                    v(k) + w * (v(k + 1) - v(k))
                })
                .collect()
        };
        let r_w = at_edges(&|k| layers[k].2);
        let r_o3 = at_edges(&|k| layers[k].3);
        let x_w: Vec<f64> = r_w.iter().map(|r| vmr_from_dry_mole_ratio(*r)).collect();
        let dry = |r: f64, k: usize| r * (1.0 - x_w[k]);
        let mut gases = vec![
            GasProfile {
                name: "H2O".into(),
                vmr: x_w.clone(),
            },
            GasProfile {
                name: "O3".into(),
                vmr: r_o3.iter().enumerate().map(|(k, r)| dry(*r, k)).collect(),
            },
        ];
        for (g, v) in &means {
            gases.push(GasProfile {
                name: g.clone(),
                vmr: (0..p.len()).map(|k| dry(*v, k)).collect(),
            });
        }
        set.members.push(finish(
            layers_path,
            rows[0].0,
            format!("rfmip #{id}"),
            meta,
            p,
            temp,
            gases,
        )?);
    }
    Ok(set)
}

/// ISO 8601 time from days since 2014-01-01T00:00Z (RFMIP's `day_of_2014`), to the minute.
fn time_from_days_2014(days: f64) -> String {
    const MONTH_DAYS: [u32; 12] = [31, 28, 31, 30, 31, 30, 31, 31, 30, 31, 30, 31];
    let minutes = (days * 1440.0).round() as i64;
    let (mut d, rem) = (minutes.div_euclid(1440), minutes.rem_euclid(1440));
    let mut month = 0;
    while month < 11 && d >= MONTH_DAYS[month] as i64 {
        d -= MONTH_DAYS[month] as i64;
        month += 1;
    }
    format!(
        "2014-{:02}-{:02}T{:02}:{:02}Z",
        month + 1,
        d + 1,
        rem / 60,
        rem % 60
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The meta header's global means are mole fractions in [0, 1], refused where they are
    /// read: at the meta file, the comment's line and the gas (fuzz finding F7: `O2=2.09e29`
    /// was blamed on the levels file).
    #[test]
    fn global_means_are_checked_where_they_are_read() {
        let header = "# RFMIP-IRF test\n# present-day global means (expt 0): CO2=397.547 ppm; \
                      CH4=1831.47 ppb; O2=GAS; N2=0.781\nsite,lat_deg\n0,1.0\n";
        let ok = CsvTable::parse("meta.csv", &header.replace("GAS", "0.209")).unwrap();
        let means = rfmip_global_means(&ok).unwrap();
        let co2 = means.iter().find(|(g, _)| g == "CO2").unwrap().1;
        assert!((co2 - 397.547e-6).abs() < 1e-15, "{co2}");
        for bad in ["2.09e29", "-0.1", "inf", "NaN"] {
            let t = CsvTable::parse("meta.csv", &header.replace("GAS", bad)).unwrap();
            let e = rfmip_global_means(&t).unwrap_err().to_string();
            assert!(e.starts_with("meta.csv:2: `O2`"), "{bad}: {e}");
        }
    }

    #[test]
    fn days_since_2014() {
        assert_eq!(time_from_days_2014(4.25), "2014-01-05T06:00Z");
        assert_eq!(time_from_days_2014(31.0), "2014-02-01T00:00Z");
        assert_eq!(time_from_days_2014(364.5), "2014-12-31T12:00Z");
    }
}
