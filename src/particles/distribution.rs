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
//! Each mode is integrated with the trapezoid rule in size parameter over the radius range that
//! holds all but `tail_fraction` of the mode's geometric cross-section (`∫ π r² n dr`, half in
//! each tail), cut into 16 panels equal in ln x, each starting with 8 intervals. All panels are
//! halved together (reusing their points) until two successive halvings change the mode's
//! extinction, scattering, backscatter and `g·Csca` integrals by less than `rel_tol`; but a
//! panel halved twice may stop early, smallest changes per unit cost of the next halving first
//! (radii times Mie terms), while the last changes of the stopped panels sum to at most a tenth
//! of `rel_tol`: the panels in the tails, which hold little of the integrals, stay coarse, and
//! a settled panel of large size parameters stops before a cheap one. The backscatter of nearly non-absorbing droplets
//! converges slowest (narrow resonances; `docs/particles.md` gives the convergence seen). The
//! angular integrals (phase function, matrix) are summed on the fly from the same Mie
//! coefficients, on the same points, so `P(180°)` in the table is exactly the backscatter used
//! for the lidar ratio, and nothing is stored per radius: memory does not grow with the number
//! of radii. Radii are evaluated in parallel (rayon) in fixed blocks whose sums are reduced in
//! block order: the numbers do not depend on the thread count.

// `!(v > 0.0)` is used on purpose: unlike `v <= 0.0` it also rejects NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use std::f64::consts::PI;
use std::fmt;

use statrs::function::gamma::{gamma_lr, ln_gamma};

use super::mie::MieError;

mod bulk;
mod fingerprint;
mod integrate;
mod options;
mod work;

pub use bulk::{bulk_optics, bulk_optics_mixture, bulk_optics_mixture_with_progress};
pub use fingerprint::{MIE_VERSION, fingerprint, fingerprint_hash, format_refractive_index};
pub use options::{
    BulkOptics, BulkOptions, Component, MIN_INDEX_CONTRAST, MieProgress, ModeConvergence,
    default_angle_grid, progress_lines, set_progress_lines,
};
pub use work::{MieWork, mie_work, mie_work_of};

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

#[cfg(test)]
mod tests;
