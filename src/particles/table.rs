//! The phase-function table format of `phase_functions/`.
//!
//! A table is a text file:
//!
//! ```text
//! # lidarsim phase function table
//! # wavelength_nm = 1064
//! # refractive_index = 1.3205+1.28e-6i
//! # distribution = Deirmendjian C.1: modified gamma n(r) = a r^6 exp(-1.5 r), r in um
//! # source = miepython 3.3.0 (shared/reference/c1_phase_1064.csv)
//! theta_deg,phase_4pi
//! 0.0,759.3225
//! ...
//! 180.0,0.6415
//! ```
//!
//! * `# key = value` lines are metadata. `wavelength_nm`, `refractive_index` and `distribution`
//!   are required (write `none` where one does not apply, e.g. a measured table); any other keys
//!   (`source`, `single_scattering_albedo`, `asymmetry`, `lidar_ratio_sr`, …) are kept as text.
//!   Other `#` lines are free comments.
//! * The header line is `theta_deg,phase_4pi`: scattering angle in degrees, strictly increasing
//!   from exactly 0 to exactly 180, and the phase function normalised so that its integral over
//!   the sphere is 4π (an isotropic scatterer has phase_4pi = 1 everywhere).
//! * Between nodes the phase function is linear in cos θ; the normalisation is checked with that
//!   rule and a table off by more than 2 % is rejected (a table normalised to 1 or to 1/(4π) by
//!   mistake is then caught). Smaller quadrature differences are removed by rescaling to exactly
//!   4π when the table is turned into a [`PhaseFunction`](super::phase::PhaseFunction).

use std::fmt::Write as _;
use std::path::Path;

use crate::input::{Bounds, CsvTable, InputError, parse_f64_in, read_to_string};

/// Metadata keys every table must carry.
pub const REQUIRED_KEYS: [&str; 3] = ["wavelength_nm", "refractive_index", "distribution"];

/// A phase-function table as read from or written to `phase_functions/`.
#[derive(Debug, Clone, PartialEq)]
pub struct PhaseTable {
    /// `# key = value` metadata, in file order.
    pub meta: Vec<(String, String)>,
    /// Scattering angles \[deg\], strictly increasing from 0 to 180.
    pub theta_deg: Vec<f64>,
    /// Phase function normalised to 4π over the sphere.
    pub phase_4pi: Vec<f64>,
}

impl PhaseTable {
    /// Read and validate a table file.
    pub fn read(path: &Path) -> Result<Self, InputError> {
        Self::parse(path, &read_to_string(path)?)
    }

    /// Parse and validate table text; `path` names the file in errors.
    pub fn parse(path: &Path, text: &str) -> Result<Self, InputError> {
        let meta = parse_meta(path, text)?;
        let t = CsvTable::parse(path, text)?;
        if t.header() != ["theta_deg", "phase_4pi"] {
            return Err(InputError::at(
                path,
                t.header_line(),
                "header",
                format!(
                    "header must be `theta_deg,phase_4pi`, found `{}`",
                    t.header().join(",")
                ),
            ));
        }
        let theta_deg = t.f64_column_in("theta_deg", Bounds::closed(0.0, 180.0))?;
        let phase_4pi = t.f64_column_in("phase_4pi", PHASE_BOUNDS)?;
        check_angles(&t, &theta_deg)?;
        let table = PhaseTable {
            meta,
            theta_deg,
            phase_4pi,
        };
        check_normalisation(&t, "phase_4pi", table.normalisation())?;
        Ok(table)
    }

    /// (1/4π) ∫ P dΩ = ½ ∫ P dμ with P linear in μ = cos θ between nodes.
    pub fn normalisation(&self) -> f64 {
        normalisation(&self.theta_deg, &self.phase_4pi)
    }

    /// A metadata value.
    pub fn meta(&self, key: &str) -> Option<&str> {
        self.meta
            .iter()
            .find(|(k, _)| k == key)
            .map(|(_, v)| v.as_str())
    }

    /// The table in the file format (see the module documentation).
    pub fn to_text(&self) -> String {
        let mut s = String::from("# lidarsim phase function table\n");
        for (k, v) in &self.meta {
            let _ = writeln!(s, "# {k} = {v}");
        }
        s.push_str("theta_deg,phase_4pi\n");
        for (t, p) in self.theta_deg.iter().zip(&self.phase_4pi) {
            let _ = writeln!(s, "{t},{p:.9e}");
        }
        s
    }

    /// Write the table to `path`, whole or not at all ([`crate::output`]).
    pub fn write(&self, path: &Path) -> Result<(), crate::output::OutputError> {
        crate::output::write_file(path, self.to_text().as_bytes())
    }
}

fn line_of_key(text: &str, key: &str) -> usize {
    text.lines()
        .position(|l| {
            l.trim()
                .strip_prefix('#')
                .and_then(|c| c.split_once('='))
                .is_some_and(|(k, _)| k.trim() == key)
        })
        .map_or(1, |i| i + 1)
}

/// Range of a tabulated phase function (and of every matrix element in magnitude): the forward
/// peak of droplets at size parameter 10⁵ is near 10¹⁰ (∝ x²).
pub(crate) const PHASE_BOUNDS: Bounds = Bounds::closed(0.0, 1e12);

