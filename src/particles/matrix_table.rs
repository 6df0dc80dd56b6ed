//! The scattering-matrix table format: the six elements of [`super::matrix`] beside the scalar
//! `phase_functions/` format of [`super::table`].
//!
//! A table is a text file:
//!
//! ```text
//! # lidarsim scattering matrix table
//! # wavelength_nm = 532
//! # refractive_index = 1.334+1.5e-9i
//! # distribution = Deirmendjian C.1: modified gamma n(r) = a r^6 exp(-1.5 r), r in um
//! # source = lidarsim Mie
//! theta_deg,F11,F22,F33,F44,F12,F34
//! 0,1.234e3,1.234e3,1.234e3,1.234e3,0,0
//! ...
//! 180,6.1e-1,6.1e-1,-6.1e-1,-6.1e-1,0,0
//! ```
//!
//! * Metadata and comments follow the scalar format exactly: `# key = value` lines, with
//!   `wavelength_nm`, `refractive_index` and `distribution` required (`none` where one does not
//!   apply), other keys kept as text, no key twice.
//! * The header names the columns `theta_deg,F11,F22,F33,F44,F12,F34` (any order; each once), or
//!   `theta_deg,F11,F22,F33,F12` for a table of **linear polarisation only**: without F44 and
//!   F34 (both or neither) the table reads as `circular = false`, its F44 and F34 are held as 0
//!   (so that a Stokes vector with V = 0 keeps V = 0 and U' = F33 U), and only a transport that
//!   follows I, Q, U may use it. A missing, unknown or repeated column is refused, named.
//! * `theta_deg` is the scattering angle in degrees, strictly increasing from exactly 0 to
//!   exactly 180. The elements use the convention of [`super::matrix`]: Stokes reference plane
//!   the scattering plane, Q > 0 parallel to it (Bohren & Huffman 1983, §3.3; Hansen & Travis
//!   1974), F12 < 0 where scattering polarises perpendicular to the plane (molecules at 90°).
//! * Every element is normalised like F11, the phase function whose integral over the sphere is
//!   4π. F11 must be > 0 at every angle and every value finite. The normalisation of F11 is
//!   checked as in the scalar format (linear in cos θ between nodes, within 2 %), and the table
//!   is then rescaled — every element by the same factor — so that F11 integrates to exactly 4π
//!   ([`MatrixTable::phase_and_matrix`]).
//! * Every row must be a physical matrix: the inequalities (M1)–(M4) of [`super::matrix`]
//!   (Hovenier, van de Hulst & van der Mee 1986; Hovenier & van der Mee 1996), or for a
//!   linear-only table their projection (M1), (M2), (M34) (some F44, F34 complete the row), each
//!   to [`MUELLER_TOLERANCE`] × F11 for rounding in the file. A row that breaks one is refused at
//!   its line, naming the element the inequality bounds and the inequality.
//!
//! The writer ([`MatrixTable::to_text`]) prints what the reader reads; a table read back from
//! its own text is equal to it (values printed with 10 significant digits).

use std::fmt::Write as _;
use std::path::Path;
use std::sync::Arc;

use super::matrix::{MUELLER_TOLERANCE, MatrixElements, ScatteringMatrix, TabulatedMatrix};
use super::phase::{PhaseError, PhaseFunction, TabulatedPhase, mu_nodes};
use super::table::{
    PHASE_BOUNDS, PhaseTable, check_angles, check_normalisation, normalisation, parse_meta,
};
use crate::input::{Bounds, CsvTable, InputError, read_to_string};

/// Column names of the full table, in the order written.
pub const COLUMNS: [&str; 7] = ["theta_deg", "F11", "F22", "F33", "F44", "F12", "F34"];

/// Column names of a linear-only table, in the order written.
pub const LINEAR_COLUMNS: [&str; 5] = ["theta_deg", "F11", "F22", "F33", "F12"];

/// Range of the elements other than F11 (F11 itself: (0, 1e12]): |F_ij| ≤ F11.
const ELEMENT_BOUNDS: Bounds = Bounds::closed(-PHASE_BOUNDS.hi, PHASE_BOUNDS.hi);

