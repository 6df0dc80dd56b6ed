//! Size distributions of spheres and their bulk (size-integrated) optical properties.
//!
//! # Distributions
//!
//! Radii are in µm and number densities in cm⁻³ (the units of Deirmendjian 1969 and OPAC), so
//! `n(r)` is in cm⁻³ µm⁻¹. Two kinds of mode and their sums are provided:
//!
//! * log-normal: `n(r) = N / (√(2π) ln σ_g r) · exp(−(ln r − ln r_g)² / (2 ln² σ_g))`, with total
//!   number density `N`, median (number mode) radius `r_g` and geometric standard deviation
//!   `σ_g > 1` (Hess et al. 1998, Eq. 3, the OPAC form);
//! * modified gamma: `n(r) = a r^α exp(−b r^γ)` (Deirmendjian 1969, Eq. 2.41), with total number
//!   density `N = a Γ((α+1)/γ) / (γ b^((α+1)/γ))`; the C.1 cloud is `a = 2.373`, `α = 6`,
//!   `b = 1.5`, `γ = 1` (N = 100 cm⁻³, mode radius 4 µm, effective radius 6 µm);
//! * [`SizeDistribution::Sum`] of such modes (e.g. a bimodal aerosol).
//!
//! Every mode may be truncated to `[r_min, r_max]` as OPAC does (Hess et al. 1998, Table 1b); the
//! number density stays that of the untruncated formula, so a per-particle quantity is
//! "per particle of the full distribution", as in OPAC's "normalised to 1 particle cm⁻³".
//!
//! # Bulk optics
//!
//! [`bulk_optics`] integrates Mie efficiencies and amplitudes over a distribution (one
//! refractive index), [`bulk_optics_mixture`] over an external mixture of components each with
//! its own refractive index (OPAC's aerosol types):
//!
//! ```text
//! ⟨C⟩ = (1/N) Σ_modes ∫ n(r) Q(x) π r² dr,             x = 2π r / λ
//! ⟨dC/dΩ⟩(θ) = (1/N) Σ_modes ∫ n(r) (|S1|² + |S2|²)/(2k²) dr,   k = 2π/λ
//! P(θ) = 4π ⟨dC/dΩ⟩ / ⟨Csca⟩   (normalised to 4π),   g = ⟨g Csca⟩ / ⟨Csca⟩
//! lidar ratio S = ⟨Cext⟩ / ⟨dC/dΩ(180°)⟩ = 4π ⟨Cext⟩ / ⟨Cback⟩
//! F_ij(θ) = 4π ⟨S_ij/k²⟩ / ⟨Csca⟩   for S11, S12, S33, S34 (Bohren & Huffman 1983, eq. 4.77);
//!           F11 = P, and for spheres F22 = F11, F44 = F33
//! ```
//!
//! The scattering matrix ([`BulkOptics::matrix`], the conventions of
//! [`super::matrix`]) comes from the same matrix products as the phase function, at no
//! measurable extra cost: S12, S33, S34 are products of the same S± = S1 ± S2
//! ([`super::mie::four_s_from_s_pm`]).
//!
//! Each mode is integrated on a uniform grid in size parameter with the trapezoid rule over the
//! radius range that holds all but `tail_fraction` of the mode's geometric cross-section
//! (`∫ π r² n dr`, half in each tail). The step is halved (reusing the previous points) until two
//! successive halvings both change the extinction, scattering, backscatter and `g·Csca`
//! integrals by less than `rel_tol` — the backscatter of nearly non-absorbing droplets converges
//! slowest (narrow resonances; see `docs/particles.md` for the convergence seen). The phase
//! function is then computed on the final grid, so `P(180°)` in the table is exactly the
//! backscatter used for the lidar ratio. Radii are evaluated in parallel (rayon) in fixed blocks
//! whose sums are reduced in block order: the numbers do not depend on the thread count.

// `!(v > 0.0)` is used on purpose: unlike `v <= 0.0` it also rejects NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use std::f64::consts::PI;
use std::fmt;

use nalgebra::DMatrix;
use num_complex::Complex64;
use rayon::prelude::*;
use statrs::function::gamma::{gamma_lr, ln_gamma};

use super::matrix::MatrixElements;
use super::matrix_table::MatrixTable;
use super::mie::{MieCoefficients, MieError, check_refractive_index, four_s_from_s_pm, n_terms};
use super::table::PhaseTable;

fn param(name: &'static str, value: f64, reason: &'static str) -> MieError {
    MieError::Parameter {
        name,
        value,
        reason,
    }
}

/// A log-normal mode (see the module documentation).
#[derive(Debug, Clone, PartialEq)]
pub struct LogNormal {
    number_density_per_cm3: f64,
    median_radius_um: f64,
    sigma_g: f64,
    r_min_um: f64,
    r_max_um: f64,
}

impl LogNormal {
    /// A log-normal mode with total number density `N` [cm⁻³] > 0, median radius `r_g` \[µm\] > 0
    /// and geometric standard deviation `σ_g` in (1, 10].
    pub fn new(
        number_density_per_cm3: f64,
        median_radius_um: f64,
        sigma_g: f64,
    ) -> Result<Self, MieError> {
        if !(number_density_per_cm3.is_finite() && number_density_per_cm3 > 0.0) {
            return Err(param(
                "number_density_per_cm3",
                number_density_per_cm3,
                "must be finite and > 0",
            ));
        }
        if !(median_radius_um.is_finite() && median_radius_um > 0.0) {
            return Err(param(
                "median_radius_um",
                median_radius_um,
                "must be finite and > 0",
            ));
        }
        if !(sigma_g.is_finite() && sigma_g > 1.0 && sigma_g <= 10.0) {
            return Err(param("sigma_g", sigma_g, "must be > 1 and ≤ 10"));
        }
        Ok(LogNormal {
            number_density_per_cm3,
            median_radius_um,
            sigma_g,
            r_min_um: 0.0,
            r_max_um: f64::INFINITY,
        })
    }

    /// Total number density N [cm⁻³].
    pub fn number_density_per_cm3(&self) -> f64 {
        self.number_density_per_cm3
    }
    /// Median radius r_g \[µm\].
    pub fn median_radius_um(&self) -> f64 {
        self.median_radius_um
    }
    /// Geometric standard deviation σ_g.
    pub fn sigma_g(&self) -> f64 {
        self.sigma_g
    }
}

/// A modified gamma mode `n(r) = a r^α exp(−b r^γ)` (Deirmendjian 1969).
#[derive(Debug, Clone, PartialEq)]
pub struct ModifiedGamma {
    a: f64,
    alpha: f64,
    b: f64,
    gamma: f64,
    r_min_um: f64,
    r_max_um: f64,
}

impl ModifiedGamma {
    /// `n(r) = a r^α exp(−b r^γ)` [cm⁻³ µm⁻¹], r in µm: `a > 0` [cm⁻³ µm^−(α+1)], `α > −1`,
    /// `b > 0` [µm^−γ], `γ > 0`.
    pub fn new(a: f64, alpha: f64, b: f64, gamma: f64) -> Result<Self, MieError> {
        if !(a.is_finite() && a > 0.0) {
            return Err(param("a", a, "must be finite and > 0"));
        }
        if !(alpha.is_finite() && alpha > -1.0 && alpha <= 100.0) {
            return Err(param("alpha", alpha, "must be > -1 and ≤ 100"));
        }
        if !(b.is_finite() && b > 0.0) {
            return Err(param("b", b, "must be finite and > 0"));
        }
        if !(gamma.is_finite() && gamma > 0.0 && gamma <= 10.0) {
            return Err(param("gamma", gamma, "must be > 0 and ≤ 10"));
        }
        Ok(ModifiedGamma {
            a,
            alpha,
            b,
            gamma,
            r_min_um: 0.0,
            r_max_um: f64::INFINITY,
        })
    }

