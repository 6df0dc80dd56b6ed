//! Line lists as CSV with a header of HITRAN parameter names, as HITRANonline and HAPI write
//! them and as laboratory work publishes beyond-Voigt parameters (e.g. the NIST 30012 band
//! list of usnistgov/MATS).
//!
//! Required columns: `molec_id`, `local_iso_id`, `nu`, `sw`, `elower`, and the air width, its
//! exponent and the air shift under either name (`gamma0_air` or `gamma_air`, `n_gamma0_air`
//! or `n_air`, `delta0_air` or `delta_air`). Optional, per perturber `b` of `air` and `self`:
//! `n_delta0_b` (default 0), `SD_gamma_b`, `n_gamma2_b` (default the width's exponent),
//! `SD_delta_b`, `nuVC_b`, `n_nuVC_b` (default 1: ν_VC scales with the number density),
//! `eta_b`, `y_b`, `n_y_b` (default the width's exponent); `gamma0_self`/`gamma_self`,
//! `n_gamma0_self`/`n_self` and `delta0_self`/`delta_self`. A `_self` column that is absent
//! takes the air value (the self width: HITRAN's practice when it has none). Which
//! beyond-Voigt columns (`SD_gamma_air`, `nuVC_air`, `eta_air`, `y_air`) the file has is kept
//! ([`ShapeColumns`]) so that a profile asking for one the file lacks is refused, naming it.
//! The quantum-number columns `global_upper_quanta`, `global_lower_quanta`,
//! `local_upper_quanta`, `local_lower_quanta` are kept when present. A repeated column name
//! (the MATS files repeat `elower`) takes its first occurrence.

use std::path::{Path, PathBuf};

use super::lines::{Broadener, Line, LineFilter, LineList, ShapeColumns, ShapeParameters, ranges};
use crate::input::Bounds;

/// `SD_gamma`: the speed dependence Γ₂/Γ₀ (typical 0.05–0.15). The quadratic model gives the
/// molecules of speed v the width Γ(v) = Γ₀ + Γ₂ (v²/v_p² − 3/2) (v_p the most probable speed;
/// Tran, Ngo & Hartmann 2013, JQSRT 129, 199, Eq. 3), which is ≥ 0 at every speed only for
/// 0 ≤ Γ₂/Γ₀ ≤ 2/3: below 0 the fast molecules, above 2/3 the slowest, would have a negative
/// width, and the profile (a speed average of Lorentzians, and HAPI's closed form of it, which
/// lidarsim evaluates) is then neither non-negative nor finite (Γ₂/Γ₀ = −0.001 gives ±1e40).
pub const SD_RATIO: Bounds = Bounds::closed(0.0, 2.0 / 3.0);
/// [`SD_RATIO`] as messages write it.
const SD_RATIO_TEXT: &str = "[0, 2/3]";
/// `SD_delta`: Δ₂/Δ₀.
const SD_SHIFT_RATIO: Bounds = Bounds::closed(-10.0, 10.0);
/// `eta`: the correlation parameter of the Hartmann-Tran profile.
const ETA: Bounds = Bounds::below(0.0, 1.0);
/// `y`: first-order line mixing \[1/atm\] (typical |y| < 0.1).
const LINE_MIXING_Y: Bounds = Bounds::closed(-10.0, 10.0);
use super::isotopologues::Isotopologue;
use crate::input::{CsvTable, InputError};

/// The column of the first of `names` the header has.
fn find(t: &CsvTable, names: &[&str]) -> Option<usize> {
    names.iter().find_map(|n| t.column_opt(n))
}

/// The column of one of `names`, or an error naming them.
fn require(t: &CsvTable, names: &[&str]) -> Result<usize, InputError> {
    find(t, names).ok_or_else(|| {
        let missing = names.join("` or `");
        t.column(names[0])
            .map_err(|e| {
                // `column`'s message is "missing column (the header has: …)": name them instead.
                let message = match e.message.strip_prefix("missing column") {
                    Some(rest) => format!("missing column `{missing}`{rest}"),
                    None => format!("missing column `{missing}` ({})", e.message),
                };
                InputError { message, ..e }
            })
            .err()
            .unwrap_or_else(|| InputError::file(t.path(), format!("missing column `{missing}`")))
    })
}

/// Column indices of one perturber's parameters.
struct BroadenerColumns {
    gamma0: Option<usize>,
    n_gamma0: Option<usize>,
    delta0: Option<usize>,
    n_delta0: Option<usize>,
    sd_gamma: Option<usize>,
    n_gamma2: Option<usize>,
    sd_delta: Option<usize>,
    nu_vc: Option<usize>,
    n_nu_vc: Option<usize>,
    eta: Option<usize>,
    y: Option<usize>,
    n_y: Option<usize>,
}

