//! One line at one state: its parameters prepared for evaluation (strength, widths, shift,
//! the beyond-Voigt profile), the checks of its file's columns, and the refusal of a negative
//! sum.

use super::{Conventions, GasState, LblOptions, LineShapeModel, VoigtMethod, WingCentre};
use crate::constants;
use crate::spectroscopy::SpectroscopyError;
use crate::spectroscopy::htp::{HtParameters, HtProfile, hartmann_tran};
use crate::spectroscopy::isotopologues::Isotopologue;
use crate::spectroscopy::lines::{Broadener, Line, LineList, ShapeParameters};
use crate::spectroscopy::tips::partition_sum;
use crate::spectroscopy::voigt::{
    SQRT_LN2, SQRT_LN2_OVER_PI, add_re_w_sorted, re_w, re_w_exact, w_fast,
};

/// One line's parameters at a given state.
#[derive(Debug, Clone)]
pub(super) struct Prepared {
    /// Unshifted HITRAN centre ν₀ [cm⁻¹] (the list is sorted by it).
    pub(super) nu0: f64,
    /// Shifted centre [cm⁻¹].
    pub(super) nu_c: f64,
    /// Centre of the cutoff window [cm⁻¹].
    pub(super) nu_w: f64,
    /// S(T)·sqrt(ln2/π)/γ_D [cm²/molecule].
    amp: f64,
    /// sqrt(ln2)/γ_D [1/cm⁻¹].
    cx: f64,
    /// y = sqrt(ln2) γ_L/γ_D.
    y: f64,
    /// γ_D [cm⁻¹].
    pub(super) gamma_d: f64,
    /// Beyond the plain Voigt: line mixing and/or the Hartmann-Tran profile.
    beyond: Beyond,
    /// Index of the line in its [`LineList`] (for messages that name it).
    line: usize,
    /// S(T) [cm/molecule], Lorentz HWHM Γ₀ [cm⁻¹] and first-order line mixing Y at the state
    /// (for messages).
    s_t: f64,
    gamma_l: f64,
    y_mix: f64,
    /// How far from ν_c the speed classes' Lorentzians sit and spread [cm⁻¹]
    /// ([`SPEED_SPREAD`] |C₂|; 0 without speed dependence): the multigrid's exact zone and the
    /// far-wing form start that much farther out.
    pub(super) spread: f64,
}

/// How a prepared line departs from the Voigt.
// Boxed: a line's state is prepared once per layer and kept ([`super::PreparedLines`]), and
// in place the beyond-Voigt variant made every line, Voigt or not, a few hundred bytes to
// write, copy and keep; its one indirection per evaluation is small against the profile's.
#[derive(Debug, Clone)]
enum Beyond {
    /// The Voigt.
    No,
    /// The Voigt with first-order line mixing Y.
    Mixing(f64),
    /// The Hartmann-Tran profile (and its limits).
    Ht(Box<HtLine>),
}

/// A beyond-Voigt line: its parameters, S(T), line mixing Y, and its far-wing form for the
/// fast path: beyond `wing` from the centre, the Voigt of the same Γ₀ and Δ₀ plus the
/// difference's leading terms, a₃/Δ³ + a₄/Δ⁴ in the real and in the imaginary part, matched at
/// `wing` and 2·`wing` on each side ([`HT_WING_WIDTHS`]).
#[derive(Debug, Clone, Copy)]
struct HtLine {
    p: HtProfile,
    s_t: f64,
    y_mix: f64,
    wing: f64,
    /// [below, above] the centre: (a₃, a₄) of the real and of the imaginary part.
    k_re: [(f64, f64); 2],
    k_im: [(f64, f64); 2],
}

