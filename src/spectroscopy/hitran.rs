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
use super::lines::{Line, LineFilter, LineList, ranges};
use crate::input::{InputError, read_to_string};

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
