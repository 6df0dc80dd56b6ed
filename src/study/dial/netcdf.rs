//! A study's tables as CF NetCDF (`profiles.nc`, `summary.nc`).

use super::*;

/// `profiles.nc` beside `profiles.csv`.
pub const PROFILES_NC: &str = "profiles.nc";
/// `summary.nc` beside `summary.csv`.
pub const SUMMARY_NC: &str = "summary.nc";

/// Where each record of a group (a profile, a class) goes: the line pairs in order of first
/// appearance, and each record's (pair, retrieval) index, the retrieval index counting the
/// pair's records in order (IPDA, then the DIAL cells: the same for every profile, since every
/// profile runs the same scene and pairs). The method of each retrieval index, checked to be
/// the same wherever it occurs.
struct Layout {
    pairs: Vec<String>,
    methods: Vec<Method>,
}

impl Layout {
    fn of<'r>(
        groups: impl Iterator<Item = Vec<(&'r str, Method)>>,
    ) -> Result<(Layout, Places), crate::netcdf::NetcdfError> {
        let mut layout = Layout {
            pairs: Vec::new(),
            methods: Vec::new(),
        };
        let mut places = Vec::new();
        for records in groups {
            let mut counts: Vec<usize> = Vec::new();
            let mut at = Vec::with_capacity(records.len());
            for (pair, method) in records {
                let p = match layout.pairs.iter().position(|x| x == pair) {
                    Some(p) => p,
                    None => {
                        layout.pairs.push(pair.to_string());
                        layout.pairs.len() - 1
                    }
                };
                counts.resize(layout.pairs.len(), 0);
                let k = counts[p];
                counts[p] += 1;
                match layout.methods.get(k) {
                    Some(m) if *m != method => {
                        return Err(crate::netcdf::NetcdfError::Layout(format!(
                            "retrieval {k} of pair {pair} is {} in one group and {} in another",
                            method.label(),
                            m.label()
                        )));
                    }
                    Some(_) => {}
                    None => layout.methods.push(method),
                }
                at.push((p, k));
            }
            places.push(at);
        }
        Ok((layout, places))
    }

    fn cells(&self) -> usize {
        self.pairs.len() * self.methods.len()
    }

    /// The coordinates `pair` and `method`, on dimensions `pair` and `retrieval`.
    fn coordinates(&self, nc: &mut crate::netcdf::Dataset) {
        nc.dim("pair", self.pairs.len());
        nc.dim("retrieval", self.methods.len());
        nc.text("pair", "pair", &self.pairs)
            .attrs([("long_name", "on-line/off-line pair (on/off)")]);
        let methods: Vec<String> = self.methods.iter().map(|m| m.label().to_string()).collect();
        nc.text("method", "retrieval", &methods).attrs([(
            "long_name",
            "retrieved quantity of the pair: ipda (column to the hard target) or dial (a cell), in the order of the CSV rows",
        )]);
    }
}

/// Each group's records' (pair, retrieval) indices, in the records' order.
type Places = Vec<Vec<(usize, usize)>>;

/// The dimensions of a study's arrays: the group (`profile` or `class`), `pair`, `retrieval`.
fn dims(group: &str) -> [&str; 3] {
    [group, "pair", "retrieval"]
}

/// A variable over (group, pair, retrieval) from one value per record, `_FillValue` where a
/// group has no such record.
#[allow(clippy::too_many_arguments)]
fn cube(
    nc: &mut crate::netcdf::Dataset,
    group: &str,
    layout: &Layout,
    places: &[Vec<(usize, usize)>],
    values: &[Vec<f64>],
    name: &str,
    long_name: &str,
    units: &str,
    coordinates: &str,
) {
    let (n_pair, n_ret) = (layout.pairs.len(), layout.methods.len());
    let mut v = vec![f64::NAN; places.len() * layout.cells()];
    for (g, (at, x)) in places.iter().zip(values).enumerate() {
        for (&(p, k), &x) in at.iter().zip(x) {
            v[(g * n_pair + p) * n_ret + k] = x;
        }
    }
    let var = nc
        .f64(name, &dims(group), v)
        .attrs([("long_name", long_name), ("units", units)])
        .fill();
    if !coordinates.is_empty() {
        var.attrs([("coordinates", coordinates)]);
    }
}