impl HtLine {
    fn new(p: HtParameters, s_t: f64, y_mix: f64, nu_c: f64, wing: f64) -> HtLine {
        let voigt = HtParameters {
            gamma2: 0.0,
            delta2: 0.0,
            nu_vc: 0.0,
            eta: 0.0,
            ..p
        };
        let mut k_re = [(0.0, 0.0); 2];
        let mut k_im = [(0.0, 0.0); 2];
        for (side, d) in [-wing, wing].into_iter().enumerate() {
            let diff = |d: f64| hartmann_tran(&p, nu_c + d) - hartmann_tran(&voigt, nu_c + d);
            // a₃/d³ + a₄/d⁴ = r₁ at d and r₂ at 2d: a₃ = d³ (16 r₂ − r₁), a₄ = d⁴ (2 r₁ − 16 r₂).
            let (r1, r2) = (diff(d), diff(2.0 * d));
            let fit = |r1: f64, r2: f64| {
                (
                    d.powi(3) * (16.0 * r2 - r1),
                    d.powi(4) * (2.0 * r1 - 16.0 * r2),
                )
            };
            k_re[side] = fit(r1.re, r2.re);
            k_im[side] = fit(r1.im, r2.im);
        }
        HtLine {
            p: HtProfile::new(&p),
            s_t,
            y_mix,
            wing,
            k_re,
            k_im,
        }
    }
}

impl Prepared {
    #[inline]
    pub(super) fn eval(&self, nu: f64, exact: bool) -> f64 {
        match self.beyond {
            Beyond::No => {
                let x = (nu - self.nu_c) * self.cx;
                self.amp
                    * if exact {
                        re_w_exact(x, self.y)
                    } else {
                        re_w(x, self.y)
                    }
            }
            // Re I + Y Im I with I = sqrt(ln2/π)/γ_D w(x + iy) (htp module docs).
            Beyond::Mixing(y_mix) => {
                let x = (nu - self.nu_c) * self.cx;
                let z = num_complex::Complex64::new(x, self.y);
                let w = if exact {
                    errorfunctions::w_with_relerror(z, 0.0)
                } else {
                    w_fast(z)
                };
                self.amp * (w.re + y_mix * w.im)
            }
            Beyond::Ht(ref h) => {
                let d = nu - self.nu_c;
                if !exact && d.abs() > h.wing {
                    // Far wing: the Voigt of the same Γ₀, Δ₀ and the difference's leading terms.
                    let x = d * self.cx;
                    let w = w_fast(num_complex::Complex64::new(x, self.y));
                    let side = usize::from(d > 0.0);
                    let d3 = d * d * d;
                    let tail = |(a3, a4): (f64, f64)| (a3 + a4 / d) / d3;
                    let re = self.amp * w.re + h.s_t * tail(h.k_re[side]);
                    let im = self.amp * w.im + h.s_t * tail(h.k_im[side]);
                    return re + h.y_mix * im;
                }
                let i = if exact {
                    h.p.eval(nu)
                } else {
                    h.p.eval_fast(nu)
                };
                h.s_t * (i.re + h.y_mix * i.im)
            }
        }
    }
    /// [`Prepared::eval`] at two wavenumbers: the same numbers, with a beyond-Voigt line's
    /// near-centre profile evaluated for both together ([`HtProfile::eval_fast_pair`]).
    #[inline]
    pub(super) fn eval_pair(&self, a: f64, b: f64, exact: bool) -> (f64, f64) {
        if let Beyond::Ht(ref h) = self.beyond
            && !exact
            && (a - self.nu_c).abs() <= h.wing
            && (b - self.nu_c).abs() <= h.wing
        {
            let (ia, ib) = h.p.eval_fast_pair(a, b);
            return (
                h.s_t * (ia.re + h.y_mix * ia.im),
                h.s_t * (ib.re + h.y_mix * ib.im),
            );
        }
        (self.eval(a, exact), self.eval(b, exact))
    }
    /// `acc[i] += self.eval(nu[i], exact)` for every i of the sorted wavenumbers `nu`, the
    /// same values; a plain Voigt line's fast path evaluated for all of them together
    /// ([`crate::spectroscopy::voigt::add_re_w`]).
    pub(super) fn add_evals(&self, nu: &[f64], exact: bool, acc: &mut [f64]) {
        match self.beyond {
            Beyond::No if !exact => add_re_w_sorted(nu, self.nu_c, self.cx, self.y, self.amp, acc),
            _ => {
                for (a, v) in acc.iter_mut().zip(nu) {
                    *a += self.eval(*v, exact);
                }
            }
        }
    }
    #[inline]
    pub(super) fn in_window(&self, nu: f64, w: f64) -> bool {
        nu > self.nu_w - w && nu <= self.nu_w + w
    }
}