/// A scattering-matrix table as read from or written to a file (see the module documentation).
#[derive(Debug, Clone, PartialEq)]
pub struct MatrixTable {
    /// `# key = value` metadata, in file order.
    pub meta: Vec<(String, String)>,
    /// Scattering angles \[deg\], strictly increasing from 0 to 180.
    pub theta_deg: Vec<f64>,
    /// The six elements at each angle, normalised like F11 (4π over the sphere, as given in
    /// the file: [`MatrixTable::phase_and_matrix`] removes the last per cent).
    pub elements: Vec<MatrixElements>,
    /// False for a table without F44 and F34 (held as 0): linear polarisation only.
    pub circular: bool,
}

impl MatrixTable {
    /// Read and validate a table file.
    pub fn read(path: &Path) -> Result<Self, InputError> {
        Self::parse(path, &read_to_string(path)?)
    }

    /// Parse and validate table text; `path` names the file in errors.
    pub fn parse(path: &Path, text: &str) -> Result<Self, InputError> {
        let meta = parse_meta(path, text)?;
        let t = CsvTable::parse(path, text)?;
        let circular = check_header(&t)?;
        let theta_deg = t.f64_column_in("theta_deg", Bounds::closed(0.0, 180.0))?;
        let f11 = t.f64_column_in("F11", Bounds::positive(PHASE_BOUNDS.hi))?;
        let column = |name: &str| t.f64_column_in(name, ELEMENT_BOUNDS);
        let (f22, f33, f12) = (column("F22")?, column("F33")?, column("F12")?);
        let (f44, f34) = if circular {
            (column("F44")?, column("F34")?)
        } else {
            (vec![0.0; f11.len()], vec![0.0; f11.len()])
        };
        check_angles(&t, &theta_deg)?;
        check_normalisation(&t, "F11", normalisation(&theta_deg, &f11))?;
        let elements: Vec<MatrixElements> = (0..f11.len())
            .map(|i| MatrixElements {
                f11: f11[i],
                f22: f22[i],
                f33: f33[i],
                f44: f44[i],
                f12: f12[i],
                f34: f34[i],
            })
            .collect();
        for (r, e) in elements.iter().enumerate() {
            let broken = if circular {
                e.mueller_violation(MUELLER_TOLERANCE)
            } else {
                e.linear_mueller_violation(MUELLER_TOLERANCE)
            };
            if let Some(v) = broken {
                return Err(InputError::at(
                    path,
                    t.line_of(r),
                    v.element,
                    format!(
                        "θ = {}°: {v}; tolerance {MUELLER_TOLERANCE:e} × F11",
                        theta_deg[r]
                    ),
                ));
            }
        }
        check_exact_directions(&t, &theta_deg, &elements, circular)?;
        Ok(MatrixTable {
            meta,
            theta_deg,
            elements,
            circular,
        })
    }

    /// (1/4π) ∫ F11 dΩ = ½ ∫ F11 dμ with F11 linear in μ = cos θ between nodes.
    pub fn normalisation(&self) -> f64 {
        let f11: Vec<f64> = self.elements.iter().map(|e| e.f11).collect();
        normalisation(&self.theta_deg, &f11)
    }

    /// A metadata value.
    pub fn meta(&self, key: &str) -> Option<&str> {
        self.meta
            .iter()
            .find(|(k, _)| k == key)
            .map(|(_, v)| v.as_str())
    }

    /// The scalar table of F11 with the same metadata and angles (the same numbers: a
    /// scalar run with it gives the phase function of [`Self::phase_and_matrix`]).
    pub fn f11_table(&self) -> PhaseTable {
        PhaseTable {
            meta: self.meta.clone(),
            theta_deg: self.theta_deg.clone(),
            phase_4pi: self.elements.iter().map(|e| e.f11).collect(),
        }
    }