    /// Parameters (a, α, b, γ).
    pub fn parameters(&self) -> (f64, f64, f64, f64) {
        (self.a, self.alpha, self.b, self.gamma)
    }
}

/// A size distribution: one mode or a sum of modes (see the module documentation).
#[derive(Debug, Clone, PartialEq)]
pub enum SizeDistribution {
    /// A log-normal mode.
    LogNormal(LogNormal),
    /// A modified gamma mode.
    ModifiedGamma(ModifiedGamma),
    /// A sum of modes (all with the same refractive index when used with [`bulk_optics`]).
    Sum(Vec<SizeDistribution>),
}

impl SizeDistribution {
    /// A log-normal mode: see [`LogNormal::new`].
    pub fn lognormal(
        number_density_per_cm3: f64,
        median_radius_um: f64,
        sigma_g: f64,
    ) -> Result<Self, MieError> {
        Ok(SizeDistribution::LogNormal(LogNormal::new(
            number_density_per_cm3,
            median_radius_um,
            sigma_g,
        )?))
    }

    /// A modified gamma mode: see [`ModifiedGamma::new`].
    pub fn modified_gamma(a: f64, alpha: f64, b: f64, gamma: f64) -> Result<Self, MieError> {
        Ok(SizeDistribution::ModifiedGamma(ModifiedGamma::new(
            a, alpha, b, gamma,
        )?))
    }

    /// Deirmendjian's (1969) C.1 cumulus cloud: `n(r) = 2.373 r⁶ exp(−1.5 r)` (N = 100 cm⁻³,
    /// mode radius 4 µm, effective radius 6 µm).
    pub fn deirmendjian_c1() -> Self {
        SizeDistribution::ModifiedGamma(ModifiedGamma {
            a: 2.373,
            alpha: 6.0,
            b: 1.5,
            gamma: 1.0,
            r_min_um: 0.0,
            r_max_um: f64::INFINITY,
        })
    }

    /// The sum of `parts` (nested sums are flattened); at least one part.
    pub fn sum(parts: Vec<SizeDistribution>) -> Result<Self, MieError> {
        let mut modes = Vec::new();
        for p in parts {
            p.collect_modes(&mut modes);
        }
        if modes.is_empty() {
            return Err(param("modes", 0.0, "a sum needs at least one mode"));
        }
        if modes.len() == 1 {
            return Ok(modes.remove(0));
        }
        Ok(SizeDistribution::Sum(modes))
    }

    /// The same distribution with every mode truncated to radii in `[r_min_um, r_max_um]`
    /// (`0 ≤ r_min < r_max`; `r_max` may be infinite). The number density is unchanged.
    pub fn truncated(mut self, r_min_um: f64, r_max_um: f64) -> Result<Self, MieError> {
        if !(r_min_um.is_finite() && r_min_um >= 0.0) {
            return Err(param("r_min_um", r_min_um, "must be finite and ≥ 0"));
        }
        if !(r_max_um > r_min_um) {
            return Err(param("r_max_um", r_max_um, "must exceed r_min_um"));
        }
        self.for_each_mode_mut(&mut |lo, hi| {
            *lo = r_min_um;
            *hi = r_max_um;
        });
        Ok(self)
    }

    fn for_each_mode_mut(&mut self, f: &mut dyn FnMut(&mut f64, &mut f64)) {
        match self {
            SizeDistribution::LogNormal(m) => f(&mut m.r_min_um, &mut m.r_max_um),
            SizeDistribution::ModifiedGamma(m) => f(&mut m.r_min_um, &mut m.r_max_um),
            SizeDistribution::Sum(v) => v.iter_mut().for_each(|d| d.for_each_mode_mut(f)),
        }
    }

    fn collect_modes(&self, out: &mut Vec<SizeDistribution>) {
        match self {
            SizeDistribution::Sum(v) => v.iter().for_each(|d| d.collect_modes(out)),
            leaf => out.push(leaf.clone()),
        }
    }

    /// The leaf modes (a sum flattened).
    pub fn modes(&self) -> Vec<SizeDistribution> {
        let mut v = Vec::new();
        self.collect_modes(&mut v);
        v
    }

    /// Total number density [cm⁻³] (of the untruncated formulas).
    pub fn number_density_per_cm3(&self) -> f64 {
        match self {
            SizeDistribution::LogNormal(m) => m.number_density_per_cm3,
            SizeDistribution::ModifiedGamma(m) => {
                let s = (m.alpha + 1.0) / m.gamma;
                m.a * (ln_gamma(s) - s * m.b.ln()).exp() / m.gamma
            }
            SizeDistribution::Sum(v) => v.iter().map(|d| d.number_density_per_cm3()).sum(),
        }
    }

    /// `n(r)` [cm⁻³ µm⁻¹] at radius `r_um` (0 outside a mode's truncation range).
    pub fn density(&self, r_um: f64) -> f64 {
        if r_um <= 0.0 {
            return 0.0;
        }
        match self {
            SizeDistribution::LogNormal(m) => {
                if r_um < m.r_min_um || r_um > m.r_max_um {
                    return 0.0;
                }
                let ls = m.sigma_g.ln();
                let z = (r_um / m.median_radius_um).ln() / ls;
                m.number_density_per_cm3 / ((2.0 * PI).sqrt() * ls * r_um) * (-0.5 * z * z).exp()
            }
            SizeDistribution::ModifiedGamma(m) => {
                if r_um < m.r_min_um || r_um > m.r_max_um {
                    return 0.0;
                }
                m.a * (m.alpha * r_um.ln() - m.b * r_um.powf(m.gamma)).exp()
            }
            SizeDistribution::Sum(v) => v.iter().map(|d| d.density(r_um)).sum(),
        }
    }

    /// The moment `∫ r^k n(r) dr / N` [µm^k] of the untruncated distribution.
    pub fn moment(&self, k: f64) -> f64 {
        match self {
            SizeDistribution::LogNormal(m) => {
                let ls = m.sigma_g.ln();
                m.median_radius_um.powf(k) * (0.5 * k * k * ls * ls).exp()
            }
            SizeDistribution::ModifiedGamma(m) => {
                let s = (m.alpha + 1.0) / m.gamma;
                (ln_gamma(s + k / m.gamma) - ln_gamma(s) - k / m.gamma * m.b.ln()).exp()
            }
            SizeDistribution::Sum(v) => {
                let n: f64 = self.number_density_per_cm3();
                v.iter()
                    .map(|d| d.number_density_per_cm3() * d.moment(k))
                    .sum::<f64>()
                    / n
            }
        }
    }

    /// Effective radius `r_eff = ⟨r³⟩/⟨r²⟩` \[µm\] (Hansen & Travis 1974, Eq. 2.53), untruncated.
    pub fn effective_radius_um(&self) -> f64 {
        self.moment(3.0) / self.moment(2.0)
    }

    /// Fraction of the mode's geometric cross-section `∫ r² n dr` below `r_um` (untruncated).
    fn area_cdf(&self, r_um: f64) -> f64 {
        match self {
            SizeDistribution::LogNormal(m) => {
                let ls = m.sigma_g.ln();
                // r² n(r) is log-normal with median r_g exp(2 ln² σ_g).
                let z = ((r_um / m.median_radius_um).ln() - 2.0 * ls * ls) / ls;
                0.5 * statrs::function::erf::erfc(-z / std::f64::consts::SQRT_2)
            }
            SizeDistribution::ModifiedGamma(m) => {
                // t = b r^γ turns r² n(r) dr into a gamma density of shape (α+3)/γ.
                gamma_lr((m.alpha + 3.0) / m.gamma, m.b * r_um.powf(m.gamma))
            }
            SizeDistribution::Sum(v) => {
                let w: Vec<f64> = v
                    .iter()
                    .map(|d| d.number_density_per_cm3() * d.moment(2.0))
                    .collect();
                let tot: f64 = w.iter().sum();
                v.iter()
                    .zip(&w)
                    .map(|(d, wi)| wi * d.area_cdf(r_um))
                    .sum::<f64>()
                    / tot
            }
        }
    }

