//! Laser line shapes, and the quadrature that turns one pulsed line into monochromatic channels.
//!
//! A pulsed laser line is not monochromatic: its emission spectrum g(x) (x the frequency offset
//! from the nominal line centre, in MHz, ∫ g dx = 1) is seen through the atmosphere's spectral
//! transmission f(x). The line return is ∫ g(x) f(x) dx, and the transport estimates it as
//! Σ wᵢ f(xᵢ): each node xᵢ becomes one monochromatic channel of the Monte Carlo, so a rule must
//! reach high accuracy with few nodes. [`LineShape::nodes`] gives, per shape:
//!
//! | shape | rule | exact for |
//! |---|---|---|
//! | [`LineShape::Monochromatic`] | one node (0, 1) | everything |
//! | [`LineShape::Gaussian`] | n-point Gauss–Hermite, nodes σξᵢ | f polynomial of degree ≤ 2n − 1 |
//! | [`LineShape::Lorentzian`] | n-point Gauss–Legendre in the CDF variable u | f(x(u)) polynomial in u of degree ≤ 2n − 1 |
//! | [`LineShape::Table`] | n-point Gauss–Legendre in the CDF variable u | f(x(u)) polynomial in u of degree ≤ 2n − 1 |
//!
//! Every rule has positive weights summing to 1 and nodes sorted ascending, and every number is
//! deterministic. Offsets are in MHz; divide by [`MHZ_PER_CM1`] for a wavenumber offset in cm⁻¹.
//!
//! The Gauss rules come from the Golub–Welsch eigenvalue method[^gw]; each node is then polished
//! by Newton steps on the three-term recurrence, and each weight evaluated as the Christoffel
//! number 1/Σₖ pₖ(xᵢ)² (the same quantity as the squared first eigenvector component, but with
//! relative rather than absolute accuracy, which the tiny tail weights of Gauss–Hermite need).
//!
//! [^gw]: G. H. Golub and J. H. Welsch (1969), "Calculation of Gauss quadrature rules",
//!     Math. Comp. 23 (106), 221–230, doi:10.1090/S0025-5718-69-99647-1.

use std::f64::consts::{LN_2, PI};
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use nalgebra::{DMatrix, SymmetricEigen};

use crate::input::{CsvTable, InputError, parse_f64, read_to_string};

/// MHz per cm⁻¹: 1 cm⁻¹ = c · 1 cm⁻¹ = 29 979.2458 MHz.
///
/// A wavenumber offset in cm⁻¹ is `offset_mhz / MHZ_PER_CM1` (c = 299 792 458 m/s exactly, SI).
pub const MHZ_PER_CM1: f64 = 29_979.245_8;

/// Column of a line-shape table holding the frequency offset \[MHz\].
const OFFSET_COLUMN: &str = "offset_mhz";
/// Column of a line-shape table holding the (unnormalised) relative intensity.
const INTENSITY_COLUMN: &str = "relative_intensity";

/// Newton steps allowed when polishing a Golub–Welsch node (one or two are used in practice).
const MAX_NEWTON_STEPS: usize = 4;
/// A Newton step smaller than this many ulps of the node ends the polishing.
const NEWTON_STOP_ULPS: f64 = 4.0;
/// A polished node that moved further than this (relative to 1 + |x|) from its eigenvalue is
/// distrusted, and the eigenvalue kept: the eigen-solver is good to ~1e-15, so a bigger jump means
/// Newton went to another root.
const NEWTON_MAX_MOVE: f64 = 1e-8;

/// The emission spectrum of one laser line, as a density in the frequency offset from the
/// nominal line centre.
#[derive(Debug, Clone, PartialEq)]
pub enum LineShape {
    /// A single frequency: g(x) = δ(x).
    Monochromatic,
    /// g(x) = exp(−x²/(2σ²)) / (σ√(2π)), σ = FWHM / (2√(2 ln 2)).
    Gaussian {
        /// Full width at half maximum \[MHz\], finite and > 0.
        fwhm_mhz: f64,
    },
    /// g(x) = (γ/π) / (x² + γ²), half width γ = FWHM / 2.
    Lorentzian {
        /// Full width at half maximum \[MHz\], finite and > 0.
        fwhm_mhz: f64,
    },
    /// A measured spectrum: piecewise linear between table points, 0 outside.
    Table(LineShapeTable),
}

/// A tabulated line shape: relative intensity against frequency offset.
///
/// The density is the linear interpolation of `relative_intensity` between points, zero outside
/// the table, scaled to unit area by the trapezoid rule (which is exact for it). Tables come from
/// [`LineShapeTable::parse`] / [`LineShapeTable::read`], which validate them; a table assembled by
/// hand can be checked with [`LineShapeTable::validate`].
///
/// File format (comma-separated, `#` comment lines anywhere, blank lines ignored):
///
/// ```text
/// # seed laser, heterodyne measurement 2026-03-02
/// offset_mhz,relative_intensity
/// -60,0
/// -20,0.45
/// 0,1
/// 20,0.47
/// 60,0
/// ```
#[derive(Debug, Clone, PartialEq)]
pub struct LineShapeTable {
    /// The file it came from (used in messages only).
    pub source: PathBuf,
    /// Frequency offset from the nominal line centre \[MHz\], strictly increasing.
    pub offset_mhz: Vec<f64>,
    /// Relative intensity at each offset, ≥ 0, not normalised.
    pub relative_intensity: Vec<f64>,
}

/// One node of a quadrature rule: ∫ g(x) f(x) dx ≈ Σ weight · f(offset_mhz).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct QuadratureNode {
    /// Node position: frequency offset from the nominal line centre \[MHz\] (for the bare rules
    /// [`gauss_hermite`] and [`gauss_legendre`], the dimensionless abscissa).
    pub offset_mhz: f64,
    /// Quadrature weight, > 0.
    pub weight: f64,
}

impl QuadratureNode {
    fn new(offset_mhz: f64, weight: f64) -> Self {
        QuadratureNode { offset_mhz, weight }
    }
}

/// What is wrong with a table's numbers; `row` is the 0-based data row.
#[derive(Debug, Clone, Copy, PartialEq)]
enum TableFault {
    LengthMismatch { offsets: usize, intensities: usize },
    TooFewRows { rows: usize },
    NotFinite { row: usize, column: &'static str },
    NotIncreasing { row: usize },
    StepOverflow { row: usize },
    Negative { row: usize },
    AreaNotFinite,
    ZeroArea,
}

impl TableFault {
    /// The data row and column at fault, where one applies.
    fn place(self) -> Option<(usize, &'static str)> {
        match self {
            TableFault::NotFinite { row, column } => Some((row, column)),
            TableFault::NotIncreasing { row } | TableFault::StepOverflow { row } => {
                Some((row, OFFSET_COLUMN))
            }
            TableFault::Negative { row } => Some((row, INTENSITY_COLUMN)),
            _ => None,
        }
    }

    fn message(self, offset_mhz: &[f64], relative_intensity: &[f64]) -> String {
        match self {
            TableFault::LengthMismatch {
                offsets,
                intensities,
            } => format!("{offsets} offsets but {intensities} intensities"),
            TableFault::TooFewRows { rows } => {
                format!("needs at least 2 rows, found {rows}")
            }
            TableFault::NotFinite { row, column } => {
                let v = if column == OFFSET_COLUMN {
                    offset_mhz[row]
                } else {
                    relative_intensity[row]
                };
                format!("`{v}` is not finite")
            }
            TableFault::NotIncreasing { row } => format!(
                "offset {} MHz does not exceed the previous one, {} MHz; offsets must strictly \
                 increase",
                offset_mhz[row],
                offset_mhz[row - 1]
            ),
            TableFault::StepOverflow { row } => format!(
                "the step from {} to {} MHz overflows a 64-bit float",
                offset_mhz[row - 1],
                offset_mhz[row]
            ),
            TableFault::Negative { row } => format!(
                "`{}` is negative; intensities must be ≥ 0",
                relative_intensity[row]
            ),
            TableFault::AreaNotFinite => {
                "the area under the table overflows a 64-bit float; scale the intensities down"
                    .to_string()
            }
            TableFault::ZeroArea => "the line shape has zero area (every intensity is 0, or too \
                                     small to represent)"
                .to_string(),
        }
    }
}

/// A validated table as a normalised density with its cumulative distribution.
///
/// Between points xⱼ and xⱼ₊₁ (step hⱼ) the density is linear, g(xⱼ + s) = gⱼ + mⱼ s with
/// mⱼ = (gⱼ₊₁ − gⱼ)/hⱼ, so the CDF is quadratic: G(xⱼ + s) = Gⱼ + gⱼ s + ½ mⱼ s².
struct TableCdf<'a> {
    x: &'a [f64],
    /// Density at the points, normalised to unit area \[1/MHz\].
    g: Vec<f64>,
    /// CDF at the points: 0 at the first, exactly 1 at the last.
    cdf: Vec<f64>,
}