/// The altitude interval of every record: `altitude_bottom_m` and `altitude_top_m` over
/// (group, pair, retrieval), auxiliary coordinates of the values.
fn altitudes(
    nc: &mut crate::netcdf::Dataset,
    group: &str,
    layout: &Layout,
    places: &[Vec<(usize, usize)>],
    intervals: &[Vec<(f64, f64)>],
) {
    let bottom: Vec<Vec<f64>> = intervals
        .iter()
        .map(|v| v.iter().map(|a| a.0).collect())
        .collect();
    let top: Vec<Vec<f64>> = intervals
        .iter()
        .map(|v| v.iter().map(|a| a.1).collect())
        .collect();
    let (n_pair, n_ret) = (layout.pairs.len(), layout.methods.len());
    for (name, long_name, x) in [
        (
            "altitude_bottom_m",
            "altitude of the bottom of the column or cell",
            bottom,
        ),
        (
            "altitude_top_m",
            "altitude of the top of the column or cell",
            top,
        ),
    ] {
        let mut v = vec![f64::NAN; places.len() * layout.cells()];
        for (g, (at, x)) in places.iter().zip(&x).enumerate() {
            for (&(p, k), &x) in at.iter().zip(x) {
                v[(g * n_pair + p) * n_ret + k] = x;
            }
        }
        nc.f64(name, &dims(group), v)
            .attrs([
                ("long_name", long_name),
                ("standard_name", "altitude"),
                ("units", "m"),
                ("positive", "up"),
            ])
            .fill();
    }
}

/// The records of the profiles that ran as the CF NetCDF data set of `profiles.nc`: the
/// numbers of `profiles.csv` at full precision on the dimensions (`profile`, `pair`,
/// `retrieval`): `profile` the profiles that ran, in the set's order, with their ids
/// (`profile`) and latitude class (`class`) as coordinates; `pair` the line pairs by name;
/// `retrieval` each pair's retrieved quantities in the CSV's order (IPDA, then the DIAL
/// cells), with `method` as coordinate and the altitude interval of each value as auxiliary
/// coordinates. Mixing ratios in ppm have the units `1e-6` (UDUNITS, CF-1.8 §3.1). An error
/// when no profile has records. Without global attributes: the caller adds the scene's, seed
/// and set ([`crate::products::dial::profiles_nc`]).
pub fn profiles_dataset(
    outcomes: &[ProfileOutcome],
) -> Result<crate::netcdf::Dataset, crate::netcdf::NetcdfError> {
    use crate::netcdf::{Dataset, NetcdfError};
    let ran: Vec<(&ProfileOutcome, &Vec<Record>)> = outcomes
        .iter()
        .filter_map(|o| o.records.as_ref().ok().map(|r| (o, r)))
        .filter(|(_, r)| !r.is_empty())
        .collect();
    if ran.is_empty() {
        return Err(NetcdfError::Layout("a study without records".into()));
    }
    let (layout, places) = Layout::of(
        ran.iter()
            .map(|(_, rs)| rs.iter().map(|r| (r.pair.as_str(), r.method)).collect()),
    )?;
    let mut nc = Dataset::default();
    nc.dim("profile", ran.len());
    let ids: Vec<String> = ran.iter().map(|(o, _)| o.id.clone()).collect();
    nc.text("profile", "profile", &ids)
        .attrs([("long_name", "profile id in its set")]);
    let classes: Vec<String> = ran.iter().map(|(o, _)| o.class.to_string()).collect();
    nc.text("class", "profile", &classes)
        .attrs([("long_name", "latitude class of the profile")]);
    layout.coordinates(&mut nc);
    let intervals: Vec<Vec<(f64, f64)>> = ran
        .iter()
        .map(|(_, rs)| rs.iter().map(|r| r.altitude_m).collect())
        .collect();
    altitudes(&mut nc, "profile", &layout, &places, &intervals);
    let coordinates = "class method altitude_bottom_m altitude_top_m";
    let column = |f: &dyn Fn(&Record) -> f64| -> Vec<Vec<f64>> {
        ran.iter()
            .map(|(_, rs)| rs.iter().map(f).collect())
            .collect()
    };
    let values: [(&str, &str, Vec<Vec<f64>>); 6] = [
        (
            "truth_ppm",
            "true CO2 dry-air mole fraction of the profile",
            column(&|r| r.truth_ppm),
        ),
        (
            "retrieved_ppm",
            "CO2 dry-air mole fraction retrieved from noise-free signals with class-mean virtual cross-sections",
            column(&|r| r.retrieved_ppm),
        ),
        (
            "error_ppm",
            "retrieved_ppm - truth_ppm",
            column(&Record::error_ppm),
        ),
        (
            "retrieved_noisy_ppm",
            "CO2 dry-air mole fraction retrieved from one noisy averaged measurement",
            column(&|r| r.retrieved_noisy_ppm),
        ),
        (
            "error_noisy_ppm",
            "retrieved_noisy_ppm - truth_ppm",
            column(&Record::error_noisy_ppm),
        ),
        (
            "retrieved_own_profile_ppm",
            "CO2 dry-air mole fraction retrieved from noise-free signals with the profile's own state as reference",
            column(&|r| r.retrieved_own_ppm),
        ),
    ];
    for (name, long_name, v) in values {
        cube(
            &mut nc,
            "profile",
            &layout,
            &places,
            &v,
            name,
            long_name,
            "1e-6",
            coordinates,
        );
    }
    for (j, src) in Source::ALL.iter().enumerate() {
        let v = column(&|r| r.budget_ppm[j]);
        cube(
            &mut nc,
            "profile",
            &layout,
            &places,
            &v,
            src.column(),
            src.long_name(),
            "1e-6",
            coordinates,
        );
    }
    nc.check()?;
    Ok(nc)
}