/// Line parameters of every line of `molecule_id` at `state`, in line-list order.
pub(super) fn prepare(
    lines: &LineList,
    molecule_id: u8,
    state: &GasState,
    opts: &LblOptions,
) -> Result<Vec<Prepared>, SpectroscopyError> {
    state.check()?;
    opts.check()?;
    let conv = &opts.conventions;
    let t = state.temperature_k;
    let p_atm = state.pressure_pa / constants::STANDARD_ATMOSPHERE_PA;
    let p_self = if opts.self_broadening {
        state.self_vmr * p_atm
    } else {
        0.0
    };
    // Q(T), Q(296) and the Doppler factor per isotopologue, worked out once.
    let mut q_cache: Vec<IsoConstants> = Vec::new();
    // No regrowth: a line's state is written once.
    let mut out = Vec::with_capacity(lines.lines.len());
    for (index, l) in lines
        .lines
        .iter()
        .enumerate()
        .filter(|(_, l)| l.molecule_id == molecule_id)
    {
        let key = (l.molecule_id, l.iso_id);
        let IsoConstants {
            q_t,
            q_ref,
            doppler,
            ..
        } = iso_constants(&mut q_cache, key, t, conv)?;
        if l.sw_cm_per_molecule == 0.0 {
            continue;
        }
        let c2 = conv.c2_cm_k;
        let s_t = l.sw_cm_per_molecule * q_ref / q_t * (-c2 * l.elower_cm1 / t).exp()
            / (-c2 * l.elower_cm1 / T_REF).exp()
            * (1.0 - (-c2 * l.nu_cm1 / t).exp())
            / (1.0 - (-c2 * l.nu_cm1 / T_REF).exp());
        let gamma_d = l.nu_cm1 * doppler;
        let (gamma_l, shift, ht) = line_collisional(lines, l, state, opts, p_atm, p_self, t)?;
        let nu_c = if opts.line_shift {
            l.nu_cm1 + shift
        } else {
            l.nu_cm1
        };
        let nu_w = match opts.wing_centre {
            WingCentre::Unshifted => l.nu_cm1,
            WingCentre::Shifted => nu_c,
        };
        let y_mix = match (&ht, opts.line_mixing) {
            (Some(c), true) => c.y,
            _ => 0.0,
        };
        let mut spread = 0.0;
        let beyond = match (ht, opts.line_shape) {
            (Some(c), LineShapeModel::SdVoigt | LineShapeModel::HartmannTran)
                if !(c.gamma2 == 0.0
                    && c.delta2 == 0.0
                    && (opts.line_shape == LineShapeModel::SdVoigt
                        || (c.nu_vc == 0.0 && c.eta == 0.0))) =>
            {
                let hart = opts.line_shape == LineShapeModel::HartmannTran;
                let delta2 = if opts.line_shift { c.delta2 } else { 0.0 };
                spread = SPEED_SPREAD * c.gamma2.hypot(delta2);
                Beyond::Ht(Box::new(HtLine::new(
                    HtParameters {
                        nu0: l.nu_cm1,
                        gamma_d,
                        gamma0: gamma_l,
                        gamma2: c.gamma2,
                        delta0: nu_c - l.nu_cm1,
                        delta2,
                        nu_vc: if hart { c.nu_vc } else { 0.0 },
                        eta: if hart { c.eta } else { 0.0 },
                    },
                    s_t,
                    y_mix,
                    nu_c,
                    HT_WING_WIDTHS * gamma_l.max(gamma_d) + spread,
                )))
            }
            // No speed dependence (and for HT no Dicke narrowing): the Voigt itself.
            _ if y_mix != 0.0 => Beyond::Mixing(y_mix),
            _ => Beyond::No,
        };
        out.push(Prepared {
            nu0: l.nu_cm1,
            nu_c,
            nu_w,
            amp: s_t * SQRT_LN2_OVER_PI / gamma_d,
            cx: SQRT_LN2 / gamma_d,
            y: SQRT_LN2 * gamma_l / gamma_d,
            gamma_d,
            beyond,
            line: index,
            s_t,
            gamma_l,
            y_mix,
            spread,
        });
    }
    // `LineList::lines` is public: a hand-built list may be unsorted; the searches need ν₀ order.
    if !out.windows(2).all(|w| w[0].nu0 <= w[1].nu0) {
        out.sort_by(|a, b| a.nu0.total_cmp(&b.nu0));
    }
    Ok(out)
}

