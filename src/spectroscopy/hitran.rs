//! HITRAN line lists: the 160-character `.par` record (HITRAN2004 and later; HAPI's `.data`
//! tables hold the same records).
//!
//! Record layout (Rothman et al. 2005, JQSRT 96, 139, Table 1), 1-based columns:
//!
//! | cols | field | format | unit |
//! |---|---|---|---|
//! | 1–2 | molecule number | I2 | |
//! | 3 | isotopologue number (`0` = 10, `A` = 11, `B` = 12) | I1 | |
//! | 4–15 | ν, vacuum wavenumber | F12.6 | cm⁻¹ |
//! | 16–25 | S, intensity at 296 K (natural abundance) | E10.3 | cm/molecule |
//! | 26–35 | A, Einstein coefficient | E10.3 | s⁻¹ |
//! | 36–40 | γ_air, air-broadened HWHM at 296 K, 1 atm | F5.4 | cm⁻¹/atm |
//! | 41–45 | γ_self, self-broadened HWHM | F5.3 | cm⁻¹/atm |
//! | 46–55 | E″, lower-state energy | F10.4 | cm⁻¹ |
//! | 56–59 | n_air, temperature exponent of γ_air | F4.2 | |
//! | 60–67 | δ_air, air pressure shift | F8.6 | cm⁻¹/atm |
//! | 68–127 | upper/lower global and local quanta | 4 × A15 | |
//! | 128–146 | uncertainty codes, references, line-mixing flag | | |
//! | 147–160 | g′, g″ statistical weights | 2 × F7.1 | |

use std::path::{Path, PathBuf};

use super::SpectroscopyError;
use super::isotopologues::Isotopologue;
use crate::input::{InputError, read_to_string};

/// One spectral line with the HITRAN parameters lidarsim uses.
#[derive(Debug, Clone, PartialEq)]
pub struct Line {
    /// HITRAN molecule number.
    pub molecule_id: u8,
    /// HITRAN local isotopologue number (1–12).
    pub iso_id: u8,
    /// Vacuum wavenumber of the transition at zero pressure [cm⁻¹].
    pub nu_cm1: f64,
    /// Intensity at 296 K, weighted by the natural abundance [cm/molecule].
    pub sw_cm_per_molecule: f64,
    /// Einstein A coefficient [s⁻¹].
    pub einstein_a_per_s: f64,
    /// Air-broadened Lorentz HWHM at 296 K [cm⁻¹/atm].
    pub gamma_air_cm1_per_atm: f64,
    /// Self-broadened Lorentz HWHM at 296 K [cm⁻¹/atm].
    pub gamma_self_cm1_per_atm: f64,
    /// Lower-state energy E″ [cm⁻¹].
    pub elower_cm1: f64,
    /// Temperature exponent of the broadening, γ(T) = γ(296) (296/T)^n_air.
    pub n_air: f64,
    /// Air pressure shift at 296 K [cm⁻¹/atm].
    pub delta_air_cm1_per_atm: f64,
    /// The four quantum-number fields (global upper, global lower, local upper, local lower),
    /// 15 characters each, as in the record.
    pub quanta: [u8; 60],
    /// Beyond-Voigt parameters (speed dependence, Dicke narrowing, line mixing) from a CSV line
    /// list ([`super::csv_lines`]); `None` for a `.par` record.
    pub shape: Option<Box<ShapeParameters>>,
}

/// The line-shape parameters of one line for one perturber, in HITRAN's names and units
/// (widths and shifts in cm⁻¹/atm at 296 K; Tennyson et al. 2014).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Broadener {
    /// `gamma0`: speed-averaged half width.
    pub gamma0: f64,
    /// `n_gamma0`: its exponent, Γ₀(T) = Γ₀ (296/T)^n.
    pub n_gamma0: f64,
    /// `delta0`: speed-averaged shift.
    pub delta0: f64,
    /// `n_delta0`: its linear temperature dependence [cm⁻¹/atm/K], Δ₀(T) = Δ₀ + n (T − 296).
    pub n_delta0: f64,
    /// `SD_gamma`: Γ₂/Γ₀.
    pub sd_gamma: f64,
    /// `n_gamma2`: exponent of Γ₂.
    pub n_gamma2: f64,
    /// `SD_delta`: Δ₂/Δ₀.
    pub sd_delta: f64,
    /// `nuVC`: velocity-changing collision frequency.
    pub nu_vc: f64,
    /// `n_nuVC`: its exponent.
    pub n_nu_vc: f64,
    /// `eta`: correlation parameter.
    pub eta: f64,
    /// `y`: first-order line-mixing coefficient [1/atm].
    pub y: f64,
    /// `n_y`: its exponent.
    pub n_y: f64,
}