impl<'a> TableCdf<'a> {
    fn new(offset_mhz: &'a [f64], relative_intensity: &[f64]) -> Result<Self, TableFault> {
        let n = offset_mhz.len();
        if relative_intensity.len() != n {
            return Err(TableFault::LengthMismatch {
                offsets: n,
                intensities: relative_intensity.len(),
            });
        }
        for row in 0..n {
            let (x, i) = (offset_mhz[row], relative_intensity[row]);
            if !x.is_finite() {
                return Err(TableFault::NotFinite {
                    row,
                    column: OFFSET_COLUMN,
                });
            }
            if !i.is_finite() {
                return Err(TableFault::NotFinite {
                    row,
                    column: INTENSITY_COLUMN,
                });
            }
            if row > 0 {
                if !(x > offset_mhz[row - 1]) {
                    return Err(TableFault::NotIncreasing { row });
                }
                if !(x - offset_mhz[row - 1]).is_finite() {
                    return Err(TableFault::StepOverflow { row });
                }
            }
            if i < 0.0 {
                return Err(TableFault::Negative { row });
            }
        }
        if n < 2 {
            return Err(TableFault::TooFewRows { rows: n });
        }
        // Trapezoid areas, exact for a piecewise-linear density; halves first so the sum of two
        // huge intensities cannot overflow where their mean would not.
        let segment_area = |i: &[f64], j: usize| {
            (0.5 * i[j] + 0.5 * i[j + 1]) * (offset_mhz[j + 1] - offset_mhz[j])
        };
        let area: f64 = (0..n - 1)
            .map(|j| segment_area(relative_intensity, j))
            .sum();
        if !area.is_finite() {
            return Err(TableFault::AreaNotFinite);
        }
        if !(area > 0.0) {
            return Err(TableFault::ZeroArea);
        }
        let g: Vec<f64> = relative_intensity.iter().map(|i| i / area).collect();
        let mut cdf = Vec::with_capacity(n);
        cdf.push(0.0);
        for j in 0..n - 1 {
            cdf.push(cdf[j] + segment_area(&g, j));
        }
        // The sum is 1 to rounding; make the end exact so u ∈ (0, 1) always lands in the table.
        let total = cdf[n - 1];
        cdf.iter_mut().for_each(|c| *c /= total);
        cdf[n - 1] = 1.0;
        Ok(TableCdf {
            x: offset_mhz,
            g,
            cdf,
        })
    }

    /// g(x) \[1/MHz\]: linear interpolation, 0 outside the table.
    fn density(&self, x: f64) -> f64 {
        let last = self.x.len() - 1;
        if x.is_nan() {
            return f64::NAN;
        }
        if x < self.x[0] || x > self.x[last] {
            return 0.0;
        }
        let j = self
            .x
            .partition_point(|&xk| xk <= x)
            .saturating_sub(1)
            .min(last - 1);
        let t = (x - self.x[j]) / (self.x[j + 1] - self.x[j]);
        (1.0 - t) * self.g[j] + t * self.g[j + 1]
    }

    /// The cumulative distribution G(x): 0 before the table, 1 after it.
    fn cdf_at(&self, x: f64) -> f64 {
        let last = self.x.len() - 1;
        if x <= self.x[0] {
            return 0.0;
        }
        if x >= self.x[last] {
            return 1.0;
        }
        let j = self
            .x
            .partition_point(|&xk| xk <= x)
            .saturating_sub(1)
            .min(last - 1);
        let h = self.x[j + 1] - self.x[j];
        let s = x - self.x[j];
        let slope = (self.g[j + 1] - self.g[j]) / h;
        (self.cdf[j] + self.g[j] * s + 0.5 * slope * s * s).clamp(self.cdf[j], self.cdf[j + 1])
    }

    /// The quantile x(u) = G⁻¹(u) for u ∈ \[0, 1\].
    ///
    /// In the segment with Gⱼ ≤ u < Gⱼ₊₁ (never a zero-area one, since those have Gⱼ = Gⱼ₊₁),
    /// ½ mⱼ s² + gⱼ s = Δ with Δ = u − Gⱼ has the root
    /// s = 2Δ / (gⱼ + √(gⱼ² + 2 mⱼ Δ)),
    /// the rationalised form of (−gⱼ + √(gⱼ² + 2mⱼΔ))/mⱼ: both terms of the denominator are ≥ 0,
    /// so nothing cancels, and it holds for mⱼ = 0 (s = Δ/gⱼ) and for gⱼ = 0 (s = √(2Δ/mⱼ)).
    fn quantile(&self, u: f64) -> f64 {
        let last = self.x.len() - 1;
        let j = self
            .cdf
            .partition_point(|&c| c <= u)
            .saturating_sub(1)
            .min(last - 1);
        let h = self.x[j + 1] - self.x[j];
        let delta = (u - self.cdf[j]).max(0.0);
        let slope = (self.g[j + 1] - self.g[j]) / h;
        // ≥ 0 in exact arithmetic (it is g² at the point reached); clamp the rounding.
        let discriminant = (self.g[j] * self.g[j] + 2.0 * slope * delta).max(0.0);
        let denominator = self.g[j] + discriminant.sqrt();
        let s = if denominator > 0.0 {
            2.0 * delta / denominator
        } else {
            0.0
        };
        self.x[j] + s.clamp(0.0, h)
    }
}

impl LineShapeTable {
    /// Parse CSV text: `#` comment lines, header `offset_mhz,relative_intensity`, ≥ 2 rows.
    ///
    /// `path` names the file in errors. A leading UTF-8 byte-order mark is ignored. Errors are
    /// [`InputError`]s naming the path, the 1-based line and the column: a bad or non-finite
    /// number, a negative intensity, offsets not strictly increasing, fewer than 2 rows, zero (or
    /// overflowing) total area, a wrong or missing header column, a row with the wrong number of
    /// fields.
    pub fn parse(path: &Path, text: &str) -> Result<Self, InputError> {
        let text = text.strip_prefix('\u{feff}').unwrap_or(text);
        let table = CsvTable::parse(path, text)?;
        let header_line = header_line(text);
        let expected = [OFFSET_COLUMN, INTENSITY_COLUMN];
        if table.header() != expected {
            let header = table.header();
            let wrong = (0..header.len().max(expected.len()))
                .find(|&c| header.get(c).map(String::as_str) != expected.get(c).copied())
                .unwrap_or(0);
            let field = header
                .get(wrong)
                .map(String::as_str)
                .or(expected.get(wrong).copied())
                .unwrap_or(OFFSET_COLUMN);
            return Err(InputError::at(
                path,
                header_line,
                field,
                format!(
                    "the header must be `{}`, found `{}`",
                    expected.join(","),
                    header.join(",")
                ),
            ));
        }
        let mut offset_mhz = Vec::with_capacity(table.len());
        let mut relative_intensity = Vec::with_capacity(table.len());
        // `CsvTable` gives every row as many fields as the header: here exactly two.
        for (line, fields) in table.rows() {
            offset_mhz.push(parse_f64(path, line, OFFSET_COLUMN, &fields[0])?);
            relative_intensity.push(parse_f64(path, line, INTENSITY_COLUMN, &fields[1])?);
        }
        if let Err(fault) = TableCdf::new(&offset_mhz, &relative_intensity) {
            let message = fault.message(&offset_mhz, &relative_intensity);
            return Err(match fault.place() {
                Some((row, column)) => InputError::at(path, table.line_of(row), column, message),
                None if table.is_empty() => InputError::at(path, header_line, "row", message),
                None if matches!(fault, TableFault::TooFewRows { .. }) => {
                    InputError::at(path, table.line_of(table.len() - 1), "row", message)
                }
                None => InputError::at(path, table.line_of(0), INTENSITY_COLUMN, message),
            });
        }
        Ok(LineShapeTable {
            source: path.to_path_buf(),
            offset_mhz,
            relative_intensity,
        })
    }

    /// Read and parse a table file (see [`LineShapeTable::parse`]).
    pub fn read(path: &Path) -> Result<Self, InputError> {
        Self::parse(path, &read_to_string(path)?)
    }

    /// Check a table built by hand against the rules [`LineShapeTable::parse`] enforces.
    pub fn validate(&self) -> Result<(), String> {
        TableCdf::new(&self.offset_mhz, &self.relative_intensity)
            .map(|_| ())
            .map_err(|fault| {
                let at = fault
                    .place()
                    .map(|(row, column)| format!(" (row {}, `{column}`)", row + 1))
                    .unwrap_or_default();
                format!(
                    "line-shape table {}{at}: {}",
                    self.source.display(),
                    fault.message(&self.offset_mhz, &self.relative_intensity)
                )
            })
    }
}