/// The reference temperature of HITRAN's intensities and widths \[K\].
const T_REF: f64 = 296.0;

/// One isotopologue's Q(T), Q(296) and Doppler width per unit wavenumber at temperature `t`.
#[derive(Debug, Clone, Copy)]
struct IsoConstants {
    key: (u8, u8),
    q_t: f64,
    q_ref: f64,
    /// sqrt(2kT ln2/(mc²)): γ_D = ν₀ times this.
    doppler: f64,
}

/// [`IsoConstants`] of isotopologue `key` at temperature `t`, looked up once per isotopologue
/// in `q_cache`.
fn iso_constants(
    q_cache: &mut Vec<IsoConstants>,
    key: (u8, u8),
    t: f64,
    conv: &Conventions,
) -> Result<IsoConstants, SpectroscopyError> {
    match q_cache.iter().find(|c| c.key == key) {
        Some(c) => Ok(*c),
        None => {
            let iso =
                Isotopologue::get(key.0, key.1).ok_or_else(|| SpectroscopyError::PartitionSum {
                    molecule_id: key.0,
                    iso_id: key.1,
                    temperature_k: t,
                    reason: "unknown isotopologue".into(),
                })?;
            let mass = iso.mass_g_per_mol * conv.atomic_mass_kg;
            let c = IsoConstants {
                key,
                q_t: partition_sum(key.0, key.1, t)?,
                q_ref: partition_sum(key.0, key.1, T_REF)?,
                doppler: (2.0 * conv.boltzmann_j_per_k * t * std::f64::consts::LN_2
                    / (mass * conv.speed_of_light_m_per_s * conv.speed_of_light_m_per_s))
                    .sqrt(),
            };
            q_cache.push(c);
            Ok(c)
        }
    }
}

/// A line's Lorentz width Γ₀ and shift \[cm⁻¹\] at the state, and its collisional parameters
/// when its file has them (then checked against the profile `opts` asks for).
fn line_collisional(
    lines: &LineList,
    l: &Line,
    state: &GasState,
    opts: &LblOptions,
    p_atm: f64,
    p_self: f64,
    t: f64,
) -> Result<(f64, f64, Option<Collisional>), SpectroscopyError> {
    // Collisional parameters: HITRAN's conventions for a CSV line with its own parameters
    // (every one mole-fraction weighted between air and self; Tennyson et al. 2014), the
    // .par record's otherwise (one exponent, the air shift for the whole pressure).
    Ok(match &l.shape {
        Some(sp) => {
            let x_self = if opts.self_broadening {
                state.self_vmr
            } else {
                0.0
            };
            let c = collisional(sp, p_atm, x_self, t);
            check_columns(lines, l, sp, opts)?;
            if matches!(
                opts.line_shape,
                LineShapeModel::SdVoigt | LineShapeModel::HartmannTran
            ) {
                check_speed_dependence(lines, sp, &c, x_self, t)?;
            }
            (c.gamma0, c.delta0, Some(c))
        }
        None => {
            if opts.line_shape != LineShapeModel::Voigt || opts.line_mixing {
                return Err(no_parameters(lines, opts));
            }
            (
                (T_REF / t).powf(l.n_air)
                    * (l.gamma_air_cm1_per_atm * (p_atm - p_self)
                        + l.gamma_self_cm1_per_atm * p_self),
                l.delta_air_cm1_per_atm * p_atm,
                None,
            )
        }
    })
}