impl BroadenerColumns {
    fn of(t: &CsvTable, b: &str) -> Self {
        let c = |names: &[&str]| -> Option<usize> {
            let full: Vec<String> = names.iter().map(|n| format!("{n}_{b}")).collect();
            let refs: Vec<&str> = full.iter().map(String::as_str).collect();
            find(t, &refs)
        };
        BroadenerColumns {
            gamma0: c(&["gamma0", "gamma"]),
            n_gamma0: c(&["n_gamma0", "n"]),
            delta0: c(&["delta0", "delta"]),
            n_delta0: c(&["n_delta0"]),
            sd_gamma: c(&["SD_gamma"]),
            n_gamma2: c(&["n_gamma2"]),
            sd_delta: c(&["SD_delta"]),
            nu_vc: c(&["nuVC"]),
            n_nu_vc: c(&["n_nuVC"]),
            eta: c(&["eta"]),
            y: c(&["y"]),
            n_y: c(&["n_y"]),
        }
    }

    /// The perturber's parameters of one row; `fallback` fills absent columns (self from air).
    fn read(
        &self,
        get: &dyn Fn(usize) -> Result<f64, InputError>,
        fallback: Option<&Broadener>,
    ) -> Result<Broadener, InputError> {
        let opt = |c: Option<usize>, default: f64| -> Result<f64, InputError> {
            c.map_or(Ok(default), get)
        };
        let base = fallback.copied().unwrap_or_default();
        let gamma0 = opt(self.gamma0, base.gamma0)?;
        let n_gamma0 = opt(self.n_gamma0, base.n_gamma0)?;
        let n_default = if fallback.is_some() {
            None
        } else {
            Some(n_gamma0)
        };
        Ok(Broadener {
            gamma0,
            n_gamma0,
            delta0: opt(self.delta0, base.delta0)?,
            n_delta0: opt(self.n_delta0, base.n_delta0)?,
            sd_gamma: opt(self.sd_gamma, base.sd_gamma)?,
            n_gamma2: opt(self.n_gamma2, n_default.unwrap_or(base.n_gamma2))?,
            sd_delta: opt(self.sd_delta, base.sd_delta)?,
            nu_vc: opt(self.nu_vc, base.nu_vc)?,
            n_nu_vc: opt(
                self.n_nu_vc,
                if fallback.is_some() {
                    base.n_nu_vc
                } else {
                    1.0
                },
            )?,
            eta: opt(self.eta, base.eta)?,
            y: opt(self.y, base.y)?,
            n_y: opt(self.n_y, n_default.unwrap_or(base.n_y))?,
        })
    }
}

impl LineList {
    /// Read a line list: a CSV with HITRAN parameter names ([`super::csv_lines`]) when the
    /// file name ends in `.csv`, else HITRAN 160-character records ([`LineList::read_par`]).
    pub fn read(path: &Path, filter: &LineFilter) -> Result<LineList, super::SpectroscopyError> {
        let is_csv = path
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("csv"));
        if is_csv {
            Ok(Self::read_csv(path, filter)?)
        } else {
            Self::read_par(path, filter)
        }
    }

    /// Read a CSV line list (module docs), keeping the lines `filter` keeps.
    pub fn read_csv(path: &Path, filter: &LineFilter) -> Result<LineList, InputError> {
        Self::parse_csv(path, &crate::input::read_to_string(path)?, filter)
    }

    /// Parse a CSV line list from `text`; `path` names the source in errors.
    pub fn parse_csv(
        path: impl Into<PathBuf>,
        text: &str,
        filter: &LineFilter,
    ) -> Result<LineList, InputError> {
        let path: PathBuf = path.into();
        let t = CsvTable::parse(&path, text)?;
        let c_mol = require(&t, &["molec_id"])?;
        let c_iso = require(&t, &["local_iso_id"])?;
        let c_nu = require(&t, &["nu"])?;
        let c_sw = require(&t, &["sw"])?;
        let c_el = require(&t, &["elower"])?;
        require(&t, &["gamma0_air", "gamma_air"])?;
        require(&t, &["n_gamma0_air", "n_air"])?;
        require(&t, &["delta0_air", "delta_air"])?;
        let air = BroadenerColumns::of(&t, "air");
        let own = BroadenerColumns::of(&t, "self");
        let columns = ShapeColumns {
            speed_dependence: air.sd_gamma.is_some(),
            dicke: air.nu_vc.is_some(),
            correlation: air.eta.is_some(),
            line_mixing: air.y.is_some(),
        };
        let quanta_cols = [
            "global_upper_quanta",
            "global_lower_quanta",
            "local_upper_quanta",
            "local_lower_quanta",
        ]
        .map(|n| t.column_opt(n));
        let mut lines = Vec::new();
        for (row, (line_no, fields)) in t.rows().enumerate() {
            let get = |c: usize| t.f64_at(row, c);
            let int = |c: usize, name: &str| -> Result<u8, InputError> {
                fields[c].trim().parse::<u8>().map_err(|_| {
                    InputError::at(
                        &path,
                        line_no,
                        name,
                        format!("`{}` is not a whole number 0–255", fields[c]),
                    )
                })
            };
            let molecule_id = int(c_mol, "molec_id")?;
            let iso_id = int(c_iso, "local_iso_id")?;
            if !filter.keeps_species(molecule_id, iso_id) {
                continue;
            }
            let nu_cm1 = t.f64_in(row, c_nu, ranges::NU_CM1)?;
            if !filter.keeps_nu(nu_cm1) {
                continue;
            }
            if Isotopologue::get(molecule_id, iso_id).is_none() {
                return Err(InputError::at(
                    &path,
                    line_no,
                    "local_iso_id",
                    format!(
                        "molecule {molecule_id} isotopologue {iso_id} has no partition sum or mass in lidarsim's tables; filter it out"
                    ),
                ));
            }
            let a = air.read(&get, None)?;
            let s = own.read(&get, Some(&a))?;
            let sw = get(c_sw)?;
            let elower = get(c_el)?;
            check_line_ranges(
                &t,
                &path,
                line_no,
                sw,
                elower,
                [(&a, &air, "air"), (&s, &own, "self")],
            )?;
            let mut quanta = [b' '; 60];
            for (k, c) in quanta_cols.iter().enumerate() {
                if let Some(c) = c {
                    let q = format!("{:>15}", fields[*c].trim());
                    let bytes = q.as_bytes();
                    let n = bytes.len().min(15);
                    quanta[15 * k + 15 - n..15 * (k + 1)]
                        .copy_from_slice(&bytes[bytes.len() - n..]);
                }
            }
            lines.push(Line {
                molecule_id,
                iso_id,
                nu_cm1,
                sw_cm_per_molecule: sw,
                einstein_a_per_s: 0.0,
                gamma_air_cm1_per_atm: a.gamma0,
                gamma_self_cm1_per_atm: s.gamma0,
                elower_cm1: elower,
                n_air: a.n_gamma0,
                delta_air_cm1_per_atm: a.delta0,
                quanta,
                shape: Some(Box::new(ShapeParameters {
                    air: a,
                    self_broadening: s,
                    columns,
                    file_line: line_no,
                })),
            });
        }
        lines.sort_by(|a, b| a.nu_cm1.total_cmp(&b.nu_cm1));
        Ok(LineList {
            source: path.display().to_string(),
            lines,
        })
    }
}