    /// Radius \[µm\] below which the fraction `p` of the geometric cross-section lies.
    fn area_quantile(&self, p: f64) -> f64 {
        // Bisection in ln r over 1e-7 … 1e7 µm.
        let (mut lo, mut hi) = ((1e-7f64).ln(), (1e7f64).ln());
        for _ in 0..200 {
            let mid = 0.5 * (lo + hi);
            if self.area_cdf(mid.exp()) < p {
                lo = mid;
            } else {
                hi = mid;
            }
            if hi - lo < 1e-12 {
                break;
            }
        }
        (0.5 * (lo + hi)).exp()
    }

    fn range_um(&self) -> (f64, f64) {
        match self {
            SizeDistribution::LogNormal(m) => (m.r_min_um, m.r_max_um),
            SizeDistribution::ModifiedGamma(m) => (m.r_min_um, m.r_max_um),
            SizeDistribution::Sum(_) => (0.0, f64::INFINITY),
        }
    }
}

impl fmt::Display for SizeDistribution {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let range = |f: &mut fmt::Formatter<'_>, lo: f64, hi: f64| {
            if lo > 0.0 || hi.is_finite() {
                write!(f, ", r in [{lo}, {hi}] um")
            } else {
                Ok(())
            }
        };
        match self {
            SizeDistribution::LogNormal(m) => {
                write!(
                    f,
                    "lognormal N={} cm^-3 r_g={} um sigma_g={}",
                    m.number_density_per_cm3, m.median_radius_um, m.sigma_g
                )?;
                range(f, m.r_min_um, m.r_max_um)
            }
            SizeDistribution::ModifiedGamma(m) => {
                write!(
                    f,
                    "modified gamma n(r) = {} r^{} exp(-{} r^{}) cm^-3 um^-1 (r in um)",
                    m.a, m.alpha, m.b, m.gamma
                )?;
                range(f, m.r_min_um, m.r_max_um)
            }
            SizeDistribution::Sum(v) => {
                for (i, d) in v.iter().enumerate() {
                    if i > 0 {
                        write!(f, " + ")?;
                    }
                    write!(f, "[{d}]")?;
                }
                Ok(())
            }
        }
    }
}

/// One component of an external mixture: a size distribution and its refractive index
/// (imaginary part ≥ 0 absorbing).
#[derive(Debug, Clone, PartialEq)]
pub struct Component {
    /// A short name for tables and reports (e.g. `waso`).
    pub name: String,
    /// Size distribution (number density in cm⁻³).
    pub distribution: SizeDistribution,
    /// Refractive index relative to the medium.
    pub refractive_index: Complex64,
}

/// Options of the size integration.
#[derive(Debug, Clone, PartialEq)]
pub struct BulkOptions {
    /// Fraction of each mode's geometric cross-section left outside the integration range
    /// (half below, half above). Default 1e-5.
    pub tail_fraction: f64,
    /// Relative change of the extinction, scattering, backscatter and g·scattering integrals
    /// below which two successive halvings of the size step count as converged. Default 1e-3.
    pub rel_tol: f64,
    /// Smallest size-parameter step tried. Default 1e-3.
    pub min_step_x: f64,
    /// Most grid points per mode. Default 2²⁰.
    pub max_points: usize,
    /// Scattering angles \[deg\] of the phase function (0 … 180, increasing); `None` chooses
    /// [`default_angle_grid`]. An empty vector skips the phase function.
    pub angles_deg: Option<Vec<f64>>,
}

impl Default for BulkOptions {
    fn default() -> Self {
        BulkOptions {
            tail_fraction: 1e-5,
            rel_tol: 1e-3,
            min_step_x: 1e-3,
            max_points: 1 << 20,
            angles_deg: None,
        }
    }
}

/// How one mode's integration ended.
#[derive(Debug, Clone, PartialEq)]
pub struct ModeConvergence {
    /// Component name.
    pub component: String,
    /// Radius range integrated \[µm\].
    pub r_range_um: (f64, f64),
    /// Final size-parameter step.
    pub step_x: f64,
    /// Number of radii on the final grid.
    pub points: usize,
    /// Largest relative change of the four integrals at the last halving.
    pub last_rel_change: f64,
    /// True when the tolerance was met (false: stopped at `min_step_x` or `max_points`).
    pub converged: bool,
}

/// Bulk optical properties of a size distribution (per particle, number-weighted).
#[derive(Debug, Clone, PartialEq)]
pub struct BulkOptics {
    /// Wavelength \[m\].
    pub wavelength_m: f64,
    /// Mean extinction cross-section per particle ⟨Cext⟩ \[m²\]: a layer's extinction
    /// coefficient [1/m] is its number density [1/m³] times this.
    pub extinction_cross_section_m2: f64,
    /// Mean scattering cross-section per particle ⟨Csca⟩ \[m²\].
    pub scattering_cross_section_m2: f64,
    /// Mean backscatter ("radar") cross-section ⟨Cback⟩ = 4π ⟨dCsca/dΩ(180°)⟩ \[m²\].
    pub backscatter_cross_section_m2: f64,
    /// ⟨Csca⟩/⟨Cext⟩.
    pub single_scattering_albedo: f64,
    /// Asymmetry parameter ⟨g Csca⟩/⟨Csca⟩.
    pub asymmetry: f64,
    /// Extinction-to-backscatter ratio 4π⟨Cext⟩/⟨Cback⟩ \[sr\].
    pub lidar_ratio_sr: f64,
    /// Number density of the distribution as given [1/m³].
    pub number_density_per_m3: f64,
    /// Effective radius ∫r³n/∫r²n over the integrated range \[µm\] (all components).
    pub effective_radius_um: f64,
    /// Phase function (normalised to 4π) with metadata; empty angles if none was asked for.
    pub phase: PhaseTable,
    /// The scattering matrix on the same angles with the same metadata, every element
    /// normalised like the phase function (its F11 column is `phase`, number for number); for
    /// spheres F22 = F11 and F44 = F33.
    pub matrix: MatrixTable,
    /// Per mode: range, step and convergence of the size integration.
    pub convergence: Vec<ModeConvergence>,
}

impl BulkOptics {
    /// Extinction coefficient [1/m] of a layer with `number_density_per_m3` particles.
    pub fn extinction_per_m(&self, number_density_per_m3: f64) -> f64 {
        number_density_per_m3 * self.extinction_cross_section_m2
    }

    /// Number density [1/m³] that gives the extinction coefficient `extinction_per_m` [1/m].
    pub fn number_density_for_extinction(&self, extinction_per_m: f64) -> f64 {
        extinction_per_m / self.extinction_cross_section_m2
    }

    /// Phase function at 180° (normalised to 4π), from the integrals: ⟨Cback⟩/⟨Csca⟩.
    pub fn phase_180(&self) -> f64 {
        self.backscatter_cross_section_m2 / self.scattering_cross_section_m2
    }
}