/// The 1-based line of a CSV text's header: its first line that is neither blank nor a comment
/// (the rule of [`CsvTable::parse`]).
fn header_line(text: &str) -> usize {
    text.lines()
        .position(|l| {
            let l = l.trim();
            !l.is_empty() && !l.starts_with('#')
        })
        .map_or(1, |i| i + 1)
}

/// Check a full width at half maximum.
fn check_fwhm(fwhm_mhz: f64) -> Result<f64, String> {
    if fwhm_mhz.is_finite() && fwhm_mhz > 0.0 {
        Ok(fwhm_mhz)
    } else {
        Err(format!(
            "line-shape fwhm_mhz must be finite and > 0, got {fwhm_mhz}"
        ))
    }
}

/// Gaussian standard deviation from the FWHM: σ = FWHM / (2√(2 ln 2)).
fn gaussian_sigma(fwhm_mhz: f64) -> f64 {
    fwhm_mhz / (2.0 * (2.0 * LN_2).sqrt())
}

impl LineShape {
    /// A Gaussian line of full width at half maximum `fwhm_mhz` \[MHz\], which must be finite
    /// and > 0 (the error names the value).
    pub fn gaussian(fwhm_mhz: f64) -> Result<Self, String> {
        check_fwhm(fwhm_mhz).map(|fwhm_mhz| LineShape::Gaussian { fwhm_mhz })
    }

    /// A Lorentzian line of full width at half maximum `fwhm_mhz` \[MHz\], which must be finite
    /// and > 0 (the error names the value).
    pub fn lorentzian(fwhm_mhz: f64) -> Result<Self, String> {
        check_fwhm(fwhm_mhz).map(|fwhm_mhz| LineShape::Lorentzian { fwhm_mhz })
    }

    /// Check a shape whose fields were set by hand (the constructors and
    /// [`LineShapeTable::parse`] already do).
    pub fn validate(&self) -> Result<(), String> {
        match self {
            LineShape::Monochromatic => Ok(()),
            LineShape::Gaussian { fwhm_mhz } | LineShape::Lorentzian { fwhm_mhz } => {
                check_fwhm(*fwhm_mhz).map(|_| ())
            }
            LineShape::Table(table) => table.validate(),
        }
    }

    /// The density g(x) \[1/MHz\] at offset x \[MHz\], normalised to ∫ g dx = 1.
    ///
    /// * Gaussian: g(x) = exp(−x²/(2σ²)) / (σ√(2π)), σ = FWHM/(2√(2 ln 2)); peak
    ///   2√(ln 2/π)/FWHM.
    /// * Lorentzian: g(x) = (γ/π)/(x² + γ²), γ = FWHM/2; peak 2/(π FWHM).
    /// * Table: linear between points, 0 outside, scaled to unit trapezoid area. Costs one pass
    ///   over the table per call.
    /// * Monochromatic: a Dirac delta, returned as `f64::INFINITY` at x = 0 and 0 elsewhere.
    ///
    /// A shape that fails [`LineShape::validate`] (possible only when built by hand) gives NaN.
    pub fn density_per_mhz(&self, offset_mhz: f64) -> f64 {
        let x = offset_mhz;
        match self {
            LineShape::Monochromatic => {
                if x == 0.0 {
                    f64::INFINITY
                } else if x.is_nan() {
                    f64::NAN
                } else {
                    0.0
                }
            }
            LineShape::Gaussian { fwhm_mhz } => match check_fwhm(*fwhm_mhz) {
                Ok(fwhm) => {
                    let sigma = gaussian_sigma(fwhm);
                    let z = x / sigma;
                    (-0.5 * z * z).exp() / (sigma * (2.0 * PI).sqrt())
                }
                Err(_) => f64::NAN,
            },
            LineShape::Lorentzian { fwhm_mhz } => match check_fwhm(*fwhm_mhz) {
                Ok(fwhm) => {
                    let gamma = 0.5 * fwhm;
                    gamma / (PI * (x * x + gamma * gamma))
                }
                Err(_) => f64::NAN,
            },
            LineShape::Table(table) => {
                match TableCdf::new(&table.offset_mhz, &table.relative_intensity) {
                    Ok(cdf) => cdf.density(x),
                    Err(_) => f64::NAN,
                }
            }
        }
    }

    /// An n-point quadrature ∫ g(x) f(x) dx ≈ Σ wᵢ f(xᵢ): weights > 0 summing to 1 (to 1e-14),
    /// nodes (offsets in MHz) sorted ascending. `n = 0` is treated as 1.
    ///
    /// * Monochromatic: one node (0, 1) whatever n.
    /// * Gaussian: Gauss–Hermite for the normal weight, xᵢ = σξᵢ (see [`gauss_hermite`]); exact
    ///   when f is a polynomial of degree ≤ 2n − 1[^as46]. Nodes symmetric about 0.
    /// * Lorentzian: with u = G(x) = ½ + arctan(x/γ)/π, ∫ g f dx = ∫₀¹ f(x(u)) du with
    ///   x(u) = γ tan(π(u − ½)); n-point Gauss–Legendre in u (nodes uᵢ = (1 + tᵢ)/2, weights
    ///   wᵢ/2 from [`gauss_legendre`]). The heavy wings need no truncation: the outer nodes reach
    ///   x ≈ ±2(n + ½)²γ/(π j₀₁²) ≈ ±0.22(n + ½)²γ (16γ at n = 8, 233γ at n = 32). Nodes
    ///   symmetric about 0. The rule converges fastest when f varies on the line's own scale:
    ///   for f(x) = a²/(a² + x²) the error is 4.4e-11 at n = 8 when a = γ, but 4.5e-3, 8.2e-5
    ///   and 1.6e-8 at n = 8, 16, 32 when a = 10γ (the wings then carry the error).
    /// * Table: the same CDF mapping, with the exact inverse of the table's piecewise-quadratic
    ///   CDF (see [`LineShapeTable`] and the module source). Nodes lie inside the table, never
    ///   in a zero-density gap.
    ///
    /// A shape that fails [`LineShape::validate`] (possible only when built by hand) gives an
    /// empty rule rather than invented nodes.
    ///
    /// [^as46]: M. Abramowitz and I. A. Stegun (1964), Handbook of Mathematical Functions, NBS
    ///     Applied Mathematics Series 55, Eq. 25.4.46 (for the weight e^{−x²}; ξ = √2·x there).
    pub fn nodes(&self, n: usize) -> Vec<QuadratureNode> {
        match self {
            LineShape::Monochromatic => vec![QuadratureNode::new(0.0, 1.0)],
            LineShape::Gaussian { fwhm_mhz } => match check_fwhm(*fwhm_mhz) {
                Ok(fwhm) => {
                    let sigma = gaussian_sigma(fwhm);
                    gauss_hermite(n)
                        .into_iter()
                        .map(|q| QuadratureNode::new(sigma * q.offset_mhz, q.weight))
                        .collect()
                }
                Err(_) => Vec::new(),
            },
            LineShape::Lorentzian { fwhm_mhz } => match check_fwhm(*fwhm_mhz) {
                Ok(fwhm) => {
                    let gamma = 0.5 * fwhm;
                    gauss_legendre(n)
                        .into_iter()
                        .map(|q| {
                            // x = γ tan(π(u − ½)) = γ tan(πt/2); odd in t, so keep it exactly so.
                            let t = q.offset_mhz;
                            let x = gamma * (0.5 * PI * t.abs()).tan();
                            QuadratureNode::new(x.copysign(t), 0.5 * q.weight)
                        })
                        .collect()
                }
                Err(_) => Vec::new(),
            },
            LineShape::Table(table) => {
                match TableCdf::new(&table.offset_mhz, &table.relative_intensity) {
                    Ok(cdf) => gauss_legendre(n)
                        .into_iter()
                        .map(|q| {
                            let u = 0.5 * (1.0 + q.offset_mhz);
                            QuadratureNode::new(cdf.quantile(u), 0.5 * q.weight)
                        })
                        .collect(),
                    Err(_) => Vec::new(),
                }
            }
        }
    }
}

