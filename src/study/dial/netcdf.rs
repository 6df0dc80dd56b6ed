//! A study's tables as CF NetCDF (`profiles.nc`, `summary.nc`).

use super::*;

/// `profiles.nc` beside `profiles.csv`.
pub const PROFILES_NC: &str = "profiles.nc";
/// `summary.nc` beside `summary.csv`.
pub const SUMMARY_NC: &str = "summary.nc";

/// The records of the profiles that ran as the CF NetCDF data set of `profiles.nc`: the columns of
/// `profiles.csv` at full precision over the dimension `row`, one row per profile, line pair
/// and retrieved quantity, in the CSV's order ([`crate::netcdf::table_file`]). Mixing ratios
/// in ppm have the units `1e-6` (UDUNITS, CF-1.8 §3.1). An error when no profile has records.
pub fn profiles_dataset(
    outcomes: &[ProfileOutcome],
    title: &str,
    history: &str,
) -> Result<crate::netcdf::Dataset, crate::netcdf::NetcdfError> {
    use crate::netcdf::{Column, ColumnValues::Number, ColumnValues::Text, table_dataset};
    let rows: Vec<(&ProfileOutcome, &Record)> = outcomes
        .iter()
        .filter_map(|o| o.records.as_ref().ok().map(|r| (o, r)))
        .flat_map(|(o, records)| records.iter().map(move |r| (o, r)))
        .collect();
    let text = |name, long_name, f: &dyn Fn(&ProfileOutcome, &Record) -> String| Column {
        name,
        long_name,
        units: None,
        values: Text(rows.iter().map(|(o, r)| f(o, r)).collect()),
    };
    let num = |name, long_name, units, f: &dyn Fn(&Record) -> f64| Column {
        name,
        long_name,
        units: Some(units),
        values: Number(rows.iter().map(|(_, r)| f(r)).collect()),
    };
    let mut columns = vec![
        text("profile_id", "profile id in its set", &|o, _| o.id.clone()),
        text("class", "latitude class", &|o, _| o.class.to_string()),
        text("pair", "on-line/off-line pair", &|_, r| r.pair.clone()),
        text(
            "method",
            "retrieved quantity: ipda (column to the hard target) or dial (a cell)",
            &|_, r| r.method.label().to_string(),
        ),
        num(
            "altitude_bottom_m",
            "bottom of the altitude interval",
            "m",
            &|r| r.altitude_m.0,
        ),
        num(
            "altitude_top_m",
            "top of the altitude interval",
            "m",
            &|r| r.altitude_m.1,
        ),
        num(
            "truth_ppm",
            "true CO2 dry-air mole fraction of the profile",
            "1e-6",
            &|r| r.truth_ppm,
        ),
        num(
            "retrieved_ppm",
            "CO2 dry-air mole fraction retrieved from noise-free signals with class-mean virtual cross-sections",
            "1e-6",
            &|r| r.retrieved_ppm,
        ),
        num(
            "error_ppm",
            "retrieved_ppm - truth_ppm",
            "1e-6",
            &Record::error_ppm,
        ),
        num(
            "retrieved_noisy_ppm",
            "CO2 dry-air mole fraction retrieved from one noisy averaged measurement",
            "1e-6",
            &|r| r.retrieved_noisy_ppm,
        ),
        num(
            "error_noisy_ppm",
            "retrieved_noisy_ppm - truth_ppm",
            "1e-6",
            &Record::error_noisy_ppm,
        ),
        num(
            "retrieved_own_profile_ppm",
            "CO2 dry-air mole fraction retrieved from noise-free signals with the profile's own state as reference",
            "1e-6",
            &|r| r.retrieved_own_ppm,
        ),
    ];
    for (j, src) in Source::ALL.iter().enumerate() {
        columns.push(num(src.column(), src.long_name(), "1e-6", &|r| {
            r.budget_ppm[j]
        }));
    }
    table_dataset("row", &columns, title, history)
}

/// The statistics as the CF NetCDF data set of `summary.nc`: the columns of `summary.csv` at full
/// precision over the dimension `row`, one row per class (and `all`), line pair and retrieved
/// quantity ([`crate::netcdf::table_file`]). An error when there are no rows.
pub fn summary_dataset(
    summaries: &[Summary],
    title: &str,
    history: &str,
) -> Result<crate::netcdf::Dataset, crate::netcdf::NetcdfError> {
    use crate::netcdf::{Column, ColumnValues::Number, ColumnValues::Text, table_dataset};
    let text = |name, long_name, f: fn(&Summary) -> String| Column {
        name,
        long_name,
        units: None,
        values: Text(summaries.iter().map(f).collect()),
    };
    let num = |name, long_name, units, f: fn(&Summary) -> f64| Column {
        name,
        long_name,
        units: Some(units),
        values: Number(summaries.iter().map(f).collect()),
    };
    let columns = [
        text("class", "latitude class, or all", |m| m.class.clone()),
        text("pair", "on-line/off-line pair", |m| m.pair.clone()),
        text(
            "method",
            "retrieved quantity: ipda (column to the hard target) or dial (a cell)",
            |m| m.method.label().to_string(),
        ),
        num(
            "altitude_bottom_m",
            "bottom of the altitude interval",
            "m",
            |m| m.altitude_m.0,
        ),
        num("altitude_top_m", "top of the altitude interval", "m", |m| {
            m.altitude_m.1
        }),
        num(
            "profiles",
            "profiles in the group (failed ones excluded)",
            "1",
            |m| m.profiles as f64,
        ),
        num(
            "retrieved_profiles",
            "profiles whose noise-free values could all be computed (the members of bias_ppm, sd_ppm and the budget; fewer than profiles only from Monte Carlo returns with windows that hold no energy)",
            "1",
            |m| m.retrieved_profiles as f64,
        ),
        num(
            "noisy_profiles",
            "of the retrieved_profiles, those whose noisy measurement could be retrieved (the members of noisy_bias_ppm, noisy_sd_ppm and noise_ratio)",
            "1",
            |m| m.noisy_profiles as f64,
        ),
        num(
            "truth_mean_ppm",
            "mean true CO2 dry-air mole fraction",
            "1e-6",
            |m| m.truth_mean_ppm,
        ),
        num(
            "bias_ppm",
            "mean of retrieved - truth, noise-free",
            "1e-6",
            |m| m.bias_ppm,
        ),
        num(
            "sd_ppm",
            "standard deviation of retrieved - truth, noise-free",
            "1e-6",
            |m| m.sd_ppm,
        ),
        num(
            "noisy_bias_ppm",
            "mean of retrieved - truth, one noisy measurement per profile",
            "1e-6",
            |m| m.noisy_bias_ppm,
        ),
        num(
            "noisy_sd_ppm",
            "standard deviation of retrieved - truth, one noisy measurement per profile",
            "1e-6",
            |m| m.noisy_sd_ppm,
        ),
        num(
            "random_error_rms_ppm",
            "rms of the analytic random error of one averaged measurement",
            "1e-6",
            |m| m.sources[0].rms_ppm,
        ),
        num(
            "noise_ratio",
            "standard deviation of noisy - noise-free over the rms analytic random error",
            "1",
            |m| m.noise_ratio,
        ),
        num(
            "total_budget_ppm",
            "root-sum-square of every budget row's rms",
            "1e-6",
            |m| m.total_ppm,
        ),
    ];
    table_dataset("row", &columns, title, history)
}
