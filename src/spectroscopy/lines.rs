//! Spectral lines and line lists as lidarsim holds them, whatever file they came from: the
//! types every reader (HITRAN `.par`, CSV, the built-in band model) fills and every
//! cross-section reads.

use super::isotopologues::Isotopologue;

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

impl LineList {
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
}

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