/// Each parameter of a line (at line `line_no` of `path`) in its range, named by the column it
/// came from (or, for a `_self` value taken from air, by the air column).
fn check_line_ranges(
    t: &CsvTable,
    path: &Path,
    line_no: usize,
    sw: f64,
    elower: f64,
    sides: [(&Broadener, &BroadenerColumns, &str); 2],
) -> Result<(), InputError> {
    let name_of = |c: Option<usize>, fallback: &str| -> String {
        c.map_or(fallback.to_string(), |c| t.header()[c].clone())
    };
    let check = |v: f64, name: String, bounds| {
        crate::input::check_finite_range(v, bounds)
            .map(|_| ())
            .map_err(|m| InputError::at(path, line_no, name, m))
    };
    check(sw, "sw".into(), ranges::SW)?;
    check(elower, "elower".into(), ranges::ELOWER_CM1)?;
    for (b, cols, side) in sides {
        let fb = |n: &str| format!("{n}_{side}");
        check(b.gamma0, name_of(cols.gamma0, &fb("gamma0")), ranges::GAMMA)?;
        check(
            b.n_gamma0,
            name_of(cols.n_gamma0, &fb("n_gamma0")),
            ranges::EXPONENT,
        )?;
        check(b.delta0, name_of(cols.delta0, &fb("delta0")), ranges::DELTA)?;
        check(
            b.n_delta0,
            name_of(cols.n_delta0, &fb("n_delta0")),
            ranges::DELTA,
        )?;
        let sd_name = name_of(cols.sd_gamma, &fb("SD_gamma"));
        if b.sd_gamma.is_finite() && !SD_RATIO.contains(b.sd_gamma) {
            return Err(InputError::at(
                path,
                line_no,
                sd_name,
                format!(
                    "{} must lie in {SD_RATIO_TEXT}: the speed-dependent width \
                     Γ(v) = Γ₀ + Γ₂ (v²/v_p² − 3/2) is negative at some speed outside it \
                     ({}), and the profile with it is not a line shape",
                    crate::input::fmt_bound(b.sd_gamma),
                    if b.sd_gamma < 0.0 {
                        "the fastest molecules"
                    } else {
                        "the slowest molecules: Γ₀ − 3Γ₂/2 < 0"
                    }
                ),
            ));
        }
        check(b.sd_gamma, sd_name, SD_RATIO)?;
        check(
            b.n_gamma2,
            name_of(cols.n_gamma2, &fb("n_gamma2")),
            ranges::EXPONENT,
        )?;
        check(
            b.sd_delta,
            name_of(cols.sd_delta, &fb("SD_delta")),
            SD_SHIFT_RATIO,
        )?;
        check(b.nu_vc, name_of(cols.nu_vc, &fb("nuVC")), ranges::GAMMA)?;
        check(
            b.n_nu_vc,
            name_of(cols.n_nu_vc, &fb("n_nuVC")),
            ranges::EXPONENT,
        )?;
        check(b.eta, name_of(cols.eta, &fb("eta")), ETA)?;
        check(b.y, name_of(cols.y, &fb("y")), LINE_MIXING_Y)?;
        check(b.n_y, name_of(cols.n_y, &fb("n_y")), ranges::EXPONENT)?;
    }
    Ok(())
}