/// The default angle grid \[deg\] for a distribution whose largest effective size parameter is
/// `x_eff`: the 1391-angle grid of the reference files (0.01° to 1°, 0.05° to 5°, 0.1° to 20°,
/// 0.25° to 160°, 0.1° to 175°, 0.02° to 178°, 0.01° to 180°), with the forward step reduced
/// below 0.01° when the diffraction peak (width ≈ 1/x_eff rad) is narrower than 0.2°, so that it
/// is always resolved by at least 20 steps.
pub fn default_angle_grid(x_eff: f64) -> Vec<f64> {
    let peak_deg = (1.0 / x_eff.max(1e-3)).to_degrees();
    let fwd = (peak_deg / 20.0).min(0.01);
    let n_fwd = (1.0 / fwd).ceil() as usize;
    let mut v: Vec<f64> = (0..n_fwd).map(|i| i as f64 / n_fwd as f64).collect();
    let segments = [
        (1.0, 5.0, 80usize),
        (5.0, 20.0, 150),
        (20.0, 160.0, 560),
        (160.0, 175.0, 150),
        (175.0, 178.0, 150),
        (178.0, 180.0, 200),
    ];
    for (a, b, n) in segments {
        for i in 0..n {
            // Round to 1e-9 deg so the printed grid is clean.
            let t = a + (b - a) * i as f64 / n as f64;
            v.push((t * 1e9).round() / 1e9);
        }
    }
    v.push(180.0);
    v
}

/// Bulk optics of `dist` with one refractive index `m` (imaginary part ≥ 0 absorbing) at
/// `wavelength_m`: see the module documentation.
pub fn bulk_optics(
    dist: &SizeDistribution,
    m: Complex64,
    wavelength_m: f64,
    opts: &BulkOptions,
) -> Result<BulkOptics, MieError> {
    bulk_optics_mixture(
        &[Component {
            name: "particles".into(),
            distribution: dist.clone(),
            refractive_index: m,
        }],
        wavelength_m,
        opts,
    )
}

/// Format a complex refractive index as `1.3205+1.28e-6i` (the CLI's syntax).
pub fn format_refractive_index(m: Complex64) -> String {
    if m.im != 0.0 && m.im.abs() < 1e-3 {
        format!("{}+{:e}i", m.re, m.im)
    } else {
        format!("{}{:+}i", m.re, m.im)
    }
}

/// A stable text fingerprint of the inputs of [`bulk_optics_mixture`] (components, wavelength,
/// options, solver version): equal inputs give equal text on every machine (shortest round-trip
/// number formatting). Use [`fingerprint_hash`] for a short file name.
pub fn fingerprint(components: &[Component], wavelength_m: f64, opts: &BulkOptions) -> String {
    // v2: results carry the scattering matrix (cache entries of v1 hold the phase function
    // only, and must be recomputed rather than read).
    let mut s = format!("lidarsim-mie-v2;wavelength_m={wavelength_m:e}");
    for c in components {
        s.push_str(&format!(
            ";component={}:m={:e}{:+e}i:{}",
            c.name, c.refractive_index.re, c.refractive_index.im, c.distribution
        ));
    }
    s.push_str(&format!(
        ";tail_fraction={:e};rel_tol={:e};min_step_x={:e};max_points={}",
        opts.tail_fraction, opts.rel_tol, opts.min_step_x, opts.max_points
    ));
    match &opts.angles_deg {
        None => s.push_str(";angles=default"),
        Some(a) => {
            s.push_str(";angles=");
            for (i, t) in a.iter().enumerate() {
                if i > 0 {
                    s.push(',');
                }
                s.push_str(&format!("{t:e}"));
            }
        }
    }
    s
}

/// 64-bit FNV-1a hash of [`fingerprint`] as 16 hex digits (stable across platforms and runs).
pub fn fingerprint_hash(components: &[Component], wavelength_m: f64, opts: &BulkOptions) -> String {
    let mut h = crate::digest::Fnv::new();
    h.update(fingerprint(components, wavelength_m, opts).as_bytes());
    format!("{:016x}", h.finish())
}

/// Integrals over one mode: ∫ n(r) {Cext, Csca, Cback, g·Csca, r²·π, r³·π} dr [cm⁻³ µm²(µm)].
#[derive(Clone, Copy, Default, Debug)]
struct Sums([f64; 6]);

impl Sums {
    fn add(&mut self, o: &Sums, w: f64) {
        for i in 0..6 {
            self.0[i] += w * o.0[i];
        }
    }
}

struct ModeGrid {
    m: Complex64,
    mode: SizeDistribution,
    k_per_um: f64,
    x_lo: f64,
    dx: f64,
    points: usize, // intervals M (points = M + 1)
    sums: Sums,
}

const BLOCK: usize = 64;

fn integrand(mode: &SizeDistribution, m: Complex64, k: f64, x: f64) -> Result<Sums, MieError> {
    let r = x / k;
    let n = mode.density(r);
    if n == 0.0 {
        return Ok(Sums::default());
    }
    let e = MieCoefficients::compute(m, x)?.efficiencies();
    let area = PI * r * r;
    Ok(Sums([
        n * e.qext * area,
        n * e.qsca * area,
        n * e.qback * area,
        n * e.g * e.qsca * area,
        n * area,
        n * area * r,
    ]))
}

/// Sum of the integrand over the points x0 + i·h, i in 0..count (parallel, fixed block order).
fn sum_points(
    mode: &SizeDistribution,
    m: Complex64,
    k: f64,
    x0: f64,
    h: f64,
    count: usize,
) -> Result<Sums, MieError> {
    let blocks: Vec<Result<Sums, MieError>> = (0..count.div_ceil(BLOCK))
        .into_par_iter()
        .map(|b| {
            let mut s = Sums::default();
            for i in b * BLOCK..((b + 1) * BLOCK).min(count) {
                s.add(&integrand(mode, m, k, x0 + i as f64 * h)?, 1.0);
            }
            Ok(s)
        })
        .collect();
    let mut total = Sums::default();
    for b in blocks {
        total.add(&b?, 1.0);
    }
    Ok(total)
}

/// The radius range \[µm\] a mode is integrated over (all but `tail_fraction` of its geometric
/// cross-section, within its truncation), for wavenumber `k` \[1/µm\].
fn mode_range_um(
    mode: &SizeDistribution,
    k: f64,
    opts: &BulkOptions,
) -> Result<(f64, f64), MieError> {
    let (tr_lo, tr_hi) = mode.range_um();
    let r_lo = mode.area_quantile(0.5 * opts.tail_fraction).max(tr_lo);
    let r_hi = mode
        .area_quantile(1.0 - 0.5 * opts.tail_fraction)
        .min(tr_hi);
    if !(r_hi > r_lo) {
        return Err(param(
            "r_max_um",
            r_hi,
            "the truncation range holds none of the distribution",
        ));
    }
    if k * r_hi > super::mie::MAX_SIZE_PARAMETER {
        return Err(MieError::SizeParameter(k * r_hi));
    }
    Ok((r_lo, r_hi))
}

/// Intervals of the finest grid the step halving of [`integrate_mode`] can reach over
/// `[x_lo, x_hi]` (it stops there if it has not converged before): 128 · 2^j, the same
/// arithmetic as the halving itself.
fn max_intervals(x_lo: f64, x_hi: f64, opts: &BulkOptions) -> usize {
    let mut intervals = 128usize;
    let mut dx = (x_hi - x_lo) / intervals as f64;
    while !(dx * 0.5 < opts.min_step_x || 2 * intervals + 1 > opts.max_points) {
        dx *= 0.5;
        intervals *= 2;
    }
    intervals
}

/// Least index contrast |m − 1| a size integration accepts: the cross-sections scale as |m − 1|²
/// (Rayleigh–Gans) and are rounding noise near |m − 1| = 10⁻¹⁵ (C.1-like drops at 532 nm: 25 %
/// off the |m − 1|² scaling there, none at 10⁻⁷); at m = 1 Cback is 0 and the lidar ratio has no
/// value. 10⁻⁶ keeps a wide margin and is below any particle in the atmosphere.
pub const MIN_INDEX_CONTRAST: f64 = 1e-6;

/// Efficiency below which the size integration's convergence is absolute (see
/// [`integrate_mode`]): 10⁻¹² is far below any efficiency that matters next to the geometric
/// cross-section, and far above the rounding noise of the Mie sums (~10⁻¹⁶).
const CONVERGENCE_FLOOR: f64 = 1e-12;