    /// The scalar phase function of F11 and the matrix, from the same nodes and the same
    /// renormalisation: the F11 column is turned into a [`TabulatedPhase`] (rescaled to
    /// exactly 4π, linear in μ), and every element is multiplied by that same factor, so that
    /// `matrix.eval(μ).f11` equals `phase.eval(μ)` to rounding at every μ. The phase function
    /// is the one the scalar table of F11 ([`Self::f11_table`]) gives, number for number.
    pub fn phase_and_matrix(&self) -> Result<(PhaseFunction, ScatteringMatrix), PhaseError> {
        let f11: Vec<f64> = self.elements.iter().map(|e| e.f11).collect();
        let (phase, scale) = TabulatedPhase::from_angles_scaled(&self.theta_deg, &f11)?;
        let values: Vec<[f64; 6]> = self
            .elements
            .iter()
            .rev()
            .map(|e| {
                // The order of `TabulatedMatrix`'s nodes; F11 × scale is exactly the value the
                // phase table holds (the same product).
                [e.f11, e.f22, e.f33, e.f44, e.f12, e.f34].map(|v| v * scale)
            })
            .collect();
        let matrix = TabulatedMatrix::from_nodes(mu_nodes(&self.theta_deg), values, self.circular);
        Ok((
            PhaseFunction::Tabulated(Box::new(phase)),
            ScatteringMatrix::Tabulated(Arc::new(matrix)),
        ))
    }

    /// The table in the file format (see the module documentation): the seven columns, or the
    /// five of linear polarisation when `circular` is false.
    pub fn to_text(&self) -> String {
        let mut s = String::from("# lidarsim scattering matrix table\n");
        for (k, v) in &self.meta {
            let _ = writeln!(s, "# {k} = {v}");
        }
        if self.circular {
            s.push_str(&COLUMNS.join(","));
        } else {
            s.push_str(&LINEAR_COLUMNS.join(","));
        }
        s.push('\n');
        for (t, e) in self.theta_deg.iter().zip(&self.elements) {
            let _ = write!(s, "{t},{:.9e},{:.9e},{:.9e}", e.f11, e.f22, e.f33);
            if self.circular {
                let _ = write!(s, ",{:.9e}", e.f44);
            }
            let _ = write!(s, ",{:.9e}", e.f12);
            if self.circular {
                let _ = write!(s, ",{:.9e}", e.f34);
            }
            s.push('\n');
        }
        s
    }

    /// Write the table to `path`, whole or not at all ([`crate::output`]).
    pub fn write(&self, path: &Path) -> Result<(), crate::output::OutputError> {
        crate::output::write_file(path, self.to_text().as_bytes())
    }
}

/// Relative tolerance (× F11) of the exact-forward and exact-backscattering conditions
/// ([`check_exact_directions`]): that of the Mueller inequalities, so that a table printed to 6
/// significant digits passes by rounding alone (Mie tables, printed to 10, meet them to ~1e-10).
pub const EXACT_DIRECTION_TOLERANCE: f64 = MUELLER_TOLERANCE;

