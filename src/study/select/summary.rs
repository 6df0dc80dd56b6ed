//! The study's results over the set: error budget, ranking, the CSV and NetCDF tables.

use super::{MemberResult, OnPosition, PositionResult, StudyConfig};

/// The uncertainties of the assumed state and laser frequency that make the total error.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Uncertainties {
    /// Temperature \[K\] (default 1: a good NWP analysis).
    pub temperature_k: f64,
    /// Laser frequency \[MHz\] (default 1).
    pub frequency_mhz: f64,
    /// Surface pressure \[hPa\] (default 1).
    pub surface_pressure_hpa: f64,
    /// Water vapour \[%\] (default 10).
    pub h2o_percent: f64,
}

impl Default for Uncertainties {
    fn default() -> Self {
        Uncertainties {
            temperature_k: 1.0,
            frequency_mhz: 1.0,
            surface_pressure_hpa: 1.0,
            h2o_percent: 10.0,
        }
    }
}

impl Uncertainties {
    /// The systematic contributions \[ppm\]: each sensitivity times its uncertainty in units of
    /// the sensitivity's step (linear in the step): T, frequency, surface pressure, H2O.
    pub fn contributions_ppm(&self, r: &Row) -> [f64; 4] {
        [
            r.dxco2_per_k_ppm * self.temperature_k,
            r.dxco2_per_mhz_ppm * self.frequency_mhz,
            r.dxco2_per_hpa_ppm * self.surface_pressure_hpa,
            r.dxco2_per_10pct_h2o_ppm * self.h2o_percent / 10.0,
        ]
    }

    /// Total expected error \[ppm\]: the root-sum-square of the random error (left out when
    /// NaN, i.e. without a noise model) and the four contributions.
    pub fn total_ppm(&self, r: &Row) -> f64 {
        let sys: f64 = self.contributions_ppm(r).iter().map(|c| c * c).sum();
        let rand = if r.random_error_ppm.is_nan() {
            0.0
        } else {
            r.random_error_ppm.powi(2)
        };
        (sys + rand).sqrt()
    }
}

/// One row of `sensitivities.csv`.
#[derive(Debug, Clone, PartialEq)]
pub struct Row {
    /// Atmosphere, latitude class or profile id.
    pub atmosphere: String,
    /// The on-line position.
    pub position: OnPosition,
    /// The off-line [cm⁻¹].
    pub off_cm1: f64,
    /// Mean one-way DAOD.
    pub daod_one_way: f64,
    /// Mean weighting-function peak \[hPa\].
    pub wf_peak_hpa: f64,
    /// Mean sensitivity to +1 K \[ppm\].
    pub dxco2_per_k_ppm: f64,
    /// Mean sensitivity to +1 MHz \[ppm\].
    pub dxco2_per_mhz_ppm: f64,
    /// Mean sensitivity to an assumed surface pressure +1 hPa \[ppm\].
    pub dxco2_per_hpa_ppm: f64,
    /// Mean sensitivity to +10 % H2O \[ppm\].
    pub dxco2_per_10pct_h2o_ppm: f64,
    /// Mean two-way transmission of the on-line.
    pub t2_on_mean: f64,
    /// Its standard deviation over the members (n − 1; 0 for one member).
    pub t2_on_std: f64,
    /// Mean random error \[ppm\].
    pub random_error_ppm: f64,
    /// Total expected error \[ppm\] ([`Uncertainties::total_ppm`]).
    pub total_error_ppm: f64,
    /// Rank within the atmosphere by total error (1 = smallest).
    pub rank: usize,
    /// Members averaged.
    pub profiles: usize,
}

/// Header of `sensitivities.csv` (the first nine columns are the contract).
pub const CSV_HEADER: &str = "atmosphere,nu_on_cm1,nu_off_cm1,daod_one_way,wf_peak_hpa,dxco2_per_k_ppm,dxco2_per_mhz_ppm,dxco2_per_hpa_ppm,dxco2_per_10pct_h2o_ppm,line,offset_ghz,t2_on_mean,t2_on_std,random_error_ppm,total_error_ppm,rank,profiles";