/// The `# key = value` metadata of a table file, checked: no key twice, the
/// [`REQUIRED_KEYS`] present, `wavelength_nm` a wavelength or `none`.
pub(crate) fn parse_meta(path: &Path, text: &str) -> Result<Vec<(String, String)>, InputError> {
    let mut meta = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let Some(c) = line.trim().strip_prefix('#') else {
            continue;
        };
        if let Some((k, v)) = c.split_once('=') {
            let key = k.trim();
            if !key.is_empty()
                && key
                    .chars()
                    .all(|ch| ch.is_ascii_alphanumeric() || ch == '_')
            {
                if meta.iter().any(|(k2, _): &(String, String)| k2 == key) {
                    return Err(InputError::at(path, i + 1, key, "metadata key given twice"));
                }
                meta.push((key.to_string(), v.trim().to_string()));
            }
        }
    }
    for key in REQUIRED_KEYS {
        if !meta.iter().any(|(k, _)| k == key) {
            return Err(InputError {
                field: Some(key.to_string()),
                ..InputError::file(
                    path,
                    format!(
                        "missing metadata line `# {key} = ...` (write `none` if it does not apply)"
                    ),
                )
            });
        }
    }
    if let Some((_, v)) = meta.iter().find(|(k, _)| k == "wavelength_nm")
        && v != "none"
    {
        let line = line_of_key(text, "wavelength_nm");
        // 10 nm to 1 cm: any wavelength a phase function of particles is computed for.
        parse_f64_in(path, line, "wavelength_nm", v, Bounds::closed(10.0, 1e7))?;
    }
    Ok(meta)
}

/// At least two angles, strictly increasing from exactly 0 to exactly 180 (`theta_deg` is the
/// parsed column of `t`).
pub(crate) fn check_angles(t: &CsvTable, theta_deg: &[f64]) -> Result<(), InputError> {
    let path = t.path();
    if theta_deg.len() < 2 {
        return Err(InputError::file(
            path,
            "needs at least two angles (0 and 180)",
        ));
    }
    for r in 1..theta_deg.len() {
        if theta_deg[r] <= theta_deg[r - 1] {
            return Err(InputError::at(
                path,
                t.line_of(r),
                "theta_deg",
                "angles must strictly increase",
            ));
        }
    }
    if theta_deg[0] != 0.0 {
        return Err(InputError::at(
            path,
            t.line_of(0),
            "theta_deg",
            "first angle must be 0",
        ));
    }
    if *theta_deg.last().unwrap_or(&0.0) != 180.0 {
        let line = t.line_of(theta_deg.len() - 1);
        return Err(InputError::at(
            path,
            line,
            "theta_deg",
            "last angle must be 180",
        ));
    }
    Ok(())
}

/// (1/4π) ∫ P dΩ = ½ ∫ P dμ with P linear in μ = cos θ between the nodes `theta_deg`.
pub(crate) fn normalisation(theta_deg: &[f64], p: &[f64]) -> f64 {
    let mu: Vec<f64> = theta_deg.iter().map(|t| t.to_radians().cos()).collect();
    let mut s = 0.0;
    for i in 0..mu.len().saturating_sub(1) {
        s += 0.5 * (p[i] + p[i + 1]) * (mu[i] - mu[i + 1]);
    }
    0.5 * s
}

/// The format's 2 % rule on the normalisation `norm` = (1/4π) ∫ P dΩ of column `column`
/// (a table normalised to 1 or to 1/(4π) by mistake is caught; smaller quadrature differences
/// are removed by rescaling when the table is used).
pub(crate) fn check_normalisation(t: &CsvTable, column: &str, norm: f64) -> Result<(), InputError> {
    if !((norm - 1.0).abs() <= 0.02) {
        return Err(InputError::at(
            t.path(),
            t.line_of(0),
            column,
            format!(
                "integrates to {:.6} × 4π over the sphere; the format requires 4π (within 2 %)",
                norm
            ),
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn iso(n: usize) -> PhaseTable {
        PhaseTable {
            meta: REQUIRED_KEYS
                .iter()
                .map(|k| (k.to_string(), "none".to_string()))
                .collect(),
            theta_deg: (0..n).map(|i| 180.0 * i as f64 / (n - 1) as f64).collect(),
            phase_4pi: vec![1.0; n],
        }
    }

    #[test]
    fn round_trips_through_text() {
        let t = iso(19);
        let back = PhaseTable::parse(Path::new("x"), &t.to_text()).unwrap();
        assert_eq!(back, t);
        assert!((back.normalisation() - 1.0).abs() < 1e-12);
    }

    #[test]
    fn rejects_wrong_normalisation_missing_meta_and_bad_angles() {
        let mut t = iso(19);
        t.phase_4pi
            .iter_mut()
            .for_each(|p| *p /= 4.0 * std::f64::consts::PI);
        let e = PhaseTable::parse(Path::new("p.txt"), &t.to_text()).unwrap_err();
        assert_eq!(e.field.as_deref(), Some("phase_4pi"));

        let text = iso(3).to_text().replace("# distribution = none\n", "");
        let e = PhaseTable::parse(Path::new("p.txt"), &text).unwrap_err();
        assert!(e.message.contains("distribution"), "{e}");
        assert_eq!(e.field.as_deref(), Some("distribution"));

        // A wrong header is named at its line.
        let text = iso(3)
            .to_text()
            .replace("theta_deg,phase_4pi", "theta,phase_4pi");
        let e = PhaseTable::parse(Path::new("p.txt"), &text).unwrap_err();
        let header_line = text.lines().position(|l| l.starts_with("theta,")).unwrap() + 1;
        assert_eq!(e.line, Some(header_line), "{e}");
        assert_eq!(e.field.as_deref(), Some("header"));

        let text = iso(3).to_text().replace("\n90,", "\n190,");
        let e = PhaseTable::parse(Path::new("p.txt"), &text).unwrap_err();
        assert_eq!(e.field.as_deref(), Some("theta_deg"));
    }
}
