//! Method (b) of [`super`]: per-level standard deviations with Gaussian vertical
//! correlations, and the embedded representative NWP forecast error.

use std::path::Path;

use nalgebra::DMatrix;

use super::Covariance;
use crate::atmosphere::set::LatitudeClass;
use crate::atmosphere::{AtmosphereError, Profile};
use crate::input::{Bounds, CsvTable, InputError, read_to_string};

/// Per-level standard deviations with Gaussian vertical correlations in ln p: method (b).
///
/// `S_ij = σ_i σ_j exp(−(ln p_i − ln p_j)² / (2 L²))` within each of T, ln H2O and CO2; no
/// correlation between variables; surface pressure independent. σ at a profile level is
/// interpolated linearly in ln p between the table's levels and held at the end values beyond
/// them (reported in the covariance notes).
#[derive(Debug, Clone, PartialEq)]
pub struct ErrorModel {
    /// Table levels \[Pa\], strictly decreasing.
    pub pressure_pa: Vec<f64>,
    /// σ_T \[K\] per table level.
    pub temperature_std_k: Vec<f64>,
    /// σ of ln H2O \[1\] per table level.
    pub ln_h2o_std: Vec<f64>,
    /// σ of CO2 \[ppmv\] per table level.
    pub co2_std_ppmv: Vec<f64>,
    /// Correlation length of T in ln p.
    pub temperature_corr_length_lnp: f64,
    /// Correlation length of ln H2O in ln p.
    pub ln_h2o_corr_length_lnp: f64,
    /// Correlation length of CO2 in ln p.
    pub co2_corr_length_lnp: f64,
    /// σ of the surface pressure \[hPa\].
    pub surface_pressure_std_hpa: f64,
    /// Where the numbers come from.
    pub source: String,
}

/// The embedded representative NWP forecast-error profile (`data/nwp_error`).
const REPRESENTATIVE_CSV: &str =
    include_str!("../../../data/nwp_error/bg_error_representative.csv");

impl ErrorModel {
    /// The representative 6-h NWP forecast ("background") error of `data/nwp_error`
    /// (synthetic mid-points of published global B-matrix ranges, see its PROVENANCE.md):
    /// σ_T and σ_lnq on 16 levels 1000–10 hPa, L_T = 0.35 and L_q = 0.25 in ln p, σ_ps = 0.7 hPa
    /// (the values its header states). It has no CO2: σ_CO2 = 0 (not perturbed) until set with
    /// [`Self::with_co2`].
    pub fn representative() -> ErrorModel {
        let mut m = Self::parse_table(
            Path::new("<embedded data/nwp_error/bg_error_representative.csv>"),
            REPRESENTATIVE_CSV,
        )
        .expect("embedded error table parses");
        m.temperature_corr_length_lnp = 0.35;
        m.ln_h2o_corr_length_lnp = 0.25;
        m.co2_corr_length_lnp = 0.35;
        m.surface_pressure_std_hpa = 0.7;
        m.source =
            "representative 6-h NWP forecast error (data/nwp_error/bg_error_representative.csv)"
                .into();
        m
    }

    /// Read a per-level error table: columns `p_hPa`, `T_std_K`, `lnq_std`, optional
    /// `CO2_std_ppmv` and free-text `basis`/`note`; correlation lengths and σ_ps are not in the
    /// table: they start as those of [`Self::representative`] and are set by the caller.
    pub fn read(path: &Path) -> Result<ErrorModel, InputError> {
        let mut m = Self::parse_table(path, &read_to_string(path)?)?;
        let r = Self::representative();
        m.temperature_corr_length_lnp = r.temperature_corr_length_lnp;
        m.ln_h2o_corr_length_lnp = r.ln_h2o_corr_length_lnp;
        m.co2_corr_length_lnp = r.co2_corr_length_lnp;
        m.surface_pressure_std_hpa = r.surface_pressure_std_hpa;
        m.source = format!("error table {}", path.display());
        Ok(m)
    }

    fn parse_table(path: &Path, text: &str) -> Result<ErrorModel, InputError> {
        let t = CsvTable::parse(path, text)?;
        for h in t.header() {
            if ![
                "p_hPa",
                "T_std_K",
                "lnq_std",
                "CO2_std_ppmv",
                "basis",
                "note",
            ]
            .contains(&h.as_str())
            {
                return Err(InputError::file(
                    path,
                    format!(
                        "unknown column `{h}` (expected p_hPa, T_std_K, lnq_std, CO2_std_ppmv, basis, note)"
                    ),
                ));
            }
        }
        // Each value in its physical range where it stands (standard deviations ≥ 0 and far
        // below what would make the perturbed profiles meaningless).
        let p: Vec<f64> = t
            .f64_column_in("p_hPa", crate::atmosphere::PRESSURE_PA.scaled(1e-2))?
            .iter()
            .map(|p| p * 100.0)
            .collect();
        let ts = t.f64_column_in("T_std_K", Bounds::closed(0.0, 100.0))?;
        let qs = t.f64_column_in("lnq_std", Bounds::closed(0.0, 10.0))?;
        let cs = match t.column_opt("CO2_std_ppmv") {
            Some(_) => t.f64_column_in("CO2_std_ppmv", Bounds::closed(0.0, 1e3))?,
            None => vec![0.0; p.len()],
        };
        if p.is_empty() {
            return Err(InputError::file(path, "no levels"));
        }
        for r in 0..p.len() {
            let line = t.line_of(r);
            if !(p[r] > 0.0) || (r > 0 && !(p[r] < p[r - 1])) {
                return Err(InputError::at(
                    path,
                    line,
                    "p_hPa",
                    "pressures must be positive and strictly decreasing",
                ));
            }
        }
        Ok(ErrorModel {
            pressure_pa: p,
            temperature_std_k: ts,
            ln_h2o_std: qs,
            co2_std_ppmv: cs,
            temperature_corr_length_lnp: f64::NAN,
            ln_h2o_corr_length_lnp: f64::NAN,
            co2_corr_length_lnp: f64::NAN,
            surface_pressure_std_hpa: f64::NAN,
            source: String::new(),
        })
    }