fn mean_std(v: &[f64]) -> (f64, f64) {
    let n = v.len() as f64;
    let m = v.iter().sum::<f64>() / n;
    let s = if v.len() > 1 {
        (v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (n - 1.0)).sqrt()
    } else {
        0.0
    };
    (m, s)
}

/// Rows of one group of member results (at least one): the mean over members of every quantity
/// per position, positions where the on-line does not absorb more than the off-line (or a
/// sensitivity is not finite) in any member dropped, ranked by total error. Returns the rows in
/// rank order and the indices of the dropped positions.
pub fn summarise(
    atmosphere: &str,
    results: &[&MemberResult],
    cfg: &StudyConfig,
    unc: &Uncertainties,
) -> (Vec<Row>, Vec<usize>) {
    let mut rows = Vec::new();
    let mut dropped = Vec::new();
    if results.is_empty() {
        return (rows, (0..cfg.positions.len()).collect());
    }
    for (i, pos) in cfg.positions.iter().enumerate() {
        let r: Vec<&PositionResult> = results.iter().map(|m| &m.positions[i]).collect();
        let usable = r.iter().all(|p| {
            p.daod_one_way > 0.0
                && [
                    p.dxco2_per_k_ppm,
                    p.dxco2_per_mhz_ppm,
                    p.dxco2_per_hpa_ppm,
                    p.dxco2_per_10pct_h2o_ppm,
                ]
                .iter()
                .all(|v| v.is_finite())
        });
        if !usable {
            dropped.push(i);
            continue;
        }
        let mean =
            |f: fn(&PositionResult) -> f64| mean_std(&r.iter().map(|p| f(p)).collect::<Vec<_>>()).0;
        let (t2_mean, t2_std) = mean_std(&r.iter().map(|p| p.t2_on).collect::<Vec<_>>());
        let mut row = Row {
            atmosphere: atmosphere.to_string(),
            position: pos.clone(),
            off_cm1: cfg.off_cm1,
            daod_one_way: mean(|p| p.daod_one_way),
            wf_peak_hpa: mean(|p| p.wf_peak_hpa),
            dxco2_per_k_ppm: mean(|p| p.dxco2_per_k_ppm),
            dxco2_per_mhz_ppm: mean(|p| p.dxco2_per_mhz_ppm),
            dxco2_per_hpa_ppm: mean(|p| p.dxco2_per_hpa_ppm),
            dxco2_per_10pct_h2o_ppm: mean(|p| p.dxco2_per_10pct_h2o_ppm),
            t2_on_mean: t2_mean,
            t2_on_std: t2_std,
            random_error_ppm: mean(|p| p.random_error_ppm),
            total_error_ppm: f64::NAN,
            rank: 0,
            profiles: results.len(),
        };
        row.total_error_ppm = unc.total_ppm(&row);
        rows.push(row);
    }
    // Stable sort: equal totals keep the position order.
    rows.sort_by(|a, b| a.total_error_ppm.total_cmp(&b.total_error_ppm));
    for (k, r) in rows.iter_mut().enumerate() {
        r.rank = k + 1;
    }
    (rows, dropped)
}

/// The CSV text (header and rows, in the order given).
pub fn to_csv(rows: &[Row]) -> String {
    use std::fmt::Write as _;
    let mut s = String::from(CSV_HEADER);
    s.push('\n');
    for r in rows {
        let _ = writeln!(
            s,
            "{},{:.6},{:.6},{:.6e},{:.2},{:.6e},{:.6e},{:.6e},{:.6e},{},{},{:.6e},{:.6e},{:.6e},{:.6e},{},{}",
            crate::output::csv_field(&r.atmosphere),
            r.position.nu_cm1,
            r.off_cm1,
            r.daod_one_way,
            r.wf_peak_hpa,
            r.dxco2_per_k_ppm,
            r.dxco2_per_mhz_ppm,
            r.dxco2_per_hpa_ppm,
            r.dxco2_per_10pct_h2o_ppm,
            crate::output::csv_field(r.position.line.as_deref().unwrap_or("")),
            if r.position.offset_ghz.is_nan() {
                String::new()
            } else {
                format!("{:.4}", r.position.offset_ghz)
            },
            r.t2_on_mean,
            r.t2_on_std,
            r.random_error_ppm,
            r.total_error_ppm,
            r.rank,
            r.profiles
        );
    }
    s
}