impl LineShape {
    /// An n-point quadrature of the line shape restricted to the window [lo, hi] (MHz offsets;
    /// ±∞ for none): ∫_lo^hi g(x) f(x) dx ≈ Σ wᵢ f(xᵢ), nodes inside the window, weights summing
    /// to the line's energy inside it (what a filter with that pass band lets through).
    ///
    /// Without a finite window this is [`LineShape::nodes`]. With one, the line is mapped
    /// through its cumulative distribution G and n-point Gauss–Legendre is applied on
    /// [G(lo), G(hi)] (for the Lorentzian, uniform in θ = arctan(x/γ)): no node is wasted on
    /// energy the filter blocks, and a Lorentzian's far wings, where the atmosphere's
    /// transmission varies on scales the rule cannot resolve, never enter. A Gaussian whose
    /// window is at least ±8σ keeps its Gauss–Hermite rule (the energy outside is 1e-15). A
    /// monochromatic line has one node of weight 1, or none outside the window.
    pub fn nodes_within(&self, n: usize, lo_mhz: f64, hi_mhz: f64) -> Vec<QuadratureNode> {
        if !(hi_mhz > lo_mhz) {
            return Vec::new();
        }
        if lo_mhz == f64::NEG_INFINITY && hi_mhz == f64::INFINITY {
            return self.nodes(n);
        }
        // Gauss–Legendre on [u_lo, u_hi] of the cumulative distribution, mapped by `quantile`.
        let on_cdf = |u_lo: f64, u_hi: f64, quantile: &dyn Fn(f64) -> f64| {
            let mass = u_hi - u_lo;
            if !(mass > 0.0) {
                return Vec::new();
            }
            gauss_legendre(n)
                .into_iter()
                .map(|q| {
                    let u = u_lo + 0.5 * (1.0 + q.offset_mhz) * mass;
                    QuadratureNode::new(quantile(u), 0.5 * q.weight * mass)
                })
                .collect()
        };
        match self {
            LineShape::Monochromatic => {
                if lo_mhz <= 0.0 && 0.0 <= hi_mhz {
                    vec![QuadratureNode::new(0.0, 1.0)]
                } else {
                    Vec::new()
                }
            }
            LineShape::Gaussian { fwhm_mhz } => match check_fwhm(*fwhm_mhz) {
                Ok(fwhm) => {
                    let sigma = gaussian_sigma(fwhm);
                    if lo_mhz <= -8.0 * sigma && hi_mhz >= 8.0 * sigma {
                        return self.nodes(n);
                    }
                    use statrs::distribution::{Continuous, ContinuousCDF, Normal};
                    let Ok(normal) = Normal::new(0.0, sigma) else {
                        return Vec::new();
                    };
                    // statrs' inverse is good to ~1e-9; one Newton step on the (accurate) CDF
                    // makes the quantile exact to rounding.
                    let quantile = |u: f64| {
                        let x = normal.inverse_cdf(u);
                        let d = normal.pdf(x);
                        if d > 0.0 {
                            x - (normal.cdf(x) - u) / d
                        } else {
                            x
                        }
                    };
                    on_cdf(normal.cdf(lo_mhz), normal.cdf(hi_mhz), &quantile)
                }
                Err(_) => Vec::new(),
            },
            LineShape::Lorentzian { fwhm_mhz } => match check_fwhm(*fwhm_mhz) {
                Ok(fwhm) => {
                    let gamma = 0.5 * fwhm;
                    // u = ½ + θ/π with θ = arctan(x/γ): uniform in θ.
                    let (t_lo, t_hi) = ((lo_mhz / gamma).atan(), (hi_mhz / gamma).atan());
                    on_cdf(0.5 + t_lo / PI, 0.5 + t_hi / PI, &|u| {
                        gamma * (PI * (u - 0.5)).tan()
                    })
                }
                Err(_) => Vec::new(),
            },
            LineShape::Table(table) => {
                match TableCdf::new(&table.offset_mhz, &table.relative_intensity) {
                    Ok(cdf) => on_cdf(cdf.cdf_at(lo_mhz), cdf.cdf_at(hi_mhz), &|u| cdf.quantile(u)),
                    Err(_) => Vec::new(),
                }
            }
        }
    }
}

/// Gauss–Hermite rule for the standard normal weight exp(−x²/2)/√(2π) (probabilists'
/// convention), n nodes (`n = 0` is treated as 1), weights summing to 1, nodes ascending and
/// exactly symmetric.
///
/// ∫ φ(x) f(x) dx = Σ wᵢ f(ξᵢ) exactly for f a polynomial of degree ≤ 2n − 1. The nodes ξᵢ are
/// the zeros of Heₙ, √2 times the physicists' nodes of Abramowitz & Stegun Eq. 25.4.46 and
/// Table 25.10; the weights are theirs divided by √π. Computed by Golub–Welsch[^gw] from the
/// Jacobi matrix with zero diagonal and off-diagonal βₖ = √k (k = 1 … n − 1), the recurrence
/// x pₖ = βₖ₊₁ pₖ₊₁ + βₖ pₖ₋₁ of the orthonormal pₖ = Heₖ/√(k!), then polished (module docs).
/// `offset_mhz` holds the dimensionless ξᵢ.
///
/// Above n ≈ 300 the outermost weights (≈ exp(−ξ²/2)) underflow to 0.
///
/// [^gw]: Golub & Welsch (1969), Math. Comp. 23, 221, doi:10.1090/S0025-5718-69-99647-1.
pub fn gauss_hermite(n: usize) -> Vec<QuadratureNode> {
    static RULES: [OnceLock<Vec<QuadratureNode>>; CACHED_RULES] =
        [const { OnceLock::new() }; CACHED_RULES];
    cached(&RULES, n, || symmetric_gauss_rule(n, |k| (k as f64).sqrt()))
}

/// Rules of up to this many nodes are computed once per process ([`cached`]).
const CACHED_RULES: usize = 65;

/// The rule of `n` nodes from `rules` (computed by `make` the first time), or `make`'s for a
/// larger n: a study rebuilds its laser's line-shape quadrature for every truth of every profile,
/// and the eigen decomposition behind it is the same each time. The values are `make`'s, bit
/// for bit.
fn cached(
    rules: &'static [OnceLock<Vec<QuadratureNode>>; CACHED_RULES],
    n: usize,
    make: impl FnOnce() -> Vec<QuadratureNode>,
) -> Vec<QuadratureNode> {
    match rules.get(n) {
        Some(rule) => rule.get_or_init(make).clone(),
        None => make(),
    }
}

/// Gauss–Legendre rule on \[−1, 1\], n nodes (`n = 0` is treated as 1), weights summing to 2,
/// nodes ascending and exactly symmetric.
///
/// ∫₋₁¹ f(x) dx = Σ wᵢ f(xᵢ) exactly for f a polynomial of degree ≤ 2n − 1 (Abramowitz &
/// Stegun Eq. 25.4.29, nodes and weights in Table 25.4). Computed by Golub–Welsch[^gw] from the
/// Jacobi matrix with zero diagonal and off-diagonal βₖ = k/√(4k² − 1), then polished (module
/// docs); nodes and weights are good to a few units of 1e-16.
///
/// [^gw]: Golub & Welsch (1969), Math. Comp. 23, 221, doi:10.1090/S0025-5718-69-99647-1.
pub fn gauss_legendre(n: usize) -> Vec<QuadratureNode> {
    static RULES: [OnceLock<Vec<QuadratureNode>>; CACHED_RULES] =
        [const { OnceLock::new() }; CACHED_RULES];
    cached(&RULES, n, || {
        symmetric_gauss_rule(n, |k| {
            let k = k as f64;
            k / (4.0 * k * k - 1.0).sqrt()
        })
        .into_iter()
        .map(|q| QuadratureNode::new(q.offset_mhz, 2.0 * q.weight))
        .collect()
    })
}

/// Golub–Welsch: nodes and weights of the n-point Gauss rule of a unit-mass weight whose
/// orthonormal polynomials satisfy x pₖ = βₖ₊₁ pₖ₊₁ + αₖ pₖ + βₖ pₖ₋₁ (here αₖ = 0).
///
/// The nodes are the eigenvalues of the Jacobi matrix J (Jₖₖ = αₖ, Jₖ₋₁,ₖ = βₖ) and the weights
/// the squared first components of its normalised eigenvectors (Golub & Welsch 1969, §2).
/// Nodes ascending.
fn golub_welsch(n: usize, beta: &[f64]) -> Vec<QuadratureNode> {
    let jacobi = DMatrix::from_fn(n, n, |i, j| {
        if i.abs_diff(j) == 1 {
            beta[i.max(j)]
        } else {
            0.0
        }
    });
    let eigen = SymmetricEigen::new(jacobi);
    let mut rule: Vec<QuadratureNode> = (0..n)
        .map(|i| {
            let v0 = eigen.eigenvectors[(0, i)];
            QuadratureNode::new(eigen.eigenvalues[i], v0 * v0)
        })
        .collect();
    rule.sort_by(|a, b| a.offset_mhz.total_cmp(&b.offset_mhz));
    rule
}