/// At exactly 0° and 180° the scattering plane, the reference plane of the elements, is not
/// defined: any plane through the direction serves, so the matrix of a macroscopically
/// isotropic, mirror-symmetric medium (spheres; randomly oriented particles with their mirror
/// images) must not change when the plane turns. That holds if and only if
///
/// ```text
/// θ = 0°:    F12 = F34 = 0,  F33 = F22      (exact forward scattering)
/// θ = 180°:  F12 = F34 = 0,  F33 = −F22     (exact backscattering)
/// ```
///
/// (Mishchenko, Travis & Lacis 2002, *Scattering, Absorption, and Emission of Light by Small
/// Particles*, Cambridge University Press, the symmetry relations of the scattering matrix at
/// 0 and 180°; Hovenier, van der Mee & Domke 2004, §2.7). A table that breaks them describes
/// no such medium, and gives answers that depend on which plane a calculation picks: a
/// polarised Monte Carlo scores single backscatter in the lidar's plane of polarisation
/// (F11 + F12 at 180° for linear light), the scalar lidar equation in none (F11), so their
/// order-1 returns differed by (1 + F12/F11): 1.04e-3 for a polariser with F12 = −0.999 F11
/// (`tests/matrices.rs`). Tables must have nodes at exactly 0° and 180° ([`check_angles`]: nothing is
/// extrapolated), so the conditions are checked at those two rows, each to
/// [`EXACT_DIRECTION_TOLERANCE`] × F11, and a row that breaks one is refused at its line and
/// the column it names. (Backscattering also has F44 = F11 − 2 F22 by reciprocity, Mishchenko
/// & Hovenier 1995; it does not depend on the plane and is not enforced.)
fn check_exact_directions(
    t: &CsvTable,
    theta_deg: &[f64],
    elements: &[MatrixElements],
    circular: bool,
) -> Result<(), InputError> {
    let last = elements.len() - 1;
    for (r, sign, name) in [
        (0, 1.0, "exact forward scattering"),
        (last, -1.0, "exact backscattering"),
    ] {
        let e = &elements[r];
        let tol = EXACT_DIRECTION_TOLERANCE * e.f11;
        let f33_rule = if sign > 0.0 { "F22" } else { "−F22" };
        let mut broken: Vec<(&str, String)> = Vec::new();
        if !(e.f12.abs() <= tol) {
            broken.push(("F12", format!("F12 = {} must be 0", e.f12)));
        }
        if circular && !(e.f34.abs() <= tol) {
            broken.push(("F34", format!("F34 = {} must be 0", e.f34)));
        }
        if !((e.f33 - sign * e.f22).abs() <= tol) {
            broken.push((
                "F33",
                format!("F33 = {} must equal {f33_rule} = {}", e.f33, sign * e.f22),
            ));
        }
        if let Some((field, what)) = broken.into_iter().next() {
            return Err(InputError::at(
                t.path(),
                t.line_of(r),
                field,
                format!(
                    "θ = {}° ({name}): {what}, so that the matrix does not depend on the \
                     reference plane, which is undefined there (spheres and randomly oriented \
                     mirror-symmetric particles: F12 = F34 = 0, F33 = {f33_rule}; Mishchenko, \
                     Travis & Lacis 2002); tolerance {EXACT_DIRECTION_TOLERANCE:e} × F11",
                    theta_deg[r]
                ),
            ));
        }
    }
    Ok(())
}