fn integrate_mode(
    name: &str,
    mode: &SizeDistribution,
    m: Complex64,
    wavelength_um: f64,
    opts: &BulkOptions,
) -> Result<(ModeGrid, ModeConvergence), MieError> {
    let k = 2.0 * PI / wavelength_um;
    let (r_lo, r_hi) = mode_range_um(mode, k, opts)?;
    let (x_lo, x_hi) = (k * r_lo, k * r_hi);
    // Level 0: 128 intervals.
    let mut intervals = 128usize;
    let mut dx = (x_hi - x_lo) / intervals as f64;
    let ends = {
        let mut e = integrand(mode, m, k, x_lo)?;
        e.add(&integrand(mode, m, k, x_hi)?, 1.0);
        e
    };
    // Sum over all points, ends with weight 1/2.
    let mut total = ends;
    for v in total.0.iter_mut() {
        *v *= 0.5;
    }
    total.add(&sum_points(mode, m, k, x_lo + dx, dx, intervals - 1)?, 1.0);
    let integral = |t: &Sums, dx: f64| -> [f64; 6] {
        let mut o = t.0;
        o.iter_mut().for_each(|v| *v *= dx / k);
        o
    };
    let mut prev = integral(&total, dx);
    let mut passes = 0;
    let mut last_change = f64::INFINITY;
    let mut converged = false;
    loop {
        if dx * 0.5 < opts.min_step_x || 2 * intervals + 1 > opts.max_points {
            break;
        }
        let h = dx * 0.5;
        total.add(&sum_points(mode, m, k, x_lo + h, dx, intervals)?, 1.0);
        intervals *= 2;
        dx = h;
        let cur = integral(&total, dx);
        // Each change relative to the integral, or to CONVERGENCE_FLOOR × the geometric
        // cross-section (cur[4] > 0) where the integral is smaller: an integral that is
        // rounding noise (no index contrast, m ≈ 1) has no relative convergence and would
        // refine to the finest grid.
        let floor = CONVERGENCE_FLOOR * cur[4];
        last_change = (0..4)
            .map(|i| {
                let scale = cur[i].abs().max(floor);
                if scale == 0.0 {
                    0.0
                } else {
                    ((cur[i] - prev[i]) / scale).abs()
                }
            })
            .fold(0.0, f64::max);
        prev = cur;
        if last_change <= opts.rel_tol {
            passes += 1;
            if passes >= 2 {
                converged = true;
                break;
            }
        } else {
            passes = 0;
        }
    }
    let sums = Sums(prev);
    Ok((
        ModeGrid {
            m,
            mode: mode.clone(),
            k_per_um: k,
            x_lo,
            dx,
            points: intervals,
            sums,
        },
        ModeConvergence {
            component: name.to_string(),
            r_range_um: (r_lo, r_hi),
            step_x: dx,
            points: intervals + 1,
            last_rel_change: last_change,
            converged,
        },
    ))
}

/// Angle tables for the phase function: c_n (π_n ± τ_n)(cos θ_k), K × N_max, column-major.
struct AngleTables {
    plus: DMatrix<f64>,
    minus: DMatrix<f64>,
}

fn angle_tables(theta_deg: &[f64], n_max: usize) -> AngleTables {
    let kk = theta_deg.len();
    let mut plus = DMatrix::<f64>::zeros(kk, n_max);
    let mut minus = DMatrix::<f64>::zeros(kk, n_max);
    for (row, t) in theta_deg.iter().enumerate() {
        let mu = t.to_radians().cos();
        let mut pi_prev = 0.0;
        let mut pi = 1.0;
        for col in 0..n_max {
            let n = (col + 1) as f64;
            let tau = n * mu * pi - (n + 1.0) * pi_prev;
            let c = (2.0 * n + 1.0) / (n * (n + 1.0));
            plus[(row, col)] = c * (pi + tau);
            minus[(row, col)] = c * (pi - tau);
            let pi_next = ((2.0 * n + 1.0) * mu * pi - (n + 1.0) * pi_prev) / n;
            pi_prev = pi;
            pi = pi_next;
        }
    }
    AngleTables { plus, minus }
}

/// Per angle, ∫ n(r) S_ij/k² dr over a mode's final grid for S11, S12, S33, S34 [cm⁻³ µm² sr⁻¹]
/// (Bohren & Huffman 1983, eq. 4.77; S11/k² = (|S1|²+|S2|²)/(2k²) = dCsca/dΩ).
#[derive(Debug, Clone, Default)]
struct MatrixSums {
    s11: Vec<f64>,
    s12: Vec<f64>,
    s33: Vec<f64>,
    s34: Vec<f64>,
}

impl MatrixSums {
    fn zeros(n: usize) -> Self {
        MatrixSums {
            s11: vec![0.0; n],
            s12: vec![0.0; n],
            s33: vec![0.0; n],
            s34: vec![0.0; n],
        }
    }

    fn add(&mut self, o: &MatrixSums) {
        for (a, b) in [
            (&mut self.s11, &o.s11),
            (&mut self.s12, &o.s12),
            (&mut self.s33, &o.s33),
            (&mut self.s34, &o.s34),
        ] {
            for (t, v) in a.iter_mut().zip(b) {
                *t += v;
            }
        }
    }
}

/// The matrix products give S± = S1 ± S2 (the angle tables hold c_n(π_n ± τ_n), the
/// coefficients a_n ± b_n); the elements are products of S+ and S−
/// ([`super::mie::four_s_from_s_pm`]). The coefficients are stored in Bohren & Huffman's
/// convention, so these S± are BH's amplitudes — not the conjugates that
/// [`MieCoefficients::amplitudes`] returns — and S34 = ½ Im(S+ S−*) has BH's sign.
fn matrix_integral(g: &ModeGrid, tables: &AngleTables) -> Result<MatrixSums, MieError> {
    const R: usize = 32;
    let kk = tables.plus.nrows();
    let npts = g.points + 1;
    let k = g.k_per_um;
    let n_max = tables.plus.ncols();
    // Per-thread scratch matrices (reused: large fresh allocations cost page faults); they hold
    // no state between blocks, so results do not depend on the thread count.
    let scratch = || {
        (
            DMatrix::<f64>::zeros(n_max, 2 * R),
            DMatrix::<f64>::zeros(n_max, 2 * R),
            DMatrix::<f64>::zeros(kk, 2 * R),
            DMatrix::<f64>::zeros(kk, 2 * R),
        )
    };
    let blocks: Vec<Result<MatrixSums, MieError>> = (0..npts.div_ceil(R))
        .into_par_iter()
        .map_init(scratch, |(bp, bm, cp, cm), b| {
            let idx: Vec<usize> = (b * R..((b + 1) * R).min(npts)).collect();
            let mut coeffs = Vec::with_capacity(idx.len());
            let mut weights = Vec::with_capacity(idx.len());
            for &i in &idx {
                let x = g.x_lo + i as f64 * g.dx;
                let r = x / k;
                let mut w = g.mode.density(r) * g.dx / k;
                if i == 0 || i == npts - 1 {
                    w *= 0.5;
                }
                weights.push(w);
                coeffs.push(if w > 0.0 {
                    Some(MieCoefficients::compute(g.m, x)?)
                } else {
                    None
                });
            }
            let nb = coeffs
                .iter()
                .map(|c| c.as_ref().map_or(0, |c| c.len()))
                .max()
                .unwrap_or(0)
                .min(n_max);
            let mut acc = MatrixSums::zeros(kk);
            if nb == 0 {
                return Ok(acc);
            }
            bp.fill(0.0);
            bm.fill(0.0);
            for (j, c) in coeffs.iter().enumerate() {
                if let Some(c) = c {
                    for n in 0..c.len().min(nb) {
                        let p = c.a[n] + c.b[n];
                        let q = c.a[n] - c.b[n];
                        bp[(n, j)] = p.re;
                        bp[(n, R + j)] = p.im;
                        bm[(n, j)] = q.re;
                        bm[(n, R + j)] = q.im;
                    }
                }
            }
            cp.gemm(1.0, &tables.plus.columns(0, nb), &bp.rows(0, nb), 0.0);
            cm.gemm(1.0, &tables.minus.columns(0, nb), &bm.rows(0, nb), 0.0);
            for (j, w) in weights.iter().enumerate() {
                if *w == 0.0 {
                    continue;
                }
                // 4 S_ij from S± (four_s_from_s_pm); S_ij/k² = f · 4 S_ij with f = w/(4k²).
                let f = w / (4.0 * k * k);
                let (p_re, p_im) = (cp.column(j), cp.column(R + j));
                let (m_re, m_im) = (cm.column(j), cm.column(R + j));
                for a in 0..kk {
                    let [s11, s12, s33, s34] = four_s_from_s_pm(
                        Complex64::new(p_re[a], p_im[a]),
                        Complex64::new(m_re[a], m_im[a]),
                    );
                    acc.s11[a] += f * s11;
                    acc.s12[a] += f * s12;
                    acc.s33[a] += f * s33;
                    acc.s34[a] += f * s34;
                }
            }
            Ok(acc)
        })
        .collect();
    let mut total = MatrixSums::zeros(kk);
    for b in blocks {
        total.add(&b?);
    }
    Ok(total)
}