/// p_n(x), p_n′(x) and Σ_{k<n} pₖ(x)² of the orthonormal polynomials of recurrence β (β₀ = 0).
fn orthonormal_at(n: usize, beta: &[f64], x: f64) -> (f64, f64, f64) {
    let (mut p_prev, mut p) = (0.0, 1.0);
    let (mut d_prev, mut d) = (0.0, 0.0);
    let mut sum_sq = 0.0;
    for k in 0..n {
        sum_sq += p * p;
        let p_next = (x * p - beta[k] * p_prev) / beta[k + 1];
        let d_next = (p + x * d - beta[k] * d_prev) / beta[k + 1];
        (p_prev, p) = (p, p_next);
        (d_prev, d) = (d, d_next);
    }
    (p, d, sum_sq)
}

/// A Golub–Welsch node polished by Newton steps on pₙ, with its Christoffel weight
/// 1/Σ_{k<n} pₖ(x)² (the squared first eigenvector component: the eigenvector of J at x is
/// (p₀(x), …, pₙ₋₁(x)) with p₀ = 1; Golub & Welsch 1969, §2).
fn polished(n: usize, beta: &[f64], eigenvalue: f64) -> QuadratureNode {
    let mut x = eigenvalue;
    for _ in 0..MAX_NEWTON_STEPS {
        let (p, d, _) = orthonormal_at(n, beta, x);
        let step = p / d;
        if !step.is_finite() {
            break;
        }
        x -= step;
        if step.abs() <= NEWTON_STOP_ULPS * f64::EPSILON * x.abs() {
            break;
        }
    }
    if !((x - eigenvalue).abs() <= NEWTON_MAX_MOVE * (1.0 + eigenvalue.abs())) {
        x = eigenvalue;
    }
    let (_, _, sum_sq) = orthonormal_at(n, beta, x);
    QuadratureNode::new(x, 1.0 / sum_sq)
}

/// The n-point Gauss rule (n = 0 read as 1) of a symmetric unit-mass weight with recurrence
/// coefficients βₖ = `beta(k)`: Golub–Welsch, then polished, mirrored to exact symmetry and the
/// weights scaled to sum to 1 (a change of a few ulps).
fn symmetric_gauss_rule(n: usize, beta: impl Fn(usize) -> f64) -> Vec<QuadratureNode> {
    let n = n.max(1);
    if n == 1 {
        return vec![QuadratureNode::new(0.0, 1.0)];
    }
    let beta: Vec<f64> = (0..=n)
        .map(|k| if k == 0 { 0.0 } else { beta(k) })
        .collect();
    let raw = golub_welsch(n, &beta);
    let upper: Vec<QuadratureNode> = raw[n - n / 2..]
        .iter()
        .map(|q| polished(n, &beta, q.offset_mhz.abs()))
        .collect();
    let mut rule: Vec<QuadratureNode> = upper
        .iter()
        .rev()
        .map(|q| QuadratureNode::new(-q.offset_mhz, q.weight))
        .collect();
    if n % 2 == 1 {
        // The middle node is 0 exactly for a symmetric weight.
        let (_, _, sum_sq) = orthonormal_at(n, &beta, 0.0);
        rule.push(QuadratureNode::new(0.0, 1.0 / sum_sq));
    }
    rule.extend(upper);
    let total: f64 = rule.iter().map(|q| q.weight).sum();
    rule.iter_mut().for_each(|q| q.weight /= total);
    rule
}

#[cfg(test)]
mod tests {
    use super::*;

    fn moment(rule: &[QuadratureNode], k: i32) -> f64 {
        rule.iter().map(|q| q.weight * q.offset_mhz.powi(k)).sum()
    }

    /// (k − 1)!! for even k (the k-th moment of the standard normal), 0 for odd k.
    fn normal_moment(k: i32) -> f64 {
        if k % 2 == 1 {
            return 0.0;
        }
        (1..k).step_by(2).map(f64::from).product()
    }

    fn gaussian_table(points: usize, sigma: f64, half_range_sigmas: f64) -> LineShapeTable {
        let x: Vec<f64> = (0..points)
            .map(|i| sigma * half_range_sigmas * (2.0 * i as f64 / (points - 1) as f64 - 1.0))
            .collect();
        let y = x
            .iter()
            .map(|x| (-0.5 * (x / sigma).powi(2)).exp())
            .collect();
        LineShapeTable {
            source: PathBuf::from("gauss.csv"),
            offset_mhz: x,
            relative_intensity: y,
        }
    }

    fn uneven_table() -> LineShapeTable {
        // Uniform, ramp down to a zero gap, ramp up, uniform at another height.
        LineShapeTable {
            source: PathBuf::from("uneven.csv"),
            offset_mhz: vec![-30.0, -10.0, 0.0, 5.0, 20.0, 45.0, 50.0],
            relative_intensity: vec![2.0, 2.0, 0.0, 0.0, 3.0, 3.0, 0.0],
        }
    }

    fn all_shapes() -> Vec<LineShape> {
        vec![
            LineShape::Monochromatic,
            LineShape::gaussian(120.0).unwrap(),
            LineShape::lorentzian(35.0).unwrap(),
            LineShape::Table(gaussian_table(2001, 50.0, 8.0)),
            LineShape::Table(uneven_table()),
        ]
    }

    /// The CDF of a piecewise-linear density, integrated forwards segment by segment (the
    /// independent counterpart of `TableCdf::quantile`).
    fn forward_cdf(t: &LineShapeTable, x: f64) -> f64 {
        let (xs, ys) = (&t.offset_mhz, &t.relative_intensity);
        let mut below = 0.0;
        let mut total = 0.0;
        for j in 0..xs.len() - 1 {
            let h = xs[j + 1] - xs[j];
            total += 0.5 * (ys[j] + ys[j + 1]) * h;
            let s = (x - xs[j]).clamp(0.0, h);
            below += ys[j] * s + 0.5 * (ys[j + 1] - ys[j]) / h * s * s;
        }
        below / total
    }

    #[test]
    fn nodes_within_a_window_carry_the_energy_inside_it() {
        // Mass inside [lo, hi]: Gaussian Φ differences, Lorentzian arctan differences, and the
        // rule integrates a smooth function over the window as a dense midpoint rule does.
        let g = LineShape::gaussian(100.0).unwrap();
        let l = LineShape::lorentzian(100.0).unwrap();
        let sigma = gaussian_sigma(100.0);
        let f = |x: f64| 1.0 / (1.0 + (x / 70.0 - 0.3).powi(2));
        for (shape, lo, hi) in [(&g, -60.0, 90.0), (&l, -60.0, 90.0), (&l, -500.0, 500.0)] {
            let rule = shape.nodes_within(24, lo, hi);
            assert!(rule.iter().all(|q| q.offset_mhz > lo && q.offset_mhz < hi));
            let m = 200_000;
            let h = (hi - lo) / m as f64;
            let (mut mass, mut integral) = (0.0, 0.0);
            for i in 0..m {
                let x = lo + (i as f64 + 0.5) * h;
                mass += shape.density_per_mhz(x) * h;
                integral += shape.density_per_mhz(x) * f(x) * h;
            }
            let w: f64 = rule.iter().map(|q| q.weight).sum();
            let q: f64 = rule.iter().map(|q| q.weight * f(q.offset_mhz)).sum();
            assert!(
                (w / mass - 1.0).abs() < 1e-9,
                "{shape:?}: mass {w} vs {mass}"
            );
            // Measured: 1.6e-9 for the cut Gaussian (its quantile's steep ends), < 1e-12 else.
            assert!(
                (q / integral - 1.0).abs() < 5e-9,
                "{shape:?}: {q} vs {integral}"
            );
        }
        // A window of ±8σ or more keeps the Gauss–Hermite rule; none is the full rule.
        assert_eq!(g.nodes_within(5, -8.0 * sigma, 8.0 * sigma), g.nodes(5));
        assert_eq!(
            l.nodes_within(5, f64::NEG_INFINITY, f64::INFINITY),
            l.nodes(5)
        );
        // Monochromatic: inside or blocked.
        assert_eq!(LineShape::Monochromatic.nodes_within(3, -1.0, 1.0).len(), 1);
        assert!(
            LineShape::Monochromatic
                .nodes_within(3, 1.0, 2.0)
                .is_empty()
        );
        // A table's window mass is its CDF difference.
        let t = LineShape::Table(LineShapeTable {
            source: "t".into(),
            offset_mhz: vec![-10.0, 0.0, 10.0],
            relative_intensity: vec![0.0, 1.0, 0.0],
        });
        let w: f64 = t.nodes_within(8, -5.0, 10.0).iter().map(|q| q.weight).sum();
        assert!((w - 0.875).abs() < 1e-14, "{w}");
    }

    #[test]
    fn mhz_per_cm1_is_c_times_one_per_cm() {
        let c = crate::constants::SPEED_OF_LIGHT_M_PER_S;
        assert_eq!(MHZ_PER_CM1, c * 100.0 / 1e6);
    }