/// Which beyond-Voigt parameters a line list carries (the columns its file has).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct ShapeColumns {
    /// `SD_gamma_air` (speed dependence of the width).
    pub speed_dependence: bool,
    /// `nuVC_air` (Dicke narrowing).
    pub dicke: bool,
    /// `eta_air` (correlation).
    pub correlation: bool,
    /// `y_air` (first-order line mixing).
    pub line_mixing: bool,
}

/// Beyond-Voigt parameters of a line: air and self broadening, and which the file had.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ShapeParameters {
    /// Broadening by air.
    pub air: Broadener,
    /// Self broadening (the air values where the file has no `_self` column).
    pub self_broadening: Broadener,
    /// The columns the file had.
    pub columns: ShapeColumns,
    /// The line of the file (1-based) the line was read from, for messages that name it.
    pub file_line: usize,
}

impl Line {
    /// Global upper quanta (15 characters, as in the record).
    pub fn global_upper_quanta(&self) -> &str {
        std::str::from_utf8(&self.quanta[0..15]).unwrap_or("")
    }
    /// Global lower quanta.
    pub fn global_lower_quanta(&self) -> &str {
        std::str::from_utf8(&self.quanta[15..30]).unwrap_or("")
    }
    /// Local upper quanta.
    pub fn local_upper_quanta(&self) -> &str {
        std::str::from_utf8(&self.quanta[30..45]).unwrap_or("")
    }
    /// Local lower quanta (e.g. `     R 16e     ` for CO2).
    pub fn local_lower_quanta(&self) -> &str {
        std::str::from_utf8(&self.quanta[45..60]).unwrap_or("")
    }
    /// The isotopologue's HITRAN parameters (always known for lines in a [`LineList`]).
    pub fn isotopologue(&self) -> Option<&'static Isotopologue> {
        Isotopologue::get(self.molecule_id, self.iso_id)
    }
}

/// Which lines to keep when reading a file. The default keeps every line.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct LineFilter {
    /// Keep only these molecule numbers (None = all).
    pub molecules: Option<Vec<u8>>,
    /// Keep only these (molecule, isotopologue) pairs (None = all).
    pub isotopologues: Option<Vec<(u8, u8)>>,
    /// Keep lines with ν ≥ this [cm⁻¹].
    pub min_cm1: Option<f64>,
    /// Keep lines with ν ≤ this [cm⁻¹].
    pub max_cm1: Option<f64>,
}

impl LineFilter {
    /// Keep lines whose centre is within `[lo, hi]` cm⁻¹ (add the wing cutoff on both sides of
    /// a spectral window to keep every line that reaches it).
    pub fn window(lo_cm1: f64, hi_cm1: f64) -> Self {
        LineFilter {
            min_cm1: Some(lo_cm1),
            max_cm1: Some(hi_cm1),
            ..Default::default()
        }
    }

    pub(crate) fn keeps_species(&self, m: u8, i: u8) -> bool {
        self.molecules.as_ref().is_none_or(|ms| ms.contains(&m))
            && self
                .isotopologues
                .as_ref()
                .is_none_or(|is| is.contains(&(m, i)))
    }

    pub(crate) fn keeps_nu(&self, nu: f64) -> bool {
        self.min_cm1.is_none_or(|lo| nu >= lo) && self.max_cm1.is_none_or(|hi| nu <= hi)
    }
}

/// A list of lines, sorted by wavenumber, with where it came from.
#[derive(Debug, Clone, PartialEq)]
pub struct LineList {
    /// Where the lines came from (file path or `<built-in …>`), for messages and metadata.
    pub source: String,
    /// The lines, sorted by increasing `nu_cm1`.
    pub lines: Vec<Line>,
}