/// Bulk optics of an external mixture of `components` at `wavelength_m`: cross-sections are
/// number-weighted over all components, the phase function scattering-weighted (see the module
/// documentation). The phase table's metadata records the inputs and the results.
pub fn bulk_optics_mixture(
    components: &[Component],
    wavelength_m: f64,
    opts: &BulkOptions,
) -> Result<BulkOptics, MieError> {
    check_inputs(components, wavelength_m, opts)?;
    // Refused before any of it is done when it would run for hours (README, "Limits").
    mie_work(components, wavelength_m, opts)?
        .check()
        .map_err(MieError::Work)?;
    let wavelength_um = wavelength_m * 1e6;
    let mut grids = Vec::new();
    let mut convergence = Vec::new();
    let mut number_density = 0.0;
    for c in components {
        number_density += c.distribution.number_density_per_cm3();
        for mode in c.distribution.modes() {
            let (g, conv) =
                integrate_mode(&c.name, &mode, c.refractive_index, wavelength_um, opts)?;
            grids.push(g);
            convergence.push(conv);
        }
    }
    let mut tot = [0.0; 6];
    for g in &grids {
        for (t, v) in tot.iter_mut().zip(g.sums.0) {
            *t += v;
        }
    }
    let [ext, sca, back, gsca, area, vol] = tot;
    let um2_to_m2 = 1e-12;
    let per = |v: f64| v / number_density * um2_to_m2;
    let r_eff = vol / area;
    let ssa = sca / ext;
    let asym = gsca / sca;
    let lidar_ratio = 4.0 * PI * ext / back;

    // Phase function on the final grids.
    let x_eff = 2.0 * PI / wavelength_um * r_eff;
    let theta = match &opts.angles_deg {
        Some(a) => {
            check_angles(a)?;
            a.clone()
        }
        None => default_angle_grid(x_eff),
    };
    let mut phase_4pi = Vec::new();
    let mut elements = Vec::new();
    if !theta.is_empty() {
        let n_max = grids
            .iter()
            .map(|g| n_terms(g.x_lo + g.points as f64 * g.dx))
            .max()
            .unwrap_or(1);
        let tables = angle_tables(&theta, n_max);
        let mut dcdo = MatrixSums::zeros(theta.len());
        for g in &grids {
            dcdo.add(&matrix_integral(g, &tables)?);
        }
        // F_ij = 4π ⟨dC_ij/dΩ⟩/⟨Csca⟩: every element normalised like the phase function; for
        // spheres F22 = F11 and F44 = F33.
        let norm = |d: f64| 4.0 * PI * d / sca;
        phase_4pi = dcdo.s11.iter().map(|d| norm(*d)).collect();
        elements = (0..theta.len())
            .map(|a| MatrixElements {
                f11: phase_4pi[a],
                f22: phase_4pi[a],
                f33: norm(dcdo.s33[a]),
                f44: norm(dcdo.s33[a]),
                f12: norm(dcdo.s12[a]),
                f34: norm(dcdo.s34[a]),
            })
            .collect();
    }

    let refr = if components.len() == 1 {
        format_refractive_index(components[0].refractive_index)
    } else {
        "external mixture (see component_* keys)".to_string()
    };
    let distribution = if components.len() == 1 {
        components[0].distribution.to_string()
    } else {
        components
            .iter()
            .map(|c| c.name.clone())
            .collect::<Vec<_>>()
            .join(" + ")
    };
    let mut meta = vec![
        (
            "wavelength_nm".to_string(),
            // Rounded to 1e-9 nm so 1572e-9 m prints as 1572, not 1572.0000000000002.
            format!("{}", (wavelength_m * 1e18).round() / 1e9),
        ),
        ("refractive_index".to_string(), refr),
        ("distribution".to_string(), distribution),
    ];
    if components.len() > 1 {
        for (i, c) in components.iter().enumerate() {
            meta.push((
                format!("component_{}", i + 1),
                format!(
                    "{}: m = {}, {}",
                    c.name,
                    format_refractive_index(c.refractive_index),
                    c.distribution
                ),
            ));
        }
    }
    let mut push = |k: &str, v: String| meta.push((k.to_string(), v));
    push("number_density_per_cm3", format!("{number_density:.6e}"));
    push(
        "extinction_cross_section_um2",
        format!("{:.9e}", ext / number_density),
    );
    push(
        "scattering_cross_section_um2",
        format!("{:.9e}", sca / number_density),
    );
    push(
        "backscatter_cross_section_um2",
        format!("{:.9e}", back / number_density),
    );
    push("single_scattering_albedo", format!("{ssa:.9}"));
    push("asymmetry", format!("{asym:.9}"));
    push("lidar_ratio_sr", format!("{lidar_ratio:.6}"));
    push("effective_radius_um", format!("{r_eff:.6}"));
    for c in &convergence {
        push(
            "size_grid",
            format!(
                "{}: r {:.6e}..{:.6e} um, dx = {:.3e}, {} radii, last change {:.1e}, {}",
                c.component,
                c.r_range_um.0,
                c.r_range_um.1,
                c.step_x,
                c.points,
                c.last_rel_change,
                if c.converged {
                    "converged"
                } else {
                    "NOT converged"
                }
            ),
        );
    }
    // Metadata keys must be unique: number the size_grid lines.
    let mut n_grid = 0;
    for (k, _) in meta.iter_mut() {
        if k == "size_grid" {
            n_grid += 1;
            *k = format!("size_grid_{n_grid}");
        }
    }
    meta.push((
        "source".to_string(),
        format!(
            "lidarsim {} Mie (Wiscombe 1979/1980 method), trapezoid in size parameter, tail_fraction {:e}, rel_tol {:e}; fingerprint {}",
            env!("CARGO_PKG_VERSION"),
            opts.tail_fraction,
            opts.rel_tol,
            fingerprint_hash(components, wavelength_m, opts)
        ),
    ));
    Ok(BulkOptics {
        wavelength_m,
        extinction_cross_section_m2: per(ext),
        scattering_cross_section_m2: per(sca),
        backscatter_cross_section_m2: per(back),
        single_scattering_albedo: ssa,
        asymmetry: asym,
        lidar_ratio_sr: lidar_ratio,
        number_density_per_m3: number_density * 1e6,
        effective_radius_um: r_eff,
        matrix: MatrixTable {
            meta: meta.clone(),
            theta_deg: theta.clone(),
            elements,
            circular: true,
        },
        phase: PhaseTable {
            meta,
            theta_deg: theta,
            phase_4pi,
        },
        convergence,
    })
}