    #[test]
    fn weights_positive_sum_to_one_nodes_ascending() {
        for shape in all_shapes() {
            for n in 1..=20 {
                let rule = shape.nodes(n);
                let expected = if shape == LineShape::Monochromatic {
                    1
                } else {
                    n
                };
                assert_eq!(rule.len(), expected, "{shape:?} n={n}");
                let sum: f64 = rule.iter().map(|q| q.weight).sum();
                // Measured worst 2.2e-16 (one ulp); documented 1e-14.
                assert!(
                    (sum - 1.0).abs() <= 1e-15,
                    "{shape:?} n={n}: Σw − 1 = {}",
                    sum - 1.0
                );
                assert!(rule.iter().all(|q| q.weight > 0.0), "{shape:?} n={n}");
                assert!(
                    rule.windows(2).all(|p| p[0].offset_mhz < p[1].offset_mhz),
                    "{shape:?} n={n}: {rule:?}"
                );
            }
            assert_eq!(shape.nodes(0), shape.nodes(1));
        }
        assert_eq!(
            LineShape::Monochromatic.nodes(7),
            vec![QuadratureNode::new(0.0, 1.0)]
        );
    }

    #[test]
    fn gaussian_and_lorentzian_nodes_are_exactly_symmetric() {
        for shape in [
            LineShape::gaussian(80.0).unwrap(),
            LineShape::lorentzian(80.0).unwrap(),
        ] {
            for n in 1..=20 {
                let rule = shape.nodes(n);
                for (a, b) in rule.iter().zip(rule.iter().rev()) {
                    assert_eq!(a.offset_mhz, -b.offset_mhz, "{shape:?} n={n}");
                    assert_eq!(a.weight, b.weight, "{shape:?} n={n}");
                }
            }
        }
    }

    #[test]
    fn gaussian_moments_are_exact_to_degree_2n_minus_1() {
        // E[x^k] = σ^k (k − 1)!! for even k, 0 for odd k. Measured worst relative error 2.4e-15.
        let fwhm = 250.0;
        let sigma = fwhm / (2.0 * (2.0 * 2f64.ln()).sqrt());
        let shape = LineShape::gaussian(fwhm).unwrap();
        let mut worst: f64 = 0.0;
        for n in 1..=12 {
            let rule = shape.nodes(n);
            for k in 0..=(2 * n as i32 - 1) {
                let got = moment(&rule, k);
                let scale = sigma.powi(k);
                if k % 2 == 1 {
                    // Odd: the symmetric terms cancel; compare with the size of the terms.
                    let size: f64 = rule
                        .iter()
                        .map(|q| q.weight * q.offset_mhz.abs().powi(k))
                        .sum();
                    assert!(got.abs() <= 1e-15 * size, "n={n} k={k}: {got}");
                } else {
                    let rel = (got / (scale * normal_moment(k)) - 1.0).abs();
                    worst = worst.max(rel);
                    assert!(rel <= 1e-14, "n={n} k={k}: relative error {rel:e}");
                }
            }
            // One degree more is not exact (for n ≥ 1): the rule really has degree 2n − 1.
            let k = 2 * n as i32;
            let rel = (moment(&rule, k) / (sigma.powi(k) * normal_moment(k)) - 1.0).abs();
            assert!(rel > 1e-3, "n={n}: degree 2n integrated exactly?");
        }
        eprintln!("Gauss–Hermite worst relative moment error (n ≤ 12, k ≤ 2n − 1): {worst:.1e}");
    }

    /// The rules kept per process are the rules computed afresh, bit for bit, below and above
    /// the largest one kept, asked for once or many times.
    #[test]
    fn cached_rules_are_the_computed_rules() {
        let bits = |r: &[QuadratureNode]| {
            r.iter()
                .map(|q| (q.offset_mhz.to_bits(), q.weight.to_bits()))
                .collect::<Vec<_>>()
        };
        for n in [0, 1, 2, 5, 8, 33, 64, 65, 70] {
            let hermite = symmetric_gauss_rule(n, |k| (k as f64).sqrt());
            let legendre: Vec<QuadratureNode> = symmetric_gauss_rule(n, |k| {
                let k = k as f64;
                k / (4.0 * k * k - 1.0).sqrt()
            })
            .into_iter()
            .map(|q| QuadratureNode::new(q.offset_mhz, 2.0 * q.weight))
            .collect();
            for _ in 0..2 {
                assert_eq!(bits(&gauss_hermite(n)), bits(&hermite), "Hermite {n}");
                assert_eq!(bits(&gauss_legendre(n)), bits(&legendre), "Legendre {n}");
            }
        }
    }

    #[test]
    fn gauss_hermite_5_point_matches_abramowitz_stegun() {
        // A&S Table 25.10 (weight e^{−x²}): x = 0, ±0.958572464613819, ±2.020182870456086;
        // w = 0.945308720482942, 0.393619323152241, 0.019953242059046. Probabilists' nodes are
        // √2·x and weights w/√π.
        let as_x = [0.958_572_464_613_819, 2.020_182_870_456_086];
        let as_w = [
            0.945_308_720_482_942,
            0.393_619_323_152_241,
            0.019_953_242_059_046,
        ];
        let rule = gauss_hermite(5);
        let sqrt_pi = PI.sqrt();
        assert_eq!(rule[2].offset_mhz, 0.0);
        for (i, &x) in as_x.iter().enumerate() {
            let got = rule[3 + i].offset_mhz;
            assert!((got - 2f64.sqrt() * x).abs() <= 2e-15, "node {i}: {got}");
        }
        for (i, &w) in as_w.iter().enumerate() {
            let got = rule[2 + i].weight;
            assert!((got - w / sqrt_pi).abs() <= 1e-15, "weight {i}: {got}");
        }
        // Closed form: He₅ = x⁵ − 10x³ + 15x, so ξ² = 5 ∓ √10; w₀ = 8/15.
        assert!((rule[3].offset_mhz.powi(2) - (5.0 - 10f64.sqrt())).abs() <= 1e-15);
        assert!((rule[4].offset_mhz.powi(2) - (5.0 + 10f64.sqrt())).abs() <= 2.5e-15);
        assert!((rule[2].weight - 8.0 / 15.0).abs() <= 2e-16);
    }

    #[test]
    fn gauss_hermite_tail_weight_is_relatively_accurate() {
        // n = 20, largest node and its weight, from mpmath 1.3 at 50 digits:
        // ξ = 7.619048541679758291, w = n!/(n² He₁₉(ξ)²) = 1.257800672437927015e-13;
        // next: ξ = 6.510590157013654486, w = 2.482062362315178646e-10.
        let rule = gauss_hermite(20);
        let check = |q: QuadratureNode, x: f64, w: f64| {
            assert!((q.offset_mhz / x - 1.0).abs() <= 4e-16, "{q:?}");
            assert!((q.weight / w - 1.0).abs() <= 5e-15, "{q:?}");
        };
        check(rule[19], 7.619_048_541_679_758, 1.257_800_672_437_927e-13);
        check(rule[18], 6.510_590_157_013_654, 2.482_062_362_315_179e-10);
        // The raw eigenvector weights agree to ~1e-16 absolute, which is all they are good for:
        // for these two tail weights that is a relative error of 6.7e-10 and 8.2e-12 (measured
        // with nalgebra 0.35), against 1.1e-15 and 2.0e-15 after polishing.
        let beta: Vec<f64> = (0..=20).map(|k| (k as f64).sqrt()).collect();
        let raw = golub_welsch(20, &beta);
        for (a, b) in raw.iter().zip(&rule) {
            assert!((a.weight - b.weight).abs() <= 1e-15);
            assert!((a.offset_mhz - b.offset_mhz).abs() <= 2e-14);
        }
    }

    #[test]
    fn gauss_legendre_integrates_polynomials_exactly() {
        let mut worst: f64 = 0.0;
        for n in 1..=20 {
            let rule = gauss_legendre(n);
            for k in 0..=(2 * n as i32 - 1) {
                let exact = if k % 2 == 1 {
                    0.0
                } else {
                    2.0 / f64::from(k + 1)
                };
                let err = (moment(&rule, k) - exact).abs();
                worst = worst.max(err);
                assert!(err <= 2e-15, "n={n} k={k}: error {err:e}");
            }
        }
        eprintln!("Gauss–Legendre worst moment error (n ≤ 20, k ≤ 2n − 1): {worst:.1e}");
    }