/// Beyond this many widths (the larger of Γ₀ and γ_D) from its centre, the fast path evaluates a
/// beyond-Voigt line as the Voigt of the same Γ₀ and Δ₀ plus the leading terms of their
/// difference. Expanding the speed average in 1/Δ, the difference starts at Δ⁻³ in both parts:
/// in the imaginary part from the spread of the widths and shifts over the speeds, in the real
/// part from their correlation (Γ₂Δ₂ ≠ 0; it vanishes without a speed-dependent shift, where
/// the real part starts at Δ⁻⁴). Two terms, a₃/Δ³ + a₄/Δ⁴, are matched at this distance and at
/// twice it on each side of the line (with one term, Δ⁻⁴ in the real part, Γ₂/Γ₀ = 2/3 with
/// Δ₂/Δ₀ = 10 erred by 10 % of the peak).
pub const HT_WING_WIDTHS: f64 = 8.0;

/// The speed classes of a speed-dependent line have widths and shifts C₀ + C₂ (x² − 3/2)
/// (x = v/v_p): from −3/2 to +8 times C₂ for all but e^{−9.5}·… ≈ 1e-3 of the molecules
/// (x ≤ 3.1). A line's structure thus spans ν_c + Δ₂·[−1.5, 8] beyond its widths; the
/// multigrid's interpolation and the far-wing expansion in 1/Δ are accurate only beyond it.
/// With Δ₂ = 0.73 Γ₀ (Γ₂/Γ₀ = 2/3, Δ₂/Δ₀ = 10) and no such margin, the multigrid interpolated
/// across the shifted peak and erred by 10 % of it.
pub const SPEED_SPREAD: f64 = 8.0;

/// A line's collisional parameters at one state \[cm⁻¹\] (Y dimensionless).
#[derive(Debug, Clone, Copy)]
struct Collisional {
    gamma0: f64,
    delta0: f64,
    gamma2: f64,
    delta2: f64,
    nu_vc: f64,
    eta: f64,
    y: f64,
}

/// HITRAN's temperature and pressure conventions (reference 296 K; Tennyson et al. 2014):
/// widths, Γ₂ and ν_VC as power laws in 296/T, shifts linear in T − 296, Γ₂ = SD_gamma·Γ₀,
/// Δ₂ = SD_delta·Δ₀, Y = p·y·(296/T)^n_y, every parameter weighted by mole fraction between
/// air (1 − x) and self (x) broadening; p in atm.
fn collisional(sp: &ShapeParameters, p_atm: f64, x_self: f64, t: f64) -> Collisional {
    const T_REF: f64 = 296.0;
    let r = T_REF / t;
    let mut c = Collisional {
        gamma0: 0.0,
        delta0: 0.0,
        gamma2: 0.0,
        delta2: 0.0,
        nu_vc: 0.0,
        eta: 0.0,
        y: 0.0,
    };
    for (b, x) in [(&sp.air, 1.0 - x_self), (&sp.self_broadening, x_self)] {
        if x == 0.0 {
            continue;
        }
        let delta0 = b.delta0 + b.n_delta0 * (t - T_REF);
        c.gamma0 += x * b.gamma0 * r.powf(b.n_gamma0);
        c.delta0 += x * delta0;
        c.gamma2 += x * b.sd_gamma * b.gamma0 * r.powf(b.n_gamma2);
        c.delta2 += x * b.sd_delta * delta0;
        c.nu_vc += x * b.nu_vc * r.powf(b.n_nu_vc);
        c.eta += x * b.eta;
        c.y += x * b.y * r.powf(b.n_y);
    }
    for v in [
        &mut c.gamma0,
        &mut c.delta0,
        &mut c.gamma2,
        &mut c.delta2,
        &mut c.nu_vc,
        &mut c.y,
    ] {
        *v *= p_atm;
    }
    c
}

/// `line shape `ht` with line mixing`, for messages.
fn shape_label(opts: &LblOptions) -> String {
    format!(
        "line shape `{}`{}",
        opts.line_shape.name(),
        if opts.line_mixing {
            " with line mixing"
        } else {
            ""
        }
    )
}

/// A list without beyond-Voigt parameters (a `.par` file, the band model) asked for them.
pub(super) fn no_parameters(lines: &LineList, opts: &LblOptions) -> SpectroscopyError {
    SpectroscopyError::MissingParameters {
        lines: lines.source.clone(),
        parameters: format!(
            "{} needs beyond-Voigt parameters, which only a CSV line list with HITRAN parameter names carries (this list has none)",
            shape_label(opts)
        ),
    }
}