    /// Set a height-independent CO2 standard deviation \[ppmv\] and its correlation length.
    pub fn with_co2(mut self, std_ppmv: f64, corr_length_lnp: f64) -> ErrorModel {
        self.co2_std_ppmv = vec![std_ppmv; self.pressure_pa.len()];
        self.co2_corr_length_lnp = corr_length_lnp;
        self
    }

    /// Scale σ_T and σ_lnq for a latitude class as the `data/nwp_error` header suggests:
    /// T × (0.8 / 1.0 / 1.2), lnq × (1.0 / 1.0 / 1.2) for tropical / mid / high.
    pub fn scaled_for_class(mut self, c: LatitudeClass) -> ErrorModel {
        let (ft, fq) = match c {
            LatitudeClass::Tropical => (0.8, 1.0),
            LatitudeClass::Mid => (1.0, 1.0),
            LatitudeClass::High => (1.2, 1.2),
        };
        self.temperature_std_k.iter_mut().for_each(|s| *s *= ft);
        self.ln_h2o_std.iter_mut().for_each(|s| *s *= fq);
        self.source = format!("{}, scaled for class {c} (T ×{ft}, lnq ×{fq})", self.source);
        self
    }

    /// Check the parameters.
    pub fn validate(&self) -> Result<(), AtmosphereError> {
        for (name, v) in [
            (
                "temperature correlation length",
                self.temperature_corr_length_lnp,
            ),
            ("lnq correlation length", self.ln_h2o_corr_length_lnp),
            ("CO2 correlation length", self.co2_corr_length_lnp),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(AtmosphereError::InvalidArgument(format!(
                    "{name} {v} (ln p) must be positive"
                )));
            }
        }
        if !(self.surface_pressure_std_hpa.is_finite() && self.surface_pressure_std_hpa >= 0.0) {
            return Err(AtmosphereError::InvalidArgument(format!(
                "surface pressure std {} hPa must be ≥ 0",
                self.surface_pressure_std_hpa
            )));
        }
        if self
            .co2_std_ppmv
            .iter()
            .any(|s| !(s.is_finite() && *s >= 0.0))
        {
            return Err(AtmosphereError::InvalidArgument(
                "CO2 std must be ≥ 0".into(),
            ));
        }
        Ok(())
    }

    fn std_at(&self, values: &[f64], p: f64) -> (f64, bool) {
        let n = self.pressure_pa.len();
        if n == 1 || p >= self.pressure_pa[0] {
            return (values[0], p > self.pressure_pa[0] * (1.0 + 1e-12));
        }
        if p <= self.pressure_pa[n - 1] {
            return (values[n - 1], p < self.pressure_pa[n - 1] * (1.0 - 1e-12));
        }
        let k = self.pressure_pa.partition_point(|q| *q > p) - 1;
        let w = (p.ln() - self.pressure_pa[k].ln())
            / (self.pressure_pa[k + 1].ln() - self.pressure_pa[k].ln());
        (values[k] + w * (values[k + 1] - values[k]), false)
    }

    /// The covariance on `profile`'s levels.
    pub fn covariance(&self, profile: &Profile) -> Result<Covariance, AtmosphereError> {
        self.validate()?;
        profile.validate()?;
        let elements = Covariance::profile_elements(profile);
        let n = profile.len();
        let dim = elements.len();
        let mut s = DMatrix::<f64>::zeros(dim, dim);
        let lnp: Vec<f64> = profile.pressure_pa.iter().map(|p| p.ln()).collect();
        let mut held = false;
        for (block, (values, l)) in [
            (&self.temperature_std_k, self.temperature_corr_length_lnp),
            (&self.ln_h2o_std, self.ln_h2o_corr_length_lnp),
            (&self.co2_std_ppmv, self.co2_corr_length_lnp),
        ]
        .into_iter()
        .enumerate()
        {
            let sd: Vec<f64> = profile
                .pressure_pa
                .iter()
                .map(|p| {
                    let (v, h) = self.std_at(values, *p);
                    held |= h;
                    v
                })
                .collect();
            for i in 0..n {
                for j in 0..n {
                    let c = (-(lnp[i] - lnp[j]).powi(2) / (2.0 * l * l)).exp();
                    s[(block * n + i, block * n + j)] = sd[i] * sd[j] * c;
                }
            }
        }
        s[(dim - 1, dim - 1)] = self.surface_pressure_std_hpa.powi(2);
        let mut notes = vec![format!(
            "{}; Gaussian correlations in ln p: L_T {}, L_lnq {}, L_CO2 {}; sigma_ps {} hPa",
            self.source,
            self.temperature_corr_length_lnp,
            self.ln_h2o_corr_length_lnp,
            self.co2_corr_length_lnp,
            self.surface_pressure_std_hpa
        )];
        if held {
            notes.push(format!(
                "profile levels outside {}–{} hPa take the standard deviations of the nearest table level",
                self.pressure_pa[0] / 100.0,
                self.pressure_pa[self.pressure_pa.len() - 1] / 100.0
            ));
        }
        if self.co2_std_ppmv.iter().all(|s| *s == 0.0) {
            notes.push("CO2: standard deviation 0, not perturbed".into());
        }
        Ok(Covariance {
            elements,
            matrix: s,
            notes,
        })
    }
}