    #[test]
    fn gauss_legendre_5_point_matches_abramowitz_stegun() {
        // A&S Table 25.4: ±0.906179845938664, ±0.538469310105683, 0;
        // w = 0.236926885056189, 0.478628670499366, 0.568888888888889.
        let rule = gauss_legendre(5);
        let x = [
            -0.906_179_845_938_664,
            -0.538_469_310_105_683,
            0.0,
            0.538_469_310_105_683,
            0.906_179_845_938_664,
        ];
        let w = [
            0.236_926_885_056_189,
            0.478_628_670_499_366,
            0.568_888_888_888_889,
            0.478_628_670_499_366,
            0.236_926_885_056_189,
        ];
        for i in 0..5 {
            assert!((rule[i].offset_mhz - x[i]).abs() <= 1e-15, "{:?}", rule[i]);
            assert!((rule[i].weight - w[i]).abs() <= 1e-15, "{:?}", rule[i]);
        }
        // Closed form: x² = (5 ∓ 2√(10/7))/9, w = (322 ± 13√70)/900, w₀ = 128/225 (measured
        // differences ≤ 2 ulps, i.e. ≤ 2.2e-16).
        let r = 2.0 * (10.0f64 / 7.0).sqrt();
        assert!((rule[3].offset_mhz - ((5.0 - r) / 9.0).sqrt()).abs() <= 2e-16);
        assert!((rule[4].offset_mhz - ((5.0 + r) / 9.0).sqrt()).abs() <= 2e-16);
        assert!((rule[3].weight - (322.0 + 13.0 * 70f64.sqrt()) / 900.0).abs() <= 3e-16);
        assert!((rule[4].weight - (322.0 - 13.0 * 70f64.sqrt()) / 900.0).abs() <= 3e-16);
        assert!((rule[2].weight - 128.0 / 225.0).abs() <= 3e-16);
    }

    #[test]
    fn lorentzian_rule_converges_on_a_lorentzian_filter() {
        // ∫ L_γ(x) a²/(a² + x²) dx = πa (L_γ * L_a)(0) = πa L_{γ+a}(0) = a/(a + γ)
        // (the convolution of two Lorentzians is the Lorentzian of summed half widths).
        let fwhm = 40.0;
        let gamma = 0.5 * fwhm;
        let shape = LineShape::lorentzian(fwhm).unwrap();
        for (a, bounds) in [
            // Measured: 4.50e-3, 8.20e-5, 1.55e-8.
            (10.0 * gamma, [4.6e-3, 8.5e-5, 1.6e-8]),
            // Measured: 4.37e-11, 1.1e-16, 5.6e-17 (f(x(u)) = cos²(π(u − ½)) is entire).
            (gamma, [4.5e-11, 3e-16, 3e-16]),
        ] {
            let exact = a / (a + gamma);
            let mut errors = Vec::new();
            for (n, bound) in [8, 16, 32].into_iter().zip(bounds) {
                let got: f64 = shape
                    .nodes(n)
                    .iter()
                    .map(|q| q.weight * a * a / (a * a + q.offset_mhz * q.offset_mhz))
                    .sum();
                let err = (got - exact).abs();
                eprintln!("Lorentzian a = {}γ, n = {n}: error {err:.2e}", a / gamma);
                assert!(err <= bound, "a={a} n={n}: error {err:e} > {bound:e}");
                errors.push(err);
            }
            if a > gamma {
                assert!(errors[1] < errors[0] / 10.0 && errors[2] < errors[1] / 10.0);
            }
        }
    }

    #[test]
    fn dense_gaussian_table_reproduces_the_gaussian() {
        // 2001 points over ±8σ: step h = 0.008σ. The piecewise-linear density g_h differs from
        // the Gaussian by O(h²): on average by −h²g″/12, so its variance is σ² − h²/6 to leading
        // order (∫x²g″ dx = 2), and its CDF by at most ≈ h²·max|g′|/12 = h²φ(1)/(12σ²) (at ±σ).
        // Checked for every node of n = 1 … 32.
        let sigma = 50.0;
        let table = gaussian_table(2001, sigma, 8.0);
        let h = table.offset_mhz[1] - table.offset_mhz[0];
        let shape = LineShape::Table(table.clone());
        let normal_cdf = |x: f64| 0.5 * statrs::function::erf::erfc(-x / (sigma * 2f64.sqrt()));
        let (mut worst_cdf, mut worst_own_cdf, mut worst_mean, mut worst_var) =
            (0f64, 0f64, 0f64, 0f64);
        for n in 1..=32 {
            let rule = shape.nodes(n);
            let legendre = gauss_legendre(n);
            let mut exact_quantile_var = 0.0;
            for (q, t) in rule.iter().zip(&legendre) {
                let u = 0.5 * (1.0 + t.offset_mhz);
                // The node sits where the Gaussian's CDF is u, to the discretisation error…
                worst_cdf = worst_cdf.max((normal_cdf(q.offset_mhz) - u).abs());
                // …and exactly where the table's own CDF is u.
                worst_own_cdf = worst_own_cdf.max((forward_cdf(&table, q.offset_mhz) - u).abs());
                let x = bisect(|x| normal_cdf(x) - u, -10.0 * sigma, 10.0 * sigma);
                exact_quantile_var += 0.5 * t.weight * x * x;
            }
            worst_mean = worst_mean.max(moment(&rule, 1).abs() / sigma);
            // The same u-rule on the exact Gaussian quantile: the u-rule's own error is common to
            // both, so the variances differ by the discretisation alone.
            worst_var =
                worst_var.max((moment(&rule, 2) - exact_quantile_var).abs() / (sigma * sigma));
        }
        let predicted_cdf = h * h * (-0.5f64).exp() / ((2.0 * PI).sqrt() * sigma * sigma) / 12.0;
        let predicted_var = h * h / (6.0 * sigma * sigma);
        // Measured: 1.2904e-6 vs 1.2905e-6 predicted; 1.0643e-5 vs 1.0667e-5; 5.6e-16; 2.3e-15.
        assert!(
            worst_cdf <= 1.01 * predicted_cdf,
            "{worst_cdf:e} vs {predicted_cdf:e}"
        );
        assert!(
            worst_var <= 1.01 * predicted_var,
            "{worst_var:e} vs {predicted_var:e}"
        );
        assert!(worst_own_cdf <= 1e-15, "{worst_own_cdf:e}");
        assert!(worst_mean <= 1e-14, "{worst_mean:e}");
    }