/// The profile `opts` asks for needs columns the line's file has.
pub(super) fn check_columns(
    lines: &LineList,
    l: &Line,
    sp: &ShapeParameters,
    opts: &LblOptions,
) -> Result<(), SpectroscopyError> {
    let have = sp.columns;
    let mut missing = Vec::new();
    if matches!(
        opts.line_shape,
        LineShapeModel::SdVoigt | LineShapeModel::HartmannTran
    ) && !have.speed_dependence
    {
        missing.push("SD_gamma_air");
    }
    if opts.line_shape == LineShapeModel::HartmannTran {
        if !have.dicke {
            missing.push("nuVC_air");
        }
        if !have.correlation {
            missing.push("eta_air");
        }
    }
    if opts.line_mixing && !have.line_mixing {
        missing.push("y_air");
    }
    if missing.is_empty() {
        return Ok(());
    }
    Err(SpectroscopyError::MissingParameters {
        lines: lines.source.clone(),
        parameters: format!(
            "{} needs the column{} {} (line at {} cm⁻¹ and every other)",
            shape_label(opts),
            if missing.len() > 1 { "s" } else { "" },
            missing.join(", "),
            l.nu_cm1
        ),
    })
}

/// The speed-dependent width of the mixture, Γ(v) = Γ₀ + Γ₂ (v²/v_p² − 3/2), must stay ≥ 0 at
/// every speed v (Tran, Ngo & Hartmann 2013, JQSRT 129, 199, Eq. 3): Γ₂ ≥ 0, which the reader's
/// range of `SD_gamma` ensures, and Γ₂ ≤ 2Γ₀/3, which it ensures at 296 K but which
/// temperature exponents of Γ₂ and Γ₀ that differ can break at the state. Refused at the line
/// of the file, naming the perturber whose own ratio is largest.
fn check_speed_dependence(
    lines: &LineList,
    sp: &ShapeParameters,
    c: &Collisional,
    x_self: f64,
    t: f64,
) -> Result<(), SpectroscopyError> {
    // A ratio at exactly 2/3 with equal exponents may exceed it by rounding.
    if 1.5 * c.gamma2 <= c.gamma0 * (1.0 + 1e-12) {
        return Ok(());
    }
    const T_REF: f64 = 296.0;
    let r = T_REF / t;
    let (b, side) = [(&sp.air, "air"), (&sp.self_broadening, "self")]
        .into_iter()
        .filter(|(_, side)| *side == "air" || x_self > 0.0)
        .max_by(|a, b| {
            let ratio = |b: &Broadener| b.sd_gamma * r.powf(b.n_gamma2 - b.n_gamma0);
            ratio(a.0).total_cmp(&ratio(b.0))
        })
        .unwrap_or((&sp.air, "air"));
    Err(crate::input::InputError::at(
        std::path::PathBuf::from(&lines.source),
        sp.file_line,
        format!("SD_gamma_{side}"),
        format!(
            "{} with `n_gamma2_{side}` = {} and `n_gamma0_{side}` = {} gives the line Γ₂/Γ₀ = {:.4} at {t} K, above 2/3: \
             the slowest molecules' width Γ₀ − 3Γ₂/2 would be negative (Tran et al. 2013, Eq. 3), \
             and the profile is not a line shape there; the temperature exponents do not hold at {t} K",
            b.sd_gamma,
            b.n_gamma2,
            b.n_gamma0,
            c.gamma2 / c.gamma0,
        ),
    )
    .into())
}