/// The statistics as the CF NetCDF data set of `summary.nc`: the numbers of `summary.csv`
/// at full precision on the dimensions (`class`, `pair`, `retrieval`): `class` the latitude
/// classes (and `all`) by name, `pair` and `retrieval` as in `profiles.nc`
/// ([`profiles_dataset`]). An error when there are no rows. Without global attributes
/// ([`crate::products::dial::summary_nc`]).
pub fn summary_dataset(
    summaries: &[Summary],
) -> Result<crate::netcdf::Dataset, crate::netcdf::NetcdfError> {
    use crate::netcdf::{Dataset, NetcdfError};
    // The summaries come class by class, each class's rows in the records' order.
    let mut classes: Vec<String> = Vec::new();
    let mut groups: Vec<Vec<&Summary>> = Vec::new();
    for m in summaries {
        match classes.iter().position(|c| *c == m.class) {
            Some(c) => groups[c].push(m),
            None => {
                classes.push(m.class.clone());
                groups.push(vec![m]);
            }
        }
    }
    if groups.is_empty() {
        return Err(NetcdfError::Layout("a summary without rows".into()));
    }
    let (layout, places) = Layout::of(
        groups
            .iter()
            .map(|ms| ms.iter().map(|m| (m.pair.as_str(), m.method)).collect()),
    )?;
    let mut nc = Dataset::default();
    nc.dim("class", classes.len());
    nc.text("class", "class", &classes)
        .attrs([("long_name", "latitude class, or all")]);
    layout.coordinates(&mut nc);
    let intervals: Vec<Vec<(f64, f64)>> = groups
        .iter()
        .map(|ms| ms.iter().map(|m| m.altitude_m).collect())
        .collect();
    altitudes(&mut nc, "class", &layout, &places, &intervals);
    let coordinates = "method altitude_bottom_m altitude_top_m";
    let column = |f: &dyn Fn(&Summary) -> f64| -> Vec<Vec<f64>> {
        groups
            .iter()
            .map(|ms| ms.iter().map(|m| f(m)).collect())
            .collect()
    };
    let values: [(&str, &str, &str, Vec<Vec<f64>>); 11] = [
        (
            "profiles",
            "profiles in the group (failed ones excluded)",
            "1",
            column(&|m| m.profiles as f64),
        ),
        (
            "retrieved_profiles",
            "profiles whose noise-free values could all be computed (the members of bias_ppm, sd_ppm and the budget; fewer than profiles only from Monte Carlo returns with windows that hold no energy)",
            "1",
            column(&|m| m.retrieved_profiles as f64),
        ),
        (
            "noisy_profiles",
            "of the retrieved_profiles, those whose noisy measurement could be retrieved (the members of noisy_bias_ppm, noisy_sd_ppm and noise_ratio)",
            "1",
            column(&|m| m.noisy_profiles as f64),
        ),
        (
            "truth_mean_ppm",
            "mean true CO2 dry-air mole fraction",
            "1e-6",
            column(&|m| m.truth_mean_ppm),
        ),
        (
            "bias_ppm",
            "mean of retrieved - truth, noise-free",
            "1e-6",
            column(&|m| m.bias_ppm),
        ),
        (
            "sd_ppm",
            "standard deviation of retrieved - truth, noise-free",
            "1e-6",
            column(&|m| m.sd_ppm),
        ),
        (
            "noisy_bias_ppm",
            "mean of retrieved - truth, one noisy measurement per profile",
            "1e-6",
            column(&|m| m.noisy_bias_ppm),
        ),
        (
            "noisy_sd_ppm",
            "standard deviation of retrieved - truth, one noisy measurement per profile",
            "1e-6",
            column(&|m| m.noisy_sd_ppm),
        ),
        (
            "random_error_rms_ppm",
            "rms of the analytic random error of one averaged measurement",
            "1e-6",
            column(&|m| m.sources[0].rms_ppm),
        ),
        (
            "noise_ratio",
            "standard deviation of noisy - noise-free over the rms analytic random error",
            "1",
            column(&|m| m.noise_ratio),
        ),
        (
            "total_budget_ppm",
            "root-sum-square of every budget row's rms",
            "1e-6",
            column(&|m| m.total_ppm),
        ),
    ];
    for (name, long_name, units, v) in values {
        cube(
            &mut nc,
            "class",
            &layout,
            &places,
            &v,
            name,
            long_name,
            units,
            coordinates,
        );
    }
    nc.check()?;
    Ok(nc)
}