/// Parse the HITRAN isotopologue character (`1`–`9`, `0` = 10, `A` = 11, `B` = 12).
fn iso_from_char(c: u8) -> Option<u8> {
    match c {
        b'1'..=b'9' => Some(c - b'0'),
        b'0' => Some(10),
        b'A' | b'a' => Some(11),
        b'B' | b'b' => Some(12),
        _ => None,
    }
}

impl LineList {
    /// Read a HITRAN `.par` file (or a HAPI `.data` table), keeping the lines `filter` keeps.
    ///
    /// Every record must be 160 characters; blank lines are skipped. A malformed field, or a
    /// kept line of an isotopologue without a partition sum, is an error naming the file, line
    /// and field.
    pub fn read_par(path: &Path, filter: &LineFilter) -> Result<LineList, SpectroscopyError> {
        let text = read_to_string(path)?;
        Ok(Self::parse_par(path, &text, filter)?)
    }

    /// Parse HITRAN records from `text`; `path` names the source in errors.
    pub fn parse_par(
        path: impl Into<PathBuf>,
        text: &str,
        filter: &LineFilter,
    ) -> Result<LineList, InputError> {
        let path = path.into();
        let mut lines = Vec::new();
        for (i, raw) in text.lines().enumerate() {
            let line_no = i + 1;
            let rec = raw.strip_suffix('\r').unwrap_or(raw);
            if rec.trim().is_empty() {
                continue;
            }
            if let Some(line) = parse_record(&path, line_no, rec, filter)? {
                lines.push(line);
            }
        }
        // Stable sort keeps the file order of coincident lines (deterministic sums).
        lines.sort_by(|a, b| a.nu_cm1.total_cmp(&b.nu_cm1));
        Ok(LineList {
            source: path.display().to_string(),
            lines,
        })
    }

    /// Number of lines.
    pub fn len(&self) -> usize {
        self.lines.len()
    }

    /// True without lines.
    pub fn is_empty(&self) -> bool {
        self.lines.is_empty()
    }

    /// The distinct molecule numbers in the list, in increasing order.
    pub fn molecules(&self) -> Vec<u8> {
        let mut m: Vec<u8> = self.lines.iter().map(|l| l.molecule_id).collect();
        m.sort_unstable();
        m.dedup();
        m
    }

    /// A new list with only the lines `filter` keeps.
    pub fn filtered(&self, filter: &LineFilter) -> LineList {
        LineList {
            source: self.source.clone(),
            lines: self
                .lines
                .iter()
                .filter(|l| {
                    filter.keeps_species(l.molecule_id, l.iso_id) && filter.keeps_nu(l.nu_cm1)
                })
                .cloned()
                .collect(),
        }
    }

    /// A stable 64-bit fingerprint of every parameter of every line (FNV-1a over the bit
    /// patterns), used to tell whether a saved optical-depth table was built from this list.
    pub fn fingerprint(&self) -> u64 {
        let mut h = crate::digest::Fnv::new();
        for l in &self.lines {
            h.update(&[l.molecule_id, l.iso_id]);
            for v in [
                l.nu_cm1,
                l.sw_cm_per_molecule,
                l.gamma_air_cm1_per_atm,
                l.gamma_self_cm1_per_atm,
                l.elower_cm1,
                l.n_air,
                l.delta_air_cm1_per_atm,
            ] {
                h.f64(v);
            }
            if let Some(sp) = &l.shape {
                for b in [&sp.air, &sp.self_broadening] {
                    for v in [
                        b.gamma0, b.n_gamma0, b.delta0, b.n_delta0, b.sd_gamma, b.n_gamma2,
                        b.sd_delta, b.nu_vc, b.n_nu_vc, b.eta, b.y, b.n_y,
                    ] {
                        h.f64(v);
                    }
                }
                let c = sp.columns;
                h.update(&[
                    u8::from(c.speed_dependence),
                    u8::from(c.dicke),
                    u8::from(c.correlation),
                    u8::from(c.line_mixing),
                ]);
            }
        }
        h.finish()
    }

    /// The built-in model of the CO2 30012←00001 band (626 only, P and R branches
    /// |m| ≤ 60), for scenes without a HITRAN file. Approximate: see
    /// [`super::band_model`] and `validation/co2_band_model/`.
    pub fn co2_30012_band_model() -> LineList {
        super::band_model::Co2BandModel::embedded().line_list(60)
    }
}