/// A cross-section below zero (or not finite) at some wavenumber is refused, naming the line
/// whose profile is most negative there, the line of its file and the cause.
///
/// Within the parameter ranges the readers accept, the Voigt, speed-dependent Voigt and
/// Hartmann-Tran profiles are non-negative (tests/beyond_voigt.rs checks them against the speed
/// average at the ranges' edges), so a sum of them is too. First-order line mixing (Rosenkranz
/// 1975) is not: Re I + Y·Im I of one line is negative beyond |ν − ν_c| ≈ Γ/|Y| on the side
/// where Y (ν − ν_c) < 0, which is the physics of the approximation. Over a whole band the
/// mixing coefficients balance (Σ S·Y ≈ 0) and the band's cross-section stays positive (the
/// NIST list of the 30012 band, as shipped, is non-negative from 0.01 to 3 atm); a list that
/// holds only part of a band can give a negative sum, which is no absorption coefficient:
/// refused, with the cure.
pub(super) fn refuse_negative(
    lines: &LineList,
    prepared: &[Prepared],
    state: &GasState,
    opts: &LblOptions,
    sigma: &[f64],
    nu_at: impl Fn(usize) -> f64,
) -> Result<(), SpectroscopyError> {
    let Some(k) = (0..sigma.len())
        .filter(|&k| !(sigma[k] >= 0.0 && sigma[k].is_finite()))
        .min_by(|&a, &b| sigma[a].total_cmp(&sigma[b]))
    else {
        return Ok(());
    };
    let nu = nu_at(k);
    let w = opts.wing_cm1;
    let exact = opts.voigt == VoigtMethod::Exact;
    let reaching: Vec<(&Prepared, f64)> = prepared
        .iter()
        .filter(|p| p.in_window(nu, w))
        .map(|p| (p, p.eval(nu, exact)))
        .collect();
    let where_ = format!(
        "cross-section {:.4e} cm²/molecule at {nu} cm⁻¹ (p = {:.5} atm, T = {:.2} K)",
        sigma[k],
        state.pressure_pa / constants::STANDARD_ATMOSPHERE_PA,
        state.temperature_k
    );
    let Some(&(p, contribution)) = reaching.iter().min_by(|a, b| a.1.total_cmp(&b.1)) else {
        return Err(SpectroscopyError::NegativeAbsorption {
            location: lines.source.clone(),
            message: format!("{where_}, where no line reaches: a numerical fault"),
        });
    };
    let line = &lines.lines[p.line];
    let location = match &line.shape {
        Some(sp) => format!("{}:{}", lines.source, sp.file_line),
        None => lines.source.clone(),
    };
    let column = "y_air";
    let quanta = line.local_lower_quanta().trim();
    let id = format!(
        "the line at ν₀ = {} cm⁻¹{}",
        line.nu_cm1,
        if quanta.is_empty() {
            String::new()
        } else {
            format!(" ({quanta})")
        }
    );
    let message = if p.y_mix != 0.0 && contribution < 0.0 {
        let (sum, abs) = reaching.iter().fold((0.0, 0.0), |(s, a), (q, _)| {
            (s + q.s_t * q.y_mix, a + q.s_t * q.y_mix.abs())
        });
        let reach = p.gamma_l / p.y_mix.abs();
        format!(
            "negative absorption {where_}: `{column}` (with `y_self`, mole-fraction weighted) of {id} gives first-order line mixing Y = {:.4e} at this state, \
             and Re I + Y·Im I of a line is negative beyond Γ/|Y| = {reach:.4} cm⁻¹ from its centre on its {} side \
             (its share here {contribution:.4e} cm²/molecule); a whole band's mixing balances (Σ S·Y ≈ 0, Rosenkranz 1975) \
             but of the {} of the list that reach {nu} cm⁻¹, Σ S·Y is {:.1} % of Σ S·|Y|. \
             Give the band's other lines, a wing cutoff below about {reach:.4} cm⁻¹, or no line mixing",
            p.y_mix,
            if p.y_mix > 0.0 {
                "low-wavenumber"
            } else {
                "high-wavenumber"
            },
            match reaching.len() {
                1 => "1 line".to_string(),
                n => format!("{n} lines"),
            },
            100.0 * sum / abs,
        )
    } else {
        format!(
            "negative absorption {where_}: the profile of {id} contributes {contribution:.4e} cm²/molecule there \
             (line shape `{}`), outside what its parameters allow: a numerical fault",
            opts.line_shape.name()
        )
    };
    Err(SpectroscopyError::NegativeAbsorption {
        location: if p.y_mix != 0.0 && contribution < 0.0 {
            format!("{location}: `{column}`")
        } else {
            location
        },
        message,
    })
}