/// The cost of Mie size integrations, bounded before any of them is done (README, "Limits").
///
/// Time goes in two places: the Mie coefficients of every radius of a mode's grid (Wiscombe's
/// N(x) = x + 4.05 x^(1/3) + 2 terms each), and the matrix products that turn them into the
/// phase function and scattering matrix on K angles (N(x)·K multiply-adds a radius). The grid is
/// the finest the step halving can reach (128·2^j intervals, down to `min_step_x` or up to
/// `max_points`): the halving may stop sooner on convergence, so the count is an upper bound,
/// and for the large droplets whose cost matters it is usually the grid reached. The work is
/// `terms × (angles + c)`, `terms` the sum of N(x) over the grids' radii and `c` the cost of the
/// coefficients in angles ([`crate::limits::MIE_COEFFICIENT_ANGLES`], twice with a phase
/// function: they are computed again for the matrix products); its unit, a "term-angle", takes
/// [`crate::limits::MIE_SECONDS_PER_WORK`] on one core of the reference machine.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct MieWork {
    /// Size integrations: modes × wavelengths.
    pub integrations: u64,
    /// Radii of the finest grids, summed over the integrations.
    pub radii: u64,
    /// Mie terms summed over those radii (an upper bound: N(x) is concave, and is evaluated
    /// at each grid's middle).
    pub terms: f64,
    /// Angles of the phase function (0: none asked for), the largest of the integrations.
    pub angles: u64,
    /// Values of the largest angle table (angles × terms at the largest radius), held twice.
    pub angle_table_values: u64,
    /// `terms × (angles + c)` summed over the integrations \[term-angles\].
    pub work: f64,
}

impl MieWork {
    /// The work of two sets of integrations (the angle table is the larger one's: tables are
    /// made one integration at a time).
    pub fn add(&mut self, o: &MieWork) {
        self.integrations += o.integrations;
        self.radii += o.radii;
        self.terms += o.terms;
        self.angles = self.angles.max(o.angles);
        self.angle_table_values = self.angle_table_values.max(o.angle_table_values);
        self.work += o.work;
    }

    /// The coefficients' cost in angles, `c` (see the type's documentation).
    fn coefficient_angles(&self) -> u64 {
        let c = crate::limits::MIE_COEFFICIENT_ANGLES;
        if self.angles > 0 { 2 * c } else { c }
    }

    /// Seconds on one core of the reference machine (README, "Limits").
    pub fn seconds(&self) -> f64 {
        self.work * crate::limits::MIE_SECONDS_PER_WORK
    }

    /// The work as a product of its factors, for messages.
    fn describe(&self) -> String {
        // Three significant digits: an order of magnitude is what a reader needs here.
        let f = |v: f64| {
            if v >= 1e5 {
                format!("{v:.2e}")
            } else {
                format!("{}", v.round())
            }
        };
        let c = self.coefficient_angles();
        format!(
            "{} size integration{} (modes × wavelengths) over up to {} radii: {} Mie terms × ({} angles + {c} for the coefficients) = {} term-angles, up to about {} on one core",
            self.integrations,
            if self.integrations == 1 { "" } else { "s" },
            self.radii,
            f(self.terms),
            self.angles,
            f(self.work),
            crate::limits::fmt_seconds(self.seconds()),
        )
    }

    /// Ok below the limits, else the message naming the product and the limit.
    pub fn check(&self) -> Result<(), String> {
        use crate::limits::{MAX_MIE_ANGLE_TABLE_VALUES, MAX_MIE_WORK, check_product};
        if self.work > MAX_MIE_WORK {
            return Err(format!(
                "Mie work: {}, more than the limit of {} (about {}; README, \"Limits\")",
                self.describe(),
                crate::input::fmt_bound(MAX_MIE_WORK),
                crate::limits::fmt_seconds(MAX_MIE_WORK * crate::limits::MIE_SECONDS_PER_WORK),
            ));
        }
        let n_max = self
            .angle_table_values
            .checked_div(self.angles)
            .unwrap_or(0);
        check_product(
            "Mie angle tables",
            &[("angles", self.angles), ("Mie terms", n_max)],
            MAX_MIE_ANGLE_TABLE_VALUES,
        )
        .map(|_| ())
    }

    /// A note when the work is allowed but long (above [`crate::limits::MIE_WORK_WARN`]).
    pub fn warning(&self) -> Option<String> {
        (self.work > crate::limits::MIE_WORK_WARN).then(|| format!("Mie work: {}", self.describe()))
    }
}

/// The cost of [`bulk_optics_mixture`] for these inputs ([`MieWork`]), from the radius ranges
/// alone: milliseconds. Errors are those of the inputs (as [`bulk_optics_mixture`] gives them).
pub fn mie_work(
    components: &[Component],
    wavelength_m: f64,
    opts: &BulkOptions,
) -> Result<MieWork, MieError> {
    check_inputs(components, wavelength_m, opts)?;
    let k = 2.0 * PI / (wavelength_m * 1e6);
    let n_terms_f = |x: f64| x + 4.05 * x.cbrt() + 2.0;
    let mut w = MieWork::default();
    let (mut area, mut vol, mut x_max) = (0.0, 0.0, 0.0f64);
    for c in components {
        let n = c.distribution.number_density_per_cm3();
        area += n * c.distribution.moment(2.0);
        vol += n * c.distribution.moment(3.0);
        for mode in c.distribution.modes() {
            let (r_lo, r_hi) = mode_range_um(&mode, k, opts)?;
            let (x_lo, x_hi) = (k * r_lo, k * r_hi);
            let radii = max_intervals(x_lo, x_hi, opts) + 1;
            w.integrations += 1;
            w.radii += radii as u64;
            w.terms += radii as f64 * n_terms_f(0.5 * (x_lo + x_hi));
            x_max = x_max.max(x_hi);
        }
    }
    // The angles bulk_optics_mixture will use: its default grid depends on the effective size
    // parameter (here of the untruncated distributions, within the integrated range).
    w.angles = match &opts.angles_deg {
        Some(a) => a.len() as u64,
        None => default_angle_grid((k * vol / area).min(x_max)).len() as u64,
    };
    w.angle_table_values = w.angles.saturating_mul(n_terms(x_max) as u64);
    w.work = w.terms * (w.angles + w.coefficient_angles()) as f64;
    Ok(w)
}

/// The cost of the size integrations of several (components, wavelength) sets, each counted
/// once however often it appears (equal inputs are computed once: the cache of
/// [`super::cache`]).
pub fn mie_work_of<'a>(
    sets: impl IntoIterator<Item = (&'a [Component], f64)>,
    opts: &BulkOptions,
) -> Result<MieWork, MieError> {
    let mut seen = std::collections::HashSet::new();
    let mut total = MieWork::default();
    for (components, wavelength_m) in sets {
        if seen.insert(fingerprint(components, wavelength_m, opts)) {
            total.add(&mie_work(components, wavelength_m, opts)?);
        }
    }
    Ok(total)
}