/// Column ranges (0-based, end exclusive) and names of the numeric fields.
const F_NU: (usize, usize, &str) = (3, 15, "nu");
const F_SW: (usize, usize, &str) = (15, 25, "sw");
const F_A: (usize, usize, &str) = (25, 35, "a");
const F_GAIR: (usize, usize, &str) = (35, 40, "gamma_air");
const F_GSELF: (usize, usize, &str) = (40, 45, "gamma_self");
const F_ELOWER: (usize, usize, &str) = (45, 55, "elower");
const F_NAIR: (usize, usize, &str) = (55, 59, "n_air");
const F_DAIR: (usize, usize, &str) = (59, 67, "delta_air");

/// The physical range of each line parameter lidarsim uses, shared by the `.par` and CSV
/// readers; a value outside is refused at its file, line and field.
pub(crate) mod ranges {
    use crate::input::Bounds;
    /// Line position \[cm⁻¹\] (HITRAN reaches about 1e5).
    pub const NU_CM1: Bounds = Bounds::positive(1e6);
    /// Intensity at 296 K \[cm/molecule\] (the strongest lines are near 1e-17).
    pub const SW: Bounds = Bounds::closed(0.0, 1e-10);
    /// Einstein A coefficient \[1/s\].
    pub const EINSTEIN_A: Bounds = Bounds::closed(0.0, 1e12);
    /// Lorentz half widths \[cm⁻¹/atm\] (typical 0.01–0.5).
    pub const GAMMA: Bounds = Bounds::closed(0.0, 10.0);
    /// Lower-state energy \[cm⁻¹\]; HITRAN writes −1 where it is unknown.
    pub const ELOWER_CM1: Bounds = Bounds::closed(-1.0, 1e5);
    /// Temperature exponents (of widths, shifts, line mixing).
    pub const EXPONENT: Bounds = Bounds::closed(-10.0, 10.0);
    /// Pressure shifts \[cm⁻¹/atm\] (typical −0.01).
    pub const DELTA: Bounds = Bounds::closed(-1.0, 1.0);
}