/// The rows as the CF NetCDF data set of `sensitivities.nc`, the columns of `sensitivities.csv` at
/// full precision over the dimension `row` ([`crate::netcdf::table_file`]).
pub fn to_dataset(
    rows: &[Row],
    title: &str,
    history: &str,
) -> Result<crate::netcdf::Dataset, crate::netcdf::NetcdfError> {
    use crate::netcdf::{Column, ColumnValues::Number, ColumnValues::Text, table_dataset};
    let num = |name, long_name, units, f: fn(&Row) -> f64| Column {
        name,
        long_name,
        units: Some(units),
        values: Number(rows.iter().map(f).collect()),
    };
    // UDUNITS: ppm as "1e-6" (CF-1.8 §3.1).
    let columns = [
        Column {
            name: "atmosphere",
            long_name: "atmosphere, latitude class or profile id",
            units: None,
            values: Text(rows.iter().map(|r| r.atmosphere.clone()).collect()),
        },
        num("nu_on_cm1", "on-line vacuum wavenumber", "cm-1", |r| {
            r.position.nu_cm1
        }),
        num("nu_off_cm1", "off-line vacuum wavenumber", "cm-1", |r| {
            r.off_cm1
        }),
        num(
            "daod_one_way",
            "one-way differential absorption optical depth, on - off",
            "1",
            |r| r.daod_one_way,
        ),
        num(
            "wf_peak_hpa",
            "pressure of the peak of the weighting function per unit pressure",
            "hPa",
            |r| r.wf_peak_hpa,
        ),
        num(
            "dxco2_per_k_ppm",
            "XCO2 error for a true temperature 1 K above the assumed",
            "1e-6",
            |r| r.dxco2_per_k_ppm,
        ),
        num(
            "dxco2_per_mhz_ppm",
            "XCO2 error for a true on-line frequency 1 MHz above the assumed",
            "1e-6",
            |r| r.dxco2_per_mhz_ppm,
        ),
        num(
            "dxco2_per_hpa_ppm",
            "XCO2 error for an assumed surface pressure 1 hPa above the truth",
            "1e-6",
            |r| r.dxco2_per_hpa_ppm,
        ),
        num(
            "dxco2_per_10pct_h2o_ppm",
            "XCO2 error for a true humidity 10 % above the assumed",
            "1e-6",
            |r| r.dxco2_per_10pct_h2o_ppm,
        ),
        Column {
            name: "line",
            long_name: "CO2 30012<-00001 line the on-line sits on",
            units: None,
            values: Text(
                rows.iter()
                    .map(|r| r.position.line.clone().unwrap_or_default())
                    .collect(),
            ),
        },
        num(
            "offset_ghz",
            "on-line offset from the line centre",
            "GHz",
            |r| r.position.offset_ghz,
        ),
        num(
            "t2_on_mean",
            "two-way gas transmission of the on-line, mean over the profiles",
            "1",
            |r| r.t2_on_mean,
        ),
        num(
            "t2_on_std",
            "two-way gas transmission of the on-line, standard deviation over the profiles",
            "1",
            |r| r.t2_on_std,
        ),
        num(
            "random_error_ppm",
            "random error of one averaged measurement",
            "1e-6",
            |r| r.random_error_ppm,
        ),
        num(
            "total_error_ppm",
            "root-sum-square of the random error and each sensitivity times its uncertainty",
            "1e-6",
            |r| r.total_error_ppm,
        ),
        num(
            "rank",
            "rank within the atmosphere by total error (1 = smallest)",
            "1",
            |r| r.rank as f64,
        ),
        num("profiles", "profiles averaged", "1", |r| r.profiles as f64),
    ];
    table_dataset("row", &columns, title, history)
}