    fn bisect(f: impl Fn(f64) -> f64, mut lo: f64, mut hi: f64) -> f64 {
        for _ in 0..200 {
            let mid = 0.5 * (lo + hi);
            if f(mid) < 0.0 {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        0.5 * (lo + hi)
    }

    #[test]
    fn uniform_table_gives_legendre_nodes_on_its_interval() {
        let (a, b) = (-35.0, 65.0);
        let shape = LineShape::Table(LineShapeTable {
            source: PathBuf::from("flat.csv"),
            offset_mhz: vec![a, b],
            relative_intensity: vec![0.3, 0.3],
        });
        for n in 1..=20 {
            for (q, t) in shape.nodes(n).iter().zip(gauss_legendre(n)) {
                let x = a + (b - a) * 0.5 * (1.0 + t.offset_mhz);
                assert!((q.offset_mhz - x).abs() <= 1e-14 * (b - a), "n={n}");
                assert_eq!(q.weight, 0.5 * t.weight);
            }
        }
    }

    #[test]
    fn table_quantile_inverts_ramps_and_skips_zero_gaps() {
        // Rising ramp from 0: density 2x on [0, 1], CDF x², quantile √u.
        let ramp = LineShape::Table(LineShapeTable {
            source: PathBuf::from("ramp.csv"),
            offset_mhz: vec![0.0, 1.0],
            relative_intensity: vec![0.0, 5.0],
        });
        for (q, t) in ramp.nodes(9).iter().zip(gauss_legendre(9)) {
            let u = 0.5 * (1.0 + t.offset_mhz);
            assert!((q.offset_mhz - u.sqrt()).abs() <= 2e-16, "{q:?}");
        }
        // Falling ramp to 0: density 2(1 − x), CDF 1 − (1 − x)², quantile 1 − √(1 − u).
        let fall = LineShape::Table(LineShapeTable {
            source: PathBuf::from("fall.csv"),
            offset_mhz: vec![0.0, 1.0],
            relative_intensity: vec![5.0, 0.0],
        });
        for (q, t) in fall.nodes(9).iter().zip(gauss_legendre(9)) {
            let u = 0.5 * (1.0 + t.offset_mhz);
            assert!(
                (q.offset_mhz - (1.0 - (1.0 - u).sqrt())).abs() <= 4e-16,
                "{q:?}"
            );
        }
        // Uneven table with a zero-density gap on [0, 5]: CDF round trip, nothing in the gap.
        let table = uneven_table();
        let shape = LineShape::Table(table.clone());
        for n in 1..=40 {
            for (q, t) in shape.nodes(n).iter().zip(gauss_legendre(n)) {
                let u = 0.5 * (1.0 + t.offset_mhz);
                assert!(
                    (forward_cdf(&table, q.offset_mhz) - u).abs() <= 1e-15,
                    "n={n} {q:?}"
                );
                assert!(
                    !(q.offset_mhz > 0.0 && q.offset_mhz < 5.0),
                    "n={n}: {q:?} in gap"
                );
            }
        }
    }

    #[test]
    fn densities_integrate_to_one_and_peak_where_expected() {
        let fwhm = 90.0;
        let trapezoid = |shape: &LineShape, lo: f64, hi: f64, steps: usize| {
            let h = (hi - lo) / steps as f64;
            let inner: f64 = (1..steps)
                .map(|i| shape.density_per_mhz(lo + h * i as f64))
                .sum();
            h * (inner + 0.5 * (shape.density_per_mhz(lo) + shape.density_per_mhz(hi)))
        };
        // Gaussian: trapezoid over ±12σ converges geometrically.
        let g = LineShape::gaussian(fwhm).unwrap();
        let sigma = fwhm / (2.0 * (2.0 * 2f64.ln()).sqrt());
        let area = trapezoid(&g, -12.0 * sigma, 12.0 * sigma, 480);
        assert!((area - 1.0).abs() <= 1e-15, "{area}");
        let peak = 2.0 * (2f64.ln() / PI).sqrt() / fwhm;
        assert!((g.density_per_mhz(0.0) / peak - 1.0).abs() <= 1e-15);
        assert!((g.density_per_mhz(0.5 * fwhm) / peak - 0.5).abs() <= 1e-15);
        // Lorentzian: over ±X the area is (2/π) arctan(X/γ). The trapezoid rule's leading error,
        // (h²/12)(g′(X) − g′(−X)) = −1.3e-12 here (Euler–Maclaurin), is added to the truth.
        let l = LineShape::lorentzian(fwhm).unwrap();
        let gamma = 0.5 * fwhm;
        let (x_max, steps) = (200.0 * gamma, 40_000);
        let area = trapezoid(&l, -x_max, x_max, steps);
        let h = 2.0 * x_max / steps as f64;
        let slope_at_x_max = -2.0 * x_max * gamma / (PI * (x_max * x_max + gamma * gamma).powi(2));
        let expected = 2.0 / PI * (x_max / gamma).atan() + h * h / 12.0 * 2.0 * slope_at_x_max;
        assert!((area - expected).abs() <= 1e-14, "{area} vs {expected}");
        let peak = 2.0 / (PI * fwhm);
        assert!((l.density_per_mhz(0.0) / peak - 1.0).abs() <= 1e-15);
        assert!((l.density_per_mhz(-gamma) / peak - 0.5).abs() <= 1e-15);
        // Table: piecewise linear, so a trapezoid on a grid through its points is exact.
        let table = uneven_table();
        let t = LineShape::Table(table.clone());
        let mut area = 0.0;
        for j in 0..table.offset_mhz.len() - 1 {
            let (lo, hi) = (table.offset_mhz[j], table.offset_mhz[j + 1]);
            area += trapezoid(&t, lo, hi, 7);
        }
        assert!((area - 1.0).abs() <= 1e-15, "{area}");
        assert_eq!(t.density_per_mhz(-30.000_001), 0.0);
        assert_eq!(t.density_per_mhz(50.000_001), 0.0);
        assert_eq!(t.density_per_mhz(2.5), 0.0);
        // Height 2 on [−30, −10]; total area 2·20 + 2·10/2 + 3·15/2 + 3·25 + 3·5/2 = 155.
        assert!((t.density_per_mhz(-20.0) - 2.0 / 155.0).abs() <= 1e-17);
        // Monochromatic: a delta.
        let m = LineShape::Monochromatic;
        assert_eq!(m.density_per_mhz(0.0), f64::INFINITY);
        assert_eq!(m.density_per_mhz(1e-300), 0.0);
    }

    #[test]
    fn constructors_and_validate_reject_bad_widths() {
        for bad in [0.0, -3.0, f64::NAN, f64::INFINITY] {
            let e = LineShape::gaussian(bad).unwrap_err();
            assert!(e.contains(&format!("{bad}")), "{e}");
            let e = LineShape::lorentzian(bad).unwrap_err();
            assert!(e.contains(&format!("{bad}")), "{e}");
            let by_hand = LineShape::Gaussian { fwhm_mhz: bad };
            assert!(by_hand.validate().is_err());
            assert!(by_hand.nodes(4).is_empty());
            assert!(by_hand.density_per_mhz(0.0).is_nan());
            assert!(LineShape::Lorentzian { fwhm_mhz: bad }.nodes(4).is_empty());
        }
        assert_eq!(
            LineShape::gaussian(1e-3),
            Ok(LineShape::Gaussian { fwhm_mhz: 1e-3 })
        );
        let mut t = uneven_table();
        assert!(LineShape::Table(t.clone()).validate().is_ok());
        t.relative_intensity[3] = -1.0;
        let e = t.validate().unwrap_err();
        assert!(
            e.contains("row 4") && e.contains("relative_intensity"),
            "{e}"
        );
        assert!(LineShape::Table(t.clone()).nodes(3).is_empty());
        t.relative_intensity.pop();
        assert!(t.validate().unwrap_err().contains("7 offsets but 6"));
    }

    fn parse_err(text: &str) -> InputError {
        LineShapeTable::parse(Path::new("line.csv"), text).unwrap_err()
    }

    #[test]
    fn parses_a_table_with_comments_and_a_byte_order_mark() {
        let text =
            "\u{feff}# measured\noffset_mhz,relative_intensity\n-10,0\n\n# peak\n0,1\n10,0\n";
        let t = LineShapeTable::parse(Path::new("line.csv"), text).unwrap();
        assert_eq!(t.offset_mhz, vec![-10.0, 0.0, 10.0]);
        assert_eq!(t.relative_intensity, vec![0.0, 1.0, 0.0]);
        assert_eq!(t.source, PathBuf::from("line.csv"));
        assert!(t.validate().is_ok());
    }

    #[test]
    fn parse_errors_name_line_and_column() {
        let h = "# c\noffset_mhz,relative_intensity\n";
        let cases: [(String, usize, &str, &str); 13] = [
            (
                format!("{h}0,1\n1,x2\n"),
                4,
                INTENSITY_COLUMN,
                "not a number",
            ),
            (format!("{h}0,1\n1e,2\n"), 4, OFFSET_COLUMN, "not a number"),
            (format!("{h}0,1\ninf,2\n"), 4, OFFSET_COLUMN, "not finite"),
            (
                format!("{h}0,NaN\n1,2\n"),
                3,
                INTENSITY_COLUMN,
                "not finite",
            ),
            (
                format!("{h}0,1\n2,1\n1,1\n"),
                5,
                OFFSET_COLUMN,
                "strictly increase",
            ),
            (
                format!("{h}0,1\n0,1\n"),
                4,
                OFFSET_COLUMN,
                "strictly increase",
            ),
            (format!("{h}0,1\n1,-0.5\n"), 4, INTENSITY_COLUMN, "negative"),
            (
                format!("{h}0,0\n1,0\n2,0\n"),
                3,
                INTENSITY_COLUMN,
                "zero area",
            ),
            (format!("{h}0,1\n"), 3, "row", "at least 2 rows"),
            (h.to_string(), 2, "row", "at least 2 rows"),
            (
                "offset_mhz,intensity\n0,1\n1,1\n".to_string(),
                1,
                "intensity",
                "header",
            ),
            (
                "#\n\noffset_mhz\n0\n1\n".to_string(),
                3,
                INTENSITY_COLUMN,
                "header",
            ),
            (format!("{h}0,1\n1,2,3\n"), 4, "row", "fields"),
        ];
        for (text, line, field, words) in cases {
            let e = parse_err(&text);
            assert_eq!(e.path, PathBuf::from("line.csv"), "{text}");
            assert_eq!(e.line, Some(line), "{text}: {e}");
            assert_eq!(e.field.as_deref(), Some(field), "{text}: {e}");
            assert!(e.message.contains(words), "{text}: {e}");
        }
        assert_eq!(
            parse_err(&format!("{h}0,1\n1,x2\n")).to_string(),
            "line.csv:4: `relative_intensity`: `x2` is not a number"
        );
        assert!(
            parse_err(&format!("{h}-1e308,1\n1e308,1\n"))
                .message
                .contains("overflows")
        );
        assert!(parse_err("").message.contains("empty"));
    }

    #[test]
    fn reads_a_file_and_names_a_missing_one() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("seed.csv");
        std::fs::write(&path, "offset_mhz,relative_intensity\n-5,1\n5,1\n").unwrap();
        let t = LineShapeTable::read(&path).unwrap();
        assert_eq!(t.source, path);
        assert_eq!(t.offset_mhz, vec![-5.0, 5.0]);
        let missing = dir.path().join("none.csv");
        let e = LineShapeTable::read(&missing).unwrap_err();
        assert_eq!(e.path, missing);
    }
}