/// The checks of [`bulk_optics_mixture`]'s inputs that need no Mie theory.
fn check_inputs(
    components: &[Component],
    wavelength_m: f64,
    opts: &BulkOptions,
) -> Result<(), MieError> {
    if components.is_empty() {
        return Err(param("components", 0.0, "at least one component is needed"));
    }
    if !(wavelength_m.is_finite() && wavelength_m > 1e-8 && wavelength_m < 1e-3) {
        return Err(param(
            "wavelength_m",
            wavelength_m,
            "must lie in (10 nm, 1 mm)",
        ));
    }
    if !(opts.tail_fraction > 0.0 && opts.tail_fraction < 0.1) {
        return Err(param(
            "tail_fraction",
            opts.tail_fraction,
            "must lie in (0, 0.1)",
        ));
    }
    if !(opts.rel_tol > 0.0 && opts.rel_tol < 0.5) {
        return Err(param("rel_tol", opts.rel_tol, "must lie in (0, 0.5)"));
    }
    if !(opts.min_step_x > 0.0) {
        return Err(param("min_step_x", opts.min_step_x, "must be > 0"));
    }
    if opts.max_points < 257 {
        return Err(param("max_points", opts.max_points as f64, "must be ≥ 257"));
    }
    for c in components {
        check_refractive_index(c.refractive_index)?;
        let contrast = (c.refractive_index - 1.0).norm();
        if contrast < MIN_INDEX_CONTRAST {
            return Err(param(
                "|refractive_index − 1|",
                contrast,
                "must be ≥ 1e-6: particles with (nearly) the medium's index scatter \
                 (nearly) nothing, no phase function or lidar ratio follows, and their Mie sums \
                 are rounding noise",
            ));
        }
        if matches!(&c.distribution, SizeDistribution::Sum(v) if v.is_empty()) {
            return Err(param("modes", 0.0, "a sum needs at least one mode"));
        }
    }
    if let Some(a) = &opts.angles_deg {
        check_angles(a)?;
    }
    Ok(())
}

fn check_angles(a: &[f64]) -> Result<(), MieError> {
    if a.is_empty() {
        return Ok(());
    }
    if a[0] != 0.0 || a[a.len() - 1] != 180.0 {
        return Err(param(
            "angles_deg",
            a[0],
            "must run from exactly 0 to exactly 180",
        ));
    }
    for w in a.windows(2) {
        if !(w[1] > w[0]) {
            return Err(param("angles_deg", w[1], "must strictly increase"));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn c1_number_density_moments_and_quantiles() {
        let c1 = SizeDistribution::deirmendjian_c1();
        // N = a Γ(7)/1.5⁷ = 2.373·720/17.0859375 = 99.998 cm⁻³ (Deirmendjian: 100).
        assert!((c1.number_density_per_cm3() - 2.373 * 720.0 / 1.5f64.powi(7)).abs() < 1e-9);
        // r_eff = Γ(10)/Γ(9)/1.5 = 9/1.5 = 6 µm.
        assert!((c1.effective_radius_um() - 6.0).abs() < 1e-12);
        let q = c1.area_quantile(0.5);
        assert!((c1.area_cdf(q) - 0.5).abs() < 1e-9);
    }

    #[test]
    fn lognormal_moments_match_quadrature() {
        let d = SizeDistribution::lognormal(100.0, 0.1, 2.0).unwrap();
        // ∫ r² n dr by midpoint rule in ln r against the closed form.
        let (a, b, n) = ((1e-4f64).ln(), (1e2f64).ln(), 200_000);
        let h = (b - a) / n as f64;
        let mut s = 0.0;
        let mut s0 = 0.0;
        for i in 0..n {
            let r = (a + (i as f64 + 0.5) * h).exp();
            s += d.density(r) * r * r * r * h;
            s0 += d.density(r) * r * h;
        }
        assert!((s0 / 100.0 - 1.0).abs() < 1e-9);
        assert!((s / 100.0 / d.moment(2.0) - 1.0).abs() < 1e-9);
    }

    /// The work's radii are the grid the step halving reaches when it cannot converge (a
    /// tolerance it never meets), radius for radius, and bound it when it converges sooner;
    /// its Mie terms bound the sum of N(x) over those radii; the angles are the ones used.
    #[test]
    fn mie_work_bounds_the_grid_and_the_terms() {
        let m = Complex64::new(1.5, 0.01);
        let bimodal = SizeDistribution::sum(vec![
            SizeDistribution::lognormal(100.0, 0.05, 1.6).unwrap(),
            SizeDistribution::lognormal(1.0, 0.5, 1.4).unwrap(),
        ])
        .unwrap();
        let comps = |d: &SizeDistribution| {
            vec![Component {
                name: "p".into(),
                distribution: d.clone(),
                refractive_index: m,
            }]
        };
        let never = BulkOptions {
            rel_tol: 1e-15,
            angles_deg: Some(vec![]),
            ..BulkOptions::default()
        };
        let w = mie_work(&comps(&bimodal), 1064e-9, &never).unwrap();
        let b = bulk_optics(&bimodal, m, 1064e-9, &never).unwrap();
        assert_eq!(w.integrations, 2);
        assert!(b.convergence.iter().all(|c| !c.converged));
        let radii: usize = b.convergence.iter().map(|c| c.points).sum();
        assert_eq!(w.radii, radii as u64);
        // Σ N(x) over the final grids, directly.
        let k = 2.0 * PI / 1.064;
        let direct: f64 = b
            .convergence
            .iter()
            .map(|c| {
                let (x0, x1) = (k * c.r_range_um.0, k * c.r_range_um.1);
                (0..c.points)
                    .map(|i| {
                        let x = x0 + (x1 - x0) * i as f64 / (c.points - 1) as f64;
                        x + 4.05 * x.cbrt() + 2.0
                    })
                    .sum::<f64>()
            })
            .sum();
        assert!(
            w.terms >= direct && w.terms < 1.05 * direct,
            "{} vs {direct}",
            w.terms
        );
        assert_eq!(w.angles, 0);
        assert_eq!(w.work, w.terms * 200.0);
        // Converging at the default tolerance: fewer radii than the bound; the default grid's
        // angles counted.
        let w = mie_work(&comps(&bimodal), 1064e-9, &BulkOptions::default()).unwrap();
        let b = bulk_optics(&bimodal, m, 1064e-9, &BulkOptions::default()).unwrap();
        let radii: usize = b.convergence.iter().map(|c| c.points).sum();
        assert!(w.radii >= radii as u64);
        assert_eq!(w.angles, b.phase.theta_deg.len() as u64);
        // The same inputs twice count once; two wavelengths twice.
        let c = comps(&bimodal);
        let sets = [(&c[..], 1064e-9), (&c[..], 1064e-9), (&c[..], 532e-9)];
        let all = mie_work_of(sets, &BulkOptions::default()).unwrap();
        assert_eq!(all.integrations, 4);
    }

    /// Beyond the limit, `bulk_optics` refuses before any work, naming the product and the
    /// limit: 2 mm drops at 532 nm with a phase function.
    #[test]
    fn bulk_optics_refuses_work_beyond_the_limit() {
        let d = SizeDistribution::lognormal(1.0, 2000.0, 1.2).unwrap();
        let t = std::time::Instant::now();
        let e = bulk_optics(
            &d,
            Complex64::new(1.33, 0.0),
            532e-9,
            &BulkOptions::default(),
        )
        .unwrap_err();
        assert!(t.elapsed().as_secs_f64() < 1.0);
        let MieError::Work(msg) = e else {
            panic!("{e:?}")
        };
        assert!(
            msg.contains("term-angles") && msg.contains("limit of 4e13") && msg.contains("Limits"),
            "{msg}"
        );
    }

    #[test]
    fn constructors_reject_bad_parameters() {
        assert!(SizeDistribution::lognormal(1.0, 0.1, 1.0).is_err());
        assert!(SizeDistribution::lognormal(-1.0, 0.1, 2.0).is_err());
        assert!(SizeDistribution::modified_gamma(1.0, -2.0, 1.0, 1.0).is_err());
        assert!(SizeDistribution::modified_gamma(1.0, 2.0, 0.0, 1.0).is_err());
        assert!(SizeDistribution::sum(vec![]).is_err());
        assert!(
            SizeDistribution::deirmendjian_c1()
                .truncated(5.0, 1.0)
                .is_err()
        );
    }
}