/// The header must hold `theta_deg`, F11, F22, F33, F12 and either both or neither of F44 and
/// F34, each once and nothing else; returns whether F44 and F34 are there.
fn check_header(t: &CsvTable) -> Result<bool, InputError> {
    let at = |field: &str, message: String| {
        InputError::at(t.path(), t.header_line(), field.to_string(), message)
    };
    let header = t.header();
    let expected = format!(
        "the header is `{}` (or `{}` for linear polarisation only)",
        COLUMNS.join(","),
        LINEAR_COLUMNS.join(",")
    );
    for (i, h) in header.iter().enumerate() {
        if !COLUMNS.contains(&h.as_str()) {
            return Err(at(h, format!("unknown column `{h}`: {expected}")));
        }
        if header[..i].contains(h) {
            return Err(at(h, format!("column `{h}` given twice")));
        }
    }
    for c in LINEAR_COLUMNS {
        if !header.iter().any(|h| h == c) {
            return Err(at(c, format!("missing column `{c}`: {expected}")));
        }
    }
    let has = |c: &str| header.iter().any(|h| h == c);
    match (has("F44"), has("F34")) {
        (true, true) => Ok(true),
        (false, false) => Ok(false),
        (false, true) => Err(at(
            "F44",
            format!("missing column `F44` (F44 and F34 come together): {expected}"),
        )),
        (true, false) => Err(at(
            "F34",
            format!("missing column `F34` (F44 and F34 come together): {expected}"),
        )),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::particles::table::REQUIRED_KEYS;

    /// The molecular matrix (ρ = 0.03) on `n` angles, which satisfies (M1)–(M4), scaled by
    /// `norm` (1: normalised to 4π).
    fn rayleigh_table(n: usize, norm: f64) -> MatrixTable {
        let m = ScatteringMatrix::rayleigh(0.03);
        let theta_deg: Vec<f64> = (0..n).map(|i| 180.0 * i as f64 / (n - 1) as f64).collect();
        let elements = theta_deg
            .iter()
            .map(|t| {
                let mut e = m.eval(t.to_radians().cos());
                for v in [
                    &mut e.f11, &mut e.f22, &mut e.f33, &mut e.f44, &mut e.f12, &mut e.f34,
                ] {
                    *v *= norm;
                }
                e
            })
            .collect();
        MatrixTable {
            meta: REQUIRED_KEYS
                .iter()
                .map(|k| (k.to_string(), "none".to_string()))
                .collect(),
            theta_deg,
            elements,
            circular: true,
        }
    }

    fn parse(text: &str) -> Result<MatrixTable, InputError> {
        MatrixTable::parse(Path::new("m.txt"), text)
    }

    /// Line of the first data row whose angle is `theta` in `text`.
    fn line_of_angle(text: &str, theta: &str) -> usize {
        text.lines()
            .position(|l| l.starts_with(&format!("{theta},")))
            .unwrap()
            + 1
    }

    #[test]
    fn round_trips_through_text_full_and_linear() {
        let t = rayleigh_table(181, 1.0);
        let back = parse(&t.to_text()).unwrap();
        // Printed to 10 digits: equal to that precision, and then stable.
        for (a, b) in back.elements.iter().zip(&t.elements) {
            assert!((a.f11 - b.f11).abs() <= 5e-10 * b.f11);
            assert!((a.f34 - b.f34).abs() <= 5e-10 * b.f11);
        }
        assert_eq!(parse(&back.to_text()).unwrap(), back);

        let mut lin = back.clone();
        lin.circular = false;
        lin.elements.iter_mut().for_each(|e| {
            e.f44 = 0.0;
            e.f34 = 0.0;
        });
        let text = lin.to_text();
        assert!(text.contains("\ntheta_deg,F11,F22,F33,F12\n"), "{text}");
        assert_eq!(parse(&text).unwrap(), lin);
    }

    /// Columns may come in any order; the values follow their names.
    #[test]
    fn columns_are_read_by_name() {
        let t = rayleigh_table(19, 1.0);
        let text = t.to_text();
        let mut lines: Vec<String> = Vec::new();
        for l in text.lines() {
            if l.starts_with('#') {
                lines.push(l.to_string());
            } else {
                // theta,F11,F22,F33,F44,F12,F34 → theta,F12,F34,F11,F22,F33,F44
                let f: Vec<&str> = l.split(',').collect();
                lines.push([f[0], f[5], f[6], f[1], f[2], f[3], f[4]].join(","));
            }
        }
        assert_eq!(parse(&lines.join("\n")).unwrap(), parse(&text).unwrap());
    }

    /// F11 of the matrix and the scalar phase function from the same table agree to rounding
    /// at every μ (nodes, between nodes, both ends), after both were rescaled by the same
    /// factor from a table 1.5 % off 4π; the other elements keep their ratios to F11; and the
    /// phase function equals the one the F11 column gives as a scalar table.
    #[test]
    fn phase_and_matrix_share_nodes_and_normalisation() {
        let t = parse(&rayleigh_table(37, 1.015).to_text()).unwrap();
        let (phase, matrix) = t.phase_and_matrix().unwrap();
        let scalar = PhaseFunction::Tabulated(Box::new(
            TabulatedPhase::from_table(&t.f11_table()).unwrap(),
        ));
        assert_eq!(phase, scalar);
        let mut worst: f64 = 0.0;
        for i in 0..=20_000 {
            let mu = -1.0 + i as f64 * 1e-4;
            let (p, e) = (phase.eval(mu), matrix.eval(mu));
            worst = worst.max(((e.f11 - p) / p).abs());
        }
        assert!(worst < 1e-14, "F11 vs P: {worst:e}");
        // The normalisation removed the 1.5 %: F11 is the molecular phase function again, and
        // so are the other elements.
        let r = ScatteringMatrix::rayleigh(0.03);
        for th in [0.0f64, 35.0, 90.0, 170.0, 180.0] {
            let mu = th.to_radians().cos();
            let (a, b) = (matrix.eval(mu), r.eval(mu));
            // Piecewise linear in μ between 5° nodes: 1e-3 covers the interpolation error.
            for (x, y) in [
                (a.f11, b.f11),
                (a.f12, b.f12),
                (a.f33, b.f33),
                (a.f44, b.f44),
            ] {
                assert!((x - y).abs() < 1e-3, "θ {th}: {x} vs {y}");
            }
        }
    }

    /// A two-row table (0° and 180°, a valid matrix: F11 = F22 = 1, F33 = F44 = ±1) with the
    /// columns `header` (an unknown column gets 0).
    fn two_rows(header: &[&str]) -> String {
        let mut s = String::from(
            "# wavelength_nm = none\n# refractive_index = none\n# distribution = none\n",
        );
        s.push_str(&header.join(","));
        s.push('\n');
        for (theta, f33) in [(0.0, 1.0), (180.0, -1.0)] {
            let row: Vec<String> = header
                .iter()
                .map(|h| match *h {
                    "theta_deg" => format!("{theta}"),
                    "F11" | "F22" => "1".into(),
                    "F33" | "F44" => format!("{f33}"),
                    _ => "0".into(),
                })
                .collect();
            s.push_str(&row.join(","));
            s.push('\n');
        }
        s
    }

    #[test]
    fn refuses_bad_headers_naming_the_column() {
        assert!(parse(&two_rows(&COLUMNS)).unwrap().circular);
        assert!(!parse(&two_rows(&LINEAR_COLUMNS)).unwrap().circular);
        let header_line = 4;
        for (header, field, words) in [
            (
                &["theta_deg", "F11", "F22", "F33", "F44", "F12", "F43"][..],
                "F43",
                "unknown column `F43`",
            ),
            (
                &["theta_deg", "F11", "F22", "F33", "F44", "F12"][..],
                "F34",
                "missing column `F34`",
            ),
            (
                &["theta_deg", "F11", "F22", "F33", "F12", "F34"][..],
                "F44",
                "missing column `F44`",
            ),
            (
                &["theta_deg", "F11", "F22", "F33", "F34", "F12", "F34"][..],
                "F34",
                "given twice",
            ),
            (
                &["theta_deg", "F11", "F33", "F44", "F12", "F34"][..],
                "F22",
                "missing column `F22`",
            ),
            (
                &["theta", "F11", "F22", "F33", "F12"][..],
                "theta",
                "unknown column `theta`",
            ),
        ] {
            let e = parse(&two_rows(header)).unwrap_err();
            assert_eq!(e.line, Some(header_line), "{header:?}: {e}");
            assert_eq!(e.field.as_deref(), Some(field), "{header:?}: {e}");
            assert!(e.message.contains(words), "{header:?}: {e}");
        }
    }

    #[test]
    fn refuses_bad_values_and_normalisation_at_their_line() {
        let t = rayleigh_table(19, 1.0);
        let text = t.to_text();
        // F11 ≤ 0 and a non-finite element, each at its line and column.
        let row90 = text.lines().find(|l| l.starts_with("90,")).unwrap();
        let f: Vec<&str> = row90.split(',').collect();
        for (col, value, field) in [(1, "0", "F11"), (1, "-1", "F11"), (6, "nan", "F34")] {
            let mut g = f.clone();
            g[col] = value;
            let bad = text.replace(row90, &g.join(","));
            let e = parse(&bad).unwrap_err();
            assert_eq!(e.line, Some(line_of_angle(&text, "90")), "{e}");
            assert_eq!(e.field.as_deref(), Some(field), "{e}");
        }
        // Normalised to 1 instead of 4π.
        let e = parse(&rayleigh_table(19, 0.25 / std::f64::consts::PI).to_text()).unwrap_err();
        assert_eq!(e.field.as_deref(), Some("F11"), "{e}");
        assert!(e.message.contains("4π"), "{e}");
        // Angles as in the scalar format.
        let e = parse(&text.replace("\n180,", "\n179,")).unwrap_err();
        assert_eq!(e.field.as_deref(), Some("theta_deg"), "{e}");
        // Metadata as in the scalar format.
        let e = parse(&text.replace("# refractive_index = none\n", "")).unwrap_err();
        assert_eq!(e.field.as_deref(), Some("refractive_index"), "{e}");
    }

    /// Each inequality, broken in one row by 1 % of F11, is refused at that row's line with
    /// the element it bounds; broken by 1e-5 F11 (below the tolerance), accepted.
    #[test]
    fn refuses_rows_that_are_not_physical_matrices() {
        let base = rayleigh_table(19, 1.0);
        let row = 6; // 60°
        let line = line_of_angle(&base.to_text(), "60");
        type Edit = fn(&mut MatrixElements, f64);
        // (name, edit by d × F11, the column named, whether d = 1e-5 stays within tolerance:
        // true where the edit starts from the boundary of the inequality it breaks; the
        // others also move a molecular row across (M2)–(M3), which have little room).
        let cases: [(&str, Edit, &str, bool); 5] = [
            // |F22| ≤ F11: raise F22 above F11.
            ("F22 > F11", |e, d| e.f22 = e.f11 * (1.0 + d), "F22", false),
            // (M3): F44 far from F33 while F22 is close to F11.
            (
                "M3",
                |e, d| e.f44 = e.f33 - (e.f11 - e.f22) - d * e.f11,
                "F44",
                true,
            ),
            // (M4): F34 so large that (F33+F44)² + 4F34² exceeds (F11+F22)² − 4F12².
            (
                "M4",
                |e, d| {
                    let room =
                        (e.f11 + e.f22).powi(2) - 4.0 * e.f12 * e.f12 - (e.f33 + e.f44).powi(2);
                    e.f34 = 0.5 * room.sqrt() + d * e.f11;
                },
                "F34",
                true,
            ),
            // |F12| ≤ F11.
            (
                "F12 < -F11",
                |e, d| e.f12 = -e.f11 * (1.0 + d),
                "F12",
                false,
            ),
            // |F33| ≤ F11.
            ("F33 > F11", |e, d| e.f33 = e.f11 * (1.0 + d), "F33", false),
        ];
        for (name, edit, field, boundary) in cases {
            let mut t = base.clone();
            edit(&mut t.elements[row], 1e-2);
            let e = parse(&t.to_text()).unwrap_err();
            assert_eq!(e.line, Some(line), "{name}: {e}");
            assert_eq!(e.field.as_deref(), Some(field), "{name}: {e}");
            assert!(e.message.contains("breaks"), "{name}: {e}");
            if boundary {
                let mut t = base.clone();
                edit(&mut t.elements[row], 1e-5);
                assert!(
                    parse(&t.to_text()).is_ok(),
                    "{name}: refused within tolerance"
                );
            }
        }
    }

    /// A linear-only table is checked by the projection (M34). At 90° molecules polarise
    /// strongly (|F12| close to F22): F33 = 0.1 F11 leaves room (2|F33| < F11 − F22, so some
    /// F44 cancels F33 in (M4)), F33 = F11 does not ((F11 + F22)² + 4F12² > (F11 + F22)²).
    #[test]
    fn linear_only_rows_are_checked_by_the_projection() {
        let mut t = rayleigh_table(19, 1.0);
        t.circular = false;
        for e in t.elements.iter_mut() {
            e.f44 = 0.0;
            e.f34 = 0.0;
        }
        let row = 9; // 90°: Rayleigh F12 = −¾Δ, F33 = 0.
        let mut ok = t.clone();
        ok.elements[row].f33 = 0.1 * ok.elements[row].f11;
        assert!(parse(&ok.to_text()).is_ok());
        let mut bad = t.clone();
        bad.elements[row].f33 = bad.elements[row].f11;
        let e = parse(&bad.to_text()).unwrap_err();
        assert_eq!(e.field.as_deref(), Some("F33"), "{e}");
        assert_eq!(e.line, Some(line_of_angle(&bad.to_text(), "90")));
    }

    /// The exact-direction conditions, each broken in the 0° or 180° row by 1 % of F11, are
    /// refused at that row's line with the column and the condition named; broken by 1e-5 F11
    /// (within the tolerance) accepted. The molecular rows of the base table meet them exactly.
    #[test]
    fn refuses_rows_that_break_the_exact_direction_conditions() {
        let base = rayleigh_table(19, 1.0);
        let text = base.to_text();
        let last = base.elements.len() - 1;
        type Edit = fn(&mut MatrixElements, f64);
        // (row, edit by d × F11, the column named, words of the condition).
        let cases: [(usize, Edit, &str, &str); 6] = [
            (
                last,
                |e, d| e.f12 = d * e.f11,
                "F12",
                "exact backscattering",
            ),
            (
                last,
                |e, d| e.f34 = d * e.f11,
                "F34",
                "exact backscattering",
            ),
            (
                last,
                |e, d| e.f33 = -e.f22 + d * e.f11,
                "F33",
                "must equal −F22",
            ),
            (
                0,
                |e, d| e.f12 = -d * e.f11,
                "F12",
                "exact forward scattering",
            ),
            (
                0,
                |e, d| e.f34 = d * e.f11,
                "F34",
                "exact forward scattering",
            ),
            (0, |e, d| e.f33 = e.f22 - d * e.f11, "F33", "must equal F22"),
        ];
        for (row, edit, field, words) in cases {
            let theta = if row == 0 { "0" } else { "180" };
            let mut t = base.clone();
            edit(&mut t.elements[row], 1e-2);
            let e = parse(&t.to_text()).unwrap_err();
            assert_eq!(
                e.line,
                Some(line_of_angle(&text, theta)),
                "{field} {theta}: {e}"
            );
            assert_eq!(e.field.as_deref(), Some(field), "{theta}: {e}");
            assert!(
                e.message.contains(words) && e.message.contains("reference plane"),
                "{e}"
            );
            let mut t = base.clone();
            edit(&mut t.elements[row], 1e-5);
            assert!(
                parse(&t.to_text()).is_ok(),
                "{field} {theta}: refused within tolerance"
            );
        }
        // A linear-only table: F12 and F33 are checked (F34 is held 0).
        let lin = two_rows(&LINEAR_COLUMNS).replace("180,1,1,-1,0", "180,1,0.5,-0.5,0.3");
        let e = parse(&lin).unwrap_err();
        assert_eq!((e.line, e.field.as_deref()), (Some(6), Some("F12")), "{e}");
        let lin = two_rows(&LINEAR_COLUMNS).replace("180,1,1,-1,0", "180,1,0.5,-0.4,0");
        let e = parse(&lin).unwrap_err();
        assert_eq!((e.line, e.field.as_deref()), (Some(6), Some("F33")), "{e}");
        // The issue's table: a physical matrix (F11 = 1, F22 = 0.5, F33 = −0.5, F44 = −0.5)
        // but F12 = 0.3 at 180°.
        let issue = two_rows(&COLUMNS).replace("180,1,1,-1,-1,0,0", "180,1,0.5,-0.5,-0.5,0.3,0");
        let e = parse(&issue).unwrap_err();
        assert_eq!((e.line, e.field.as_deref()), (Some(6), Some("F12")), "{e}");
    }

    /// Nothing is extrapolated to 0° or 180°: a table without a node at exactly 0° or exactly
    /// 180° is refused at its first or last row, so the exact-direction conditions are always
    /// checked on rows of the file.
    #[test]
    fn tables_need_nodes_at_exactly_0_and_180_degrees() {
        let text = rayleigh_table(19, 1.0).to_text();
        let e = parse(&text.replace("\n0,", "\n0.5,")).unwrap_err();
        assert_eq!(e.field.as_deref(), Some("theta_deg"), "{e}");
        assert!(e.message.contains("first angle must be 0"), "{e}");
        let e = parse(&text.replace("\n180,", "\n179.9,")).unwrap_err();
        assert_eq!(e.field.as_deref(), Some("theta_deg"), "{e}");
        assert_eq!(e.line, Some(line_of_angle(&text, "180")), "{e}");
    }
}