fn parse_record(
    path: &Path,
    line_no: usize,
    rec: &str,
    filter: &LineFilter,
) -> Result<Option<Line>, InputError> {
    let b = rec.as_bytes();
    if b.len() != 160 || !rec.is_ascii() {
        return Err(InputError::at(
            path,
            line_no,
            "record",
            format!(
                "a HITRAN record has 160 ASCII characters, this one has {} {}",
                rec.chars().count(),
                if rec.is_ascii() {
                    "characters"
                } else {
                    "characters, not all ASCII"
                }
            ),
        ));
    }
    let molecule_id: u8 = rec[0..2].trim().parse().map_err(|_| {
        InputError::at(
            path,
            line_no,
            "molec_id",
            format!("`{}` (columns 1-2) is not a molecule number", &rec[0..2]),
        )
    })?;
    let iso_id = iso_from_char(b[2]).ok_or_else(|| {
        InputError::at(
            path,
            line_no,
            "local_iso_id",
            format!(
                "`{}` (column 3) is not an isotopologue number",
                b[2] as char
            ),
        )
    })?;
    if !filter.keeps_species(molecule_id, iso_id) {
        return Ok(None);
    }
    let num_in = |(a, z, name): (usize, usize, &str), bounds| -> Result<f64, InputError> {
        let s = &rec[a..z];
        let v: f64 = s.trim().parse().map_err(|_| {
            InputError::at(
                path,
                line_no,
                name,
                format!("`{s}` (columns {}-{}) is not a number", a + 1, z),
            )
        })?;
        crate::input::check_finite_range(v, bounds).map_err(|m| {
            InputError::at(
                path,
                line_no,
                name,
                format!("`{}` (columns {}-{}): {m}", s.trim(), a + 1, z),
            )
        })
    };
    let nu_cm1 = num_in(F_NU, ranges::NU_CM1)?;
    if !filter.keeps_nu(nu_cm1) {
        return Ok(None);
    }
    if Isotopologue::get(molecule_id, iso_id).is_none() {
        return Err(InputError::at(
            path,
            line_no,
            "local_iso_id",
            format!(
                "molecule {molecule_id} isotopologue {iso_id} has no partition sum or mass in lidarsim's \
                 tables (known: H2O, CO2, O3, N2O, CO, CH4, O2); filter it out"
            ),
        ));
    }
    let line = Line {
        molecule_id,
        iso_id,
        nu_cm1,
        sw_cm_per_molecule: num_in(F_SW, ranges::SW)?,
        einstein_a_per_s: num_in(F_A, ranges::EINSTEIN_A)?,
        gamma_air_cm1_per_atm: num_in(F_GAIR, ranges::GAMMA)?,
        gamma_self_cm1_per_atm: num_in(F_GSELF, ranges::GAMMA)?,
        elower_cm1: num_in(F_ELOWER, ranges::ELOWER_CM1)?,
        n_air: num_in(F_NAIR, ranges::EXPONENT)?,
        delta_air_cm1_per_atm: num_in(F_DAIR, ranges::DELTA)?,
        quanta: b[67..127].try_into().unwrap_or([b' '; 60]),
        shape: None,
    };
    Ok(Some(line))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// R(16)e of CO2 30012←00001, copied from HITRAN2016.
    const R16: &str = " 21 6359.967244 1.779E-23 7.543e-03.07470.102  106.12970.67-.005510       3 0 0 12       0 0 0 01                    R 16e     4788762029 6 5 6 8    35.0   33.0";

    #[test]
    fn parses_a_record() {
        let rec = format!("{}{}", " 21", &R16[3..]);
        let l = LineList::parse_par("x.par", &rec, &LineFilter::default()).unwrap();
        let l = &l.lines[0];
        assert_eq!((l.molecule_id, l.iso_id), (2, 1));
        assert_eq!(l.nu_cm1, 6359.967244);
        assert_eq!(l.sw_cm_per_molecule, 1.779e-23);
        assert_eq!(l.gamma_air_cm1_per_atm, 0.0747);
        assert_eq!(l.gamma_self_cm1_per_atm, 0.102);
        assert_eq!(l.elower_cm1, 106.1297);
        assert_eq!(l.n_air, 0.67);
        assert_eq!(l.delta_air_cm1_per_atm, -0.00551);
        assert_eq!(l.local_lower_quanta().trim(), "R 16e");
        assert_eq!(l.global_upper_quanta().trim(), "3 0 0 12");
    }

    #[test]
    fn isotopologue_characters_0_a_b_are_10_11_12() {
        assert_eq!(iso_from_char(b'0'), Some(10));
        assert_eq!(iso_from_char(b'A'), Some(11));
        assert_eq!(iso_from_char(b'B'), Some(12));
        assert_eq!(iso_from_char(b'x'), None);
    }

    #[test]
    fn malformed_records_name_line_and_field() {
        let good = format!("{}{}", " 21", &R16[3..]);
        let mut bad = good.clone();
        bad.replace_range(36..40, "x.xx");
        let text = format!("{good}\n\n{bad}\n");
        let e = LineList::parse_par("f.par", &text, &LineFilter::default()).unwrap_err();
        assert_eq!(e.line, Some(3));
        assert_eq!(e.field.as_deref(), Some("gamma_air"));
        let e = LineList::parse_par("f.par", &good[..150], &LineFilter::default()).unwrap_err();
        assert_eq!(e.field.as_deref(), Some("record"));
        assert!(e.to_string().contains("160"), "{e}");
        // Unknown molecule: an error, unless filtered out.
        let unknown = format!("{}{}", "471", &R16[3..]);
        let e = LineList::parse_par("f.par", &unknown, &LineFilter::default()).unwrap_err();
        assert_eq!(e.field.as_deref(), Some("local_iso_id"));
        let only_co2 = LineFilter {
            molecules: Some(vec![2]),
            ..Default::default()
        };
        assert!(
            LineList::parse_par("f.par", &unknown, &only_co2)
                .unwrap()
                .is_empty()
        );
    }

    #[test]
    fn filters_by_window_and_isotopologue() {
        let a = format!("{}{}", " 21", &R16[3..]);
        let b = format!("{}{}", " 22", &R16[3..]);
        let text = format!("{a}\n{b}\n");
        let f = LineFilter {
            isotopologues: Some(vec![(2, 2)]),
            ..Default::default()
        };
        assert_eq!(
            LineList::parse_par("f", &text, &f).unwrap().lines[0].iso_id,
            2
        );
        let w = LineFilter::window(6360.0, 6400.0);
        assert!(LineList::parse_par("f", &text, &w).unwrap().is_empty());
    }
}
