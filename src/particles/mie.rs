//! Mie scattering by a homogeneous sphere: efficiencies, asymmetry and amplitude functions.
//!
//! The method is Wiscombe's (1979, 1980)[^w]: the series is summed to
//! `N = x + 4.05 x^(1/3) + 2` terms; the logarithmic derivative `D_n(mx) = ψ_n'(mx)/ψ_n(mx)` comes
//! from the downward recurrence (Bohren & Huffman 1983[^bh], Eq. 4.89), started at `n = N` with
//! the exact value from Lentz's (1976)[^lentz] continued fraction, so it is stable for any
//! refractive index; the Riccati–Neumann function `η_n(x)` is run upward (its growing direction).
//! The Riccati–Bessel function `ψ_n(x)` is built upward from ratios,
//! `ψ_n = ψ_(n−1) / (D_n(x) + n/x)` (which follows from `ψ_(n−1) = ψ_n' + (n/x) ψ_n`), with the real
//! `D_n(x)` also from the downward recurrence, started from the larger of `ψ_0`, `ψ_1`: every
//! `ψ_n` then has full relative precision, even for `n ≫ x`, for `x = 10⁻³` where the plain
//! upward recurrence loses all digits, and at `x ≈ jπ` where `sin x` itself is inexact. The
//! series is accurate from `x = 10⁻⁶` up (tested against Wiscombe's small-particle values, which
//! are themselves accurate to ~10⁻⁷ there). Below [`SMALL_X`] (where `1/x^n` overflows as x → 0)
//! the coefficients come from their small-particle expansions (Bohren & Huffman 1983, §5.1), with
//! a relative error of order `x²` (< 10⁻¹²), and the efficiencies from the same expansions
//! divided by `x³` beforehand, so that nothing underflows into 0/0: amplitudes of order `x³`
//! underflow to a correct 0 below `x ≈ 10⁻¹⁰³`, efficiencies stay finite down to the smallest
//! positive `x`.
//!
//! # Conventions
//!
//! * Refractive index `m = n + i k` relative to the surrounding medium, `k ≥ 0` meaning
//!   **absorption** (MIEV0 and miepython write the same index as `n − i k`).
//! * Size parameter `x = 2π r / λ` (λ in the medium).
//! * Amplitudes `S1`, `S2` are Wiscombe's (MIEV0, miepython `norm="wiscombe"`), with
//!   `Qext = 4 Re S1(0°) / x²` and `Qback = 4 |S1(180°)|² / x²`. Bohren & Huffman's BHMIE (and
//!   PyMieScatt) amplitudes are their complex conjugates.
//! * `Qback` is the "radar" backscatter efficiency: `Cback = Qback π r²` and the differential
//!   backscatter cross-section is `Cback / (4π)`. The phase function normalised to 4π is
//!   `P(θ) = 2 (|S1|² + |S2|²) / (x² Qsca)`.
//!
//! [^w]: Wiscombe, W. J. (1979, rev. 1996), *Mie scattering calculations: advances in technique
//!     and fast, vector-speed computer codes*, NCAR/TN-140+STR; Wiscombe, W. J. (1980), Improved
//!     Mie scattering algorithms, *Appl. Opt.* 19, 1505–1509, doi:10.1364/AO.19.001505.
//! [^bh]: Bohren, C. F. & Huffman, D. R. (1983), *Absorption and Scattering of Light by Small
//!     Particles*, Wiley, ch. 4 (Eqs. 4.53, 4.56, 4.61, 4.62, 4.74, 4.88, 4.89).
//! [^lentz]: Lentz, W. J. (1976), Generating Bessel functions in Mie scattering calculations
//!     using continued fractions, *Appl. Opt.* 15, 668–671, doi:10.1364/AO.15.000668.

// `!(v > 0.0)` is used on purpose: unlike `v <= 0.0` it also rejects NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use num_complex::Complex64;

use super::matrix::MatrixElements;

/// Largest real and imaginary parts of a refractive index accepted: beyond any material at
/// optical and infrared wavelengths (metals in the far infrared reach a few tens), and a range
/// where the solver is checked to give finite results.
pub const MAX_REFRACTIVE_INDEX_PART: f64 = 100.0;

/// Largest size parameter accepted (the solver is tested to 2·10⁴; memory and time grow as x).
pub const MAX_SIZE_PARAMETER: f64 = 1.0e5;

/// Below this size parameter the coefficients come from the small-particle expansions (see the
/// module documentation): their error, of relative order `x²` and `(mx)²`, is below 2·10⁻⁸ there
/// for any accepted index, and the series' `1/x^n` would overflow further down.
pub const SMALL_X: f64 = 1e-6;

/// Why a Mie calculation was refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum MieError {
    /// The size parameter is not a finite number in (0, [`MAX_SIZE_PARAMETER`]].
    #[error("size parameter x = {0} must be finite, > 0 and ≤ {MAX_SIZE_PARAMETER:e}")]
    SizeParameter(f64),
    /// The refractive index is not finite, has a real part outside (0, 100] or an imaginary
    /// part outside [0, 100] ([`MAX_REFRACTIVE_INDEX_PART`]).
    #[error(
        "refractive index {re}{im:+}i must be finite with real part in (0, 100] and imaginary part in [0, 100] (≥ 0 means absorbing)",
        re = .0.re,
        im = .0.im
    )]
    RefractiveIndex(Complex64),
    /// A cosine of the scattering angle outside [−1, 1] (or not finite).
    #[error("cosine of the scattering angle {0} must lie in [-1, 1]")]
    Cosine(f64),
    /// The size integration would take longer than the limit allows (README, "Limits"): the
    /// message names the product and the limit.
    #[error("{0}")]
    Work(String),
    /// A size-distribution or integration parameter is invalid.
    #[error("{name} = {value}: {reason}")]
    Parameter {
        /// The parameter's name.
        name: &'static str,
        /// Its value.
        value: f64,
        /// The broken constraint.
        reason: &'static str,
    },
}

/// Efficiencies and asymmetry parameter of one sphere.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MieResult {
    /// Extinction efficiency `Qext = Cext / (π r²)`.
    pub qext: f64,
    /// Scattering efficiency `Qsca`.
    pub qsca: f64,
    /// Backscatter ("radar") efficiency `Qback = 4|S1(180°)|²/x²`.
    pub qback: f64,
    /// Asymmetry parameter `g = ⟨cos θ⟩` of the scattered light.
    pub g: f64,
    /// Single-scattering albedo `Qsca/Qext` (1 for a sphere that scatters nothing too).
    pub ssa: f64,
    /// Number of terms summed.
    pub n_terms: usize,
}

/// The scattering coefficients `a_n`, `b_n` (n = 1..N) of one sphere, from which efficiencies and
/// amplitudes at any angles follow.
///
/// The coefficients are stored in Bohren & Huffman's convention (BH Eq. 4.53 with `m = n + ik`);
/// the efficiencies do not depend on it, and [`MieCoefficients::amplitudes`] returns Wiscombe's
/// amplitudes (the complex conjugates of BH's).
#[derive(Debug, Clone, PartialEq)]
pub struct MieCoefficients {
    /// Size parameter.
    pub x: f64,
    /// `a_n` for n = 1..N (index n−1).
    pub a: Vec<Complex64>,
    /// `b_n` for n = 1..N (index n−1).
    pub b: Vec<Complex64>,
    lossless: bool,
    /// Below [`SMALL_X`]: `a_1/x³, b_1/x³, a_2/x³` (`b_2` = O(x⁷) is 0), from which the
    /// efficiencies and the normalised matrix are formed without dividing underflowed numbers.
    small: Option<[Complex64; 3]>,
}

/// Wiscombe's number of terms, `N = x + 4.05 x^(1/3) + 2` (Wiscombe 1980, Eq. 5), at least 1.
pub fn n_terms(x: f64) -> usize {
    ((x + 4.05 * x.cbrt() + 2.0) as usize).max(1)
}

fn check_x(x: f64) -> Result<(), MieError> {
    if x.is_finite() && x > 0.0 && x <= MAX_SIZE_PARAMETER {
        Ok(())
    } else {
        Err(MieError::SizeParameter(x))
    }
}

/// Check a refractive index against the conventions of this module.
pub fn check_refractive_index(m: Complex64) -> Result<(), MieError> {
    if m.re > 0.0
        && m.re <= MAX_REFRACTIVE_INDEX_PART
        && m.im >= 0.0
        && m.im <= MAX_REFRACTIVE_INDEX_PART
    {
        Ok(())
    } else {
        Err(MieError::RefractiveIndex(m))
    }
}

/// `D_N(z) = ψ_N'(z)/ψ_N(z)` by Lentz's (1976) continued fraction for `J_(N+1/2)/J_(N−1/2)`:
/// `D_N(z) = −N/z + 1/(a_1 + 1/(a_2 + …))`, `a_k = (−1)^(k+1) 2(N + k − 1/2)/z`.
fn lentz_dn(z: Complex64, n: usize) -> Complex64 {
    let nf = n as f64;
    let zinv = 2.0 / z;
    // Product form of the continued fraction (Lentz 1976, Eqs. 5–9).
    let a1 = (nf + 0.5) * zinv;
    let mut aj = -(nf + 1.5) * zinv;
    let mut num = aj + 1.0 / a1;
    let mut den = aj;
    let mut ratio = num / den;
    let mut result = a1 * ratio;
    let mut sign_zinv = zinv;
    // |z| + N + 100 iterations always suffice (the fraction converges once k exceeds |z|).
    let max_iter = (z.norm() as usize + n + 100).min(10_000_000);
    for _ in 0..max_iter {
        // |ratio − 1| ≤ ε also bounds ||ratio| − 1|: one test is enough (squared: no hypot,
        // which cost 2 % of an OPAC run).
        if (ratio - 1.0).norm_sqr() <= 1e-28 {
            break;
        }
        aj = sign_zinv - aj;
        // a_(j) = (−1)^(j+1) (2(N+j)−1)/z … written as the running update of Lentz's scheme.
        num = 1.0 / num + aj;
        den = 1.0 / den + aj;
        ratio = num / den;
        sign_zinv = -sign_zinv;
        result *= ratio;
    }
    -nf / z + result
}

/// Fill `d[0..=n]` with `D_k(z)`, k = 0..n, by the downward recurrence
/// `D_(k−1) = k/z − 1/(D_k + k/z)` (BH Eq. 4.89) started from Lentz's exact `D_n`.
fn d_downward(z: Complex64, n: usize, d: &mut Vec<Complex64>) {
    d.clear();
    d.resize(n + 1, Complex64::new(0.0, 0.0));
    let mut dk = lentz_dn(z, n);
    d[n] = dk;
    let inv_z = 1.0 / z;
    for k in (1..=n).rev() {
        let k_over_z = k as f64 * inv_z;
        dk = k_over_z - 1.0 / (dk + k_over_z);
        d[k - 1] = dk;
    }
}

/// The real `D_k(x)`, k = 0..n, for real argument (same recurrence, real arithmetic).
fn d_downward_real(x: f64, n: usize, d: &mut Vec<f64>) {
    d.clear();
    d.resize(n + 1, 0.0);
    let mut dk = lentz_dn(Complex64::new(x, 0.0), n).re;
    d[n] = dk;
    for k in (1..=n).rev() {
        let k_over_x = k as f64 / x;
        dk = k_over_x - 1.0 / (dk + k_over_x);
        d[k - 1] = dk;
    }
}

/// `ψ_k(x)`, k = 0..=n, from the ratios `ψ_k = ψ_(k−1) / (D_k(x) + k/x)` (exact relation, full
/// relative precision at every order). The chain starts from whichever of `ψ_0 = sin x` and
/// `ψ_1 = sin x / x − cos x` is larger: near a zero of sin x (x ≈ jπ) `sin x` has a large
/// relative rounding error that the chain would otherwise carry to every order.
fn psi_table(x: f64, n: usize, dx: &[f64], psi: &mut Vec<f64>) {
    psi.clear();
    psi.resize(n + 1, 0.0);
    let (sin_x, cos_x) = x.sin_cos();
    psi[0] = sin_x;
    if n == 0 {
        return;
    }
    let psi1 = sin_x / x - cos_x;
    psi[1] = if psi1.abs() >= sin_x.abs() {
        psi1
    } else {
        sin_x / (dx[1] + 1.0 / x)
    };
    for (k, d) in dx.iter().enumerate().take(n + 1).skip(2) {
        psi[k] = psi[k - 1] / (d + k as f64 / x);
    }
}

impl MieCoefficients {
    /// Coefficients of a sphere with relative refractive index `m` (imaginary part ≥ 0 absorbing)
    /// and size parameter `x`.
    ///
    /// BH Eq. 4.88: `a_n = [(D_n(mx)/m + n/x) ψ_n − ψ_(n−1)] / [(D_n(mx)/m + n/x) ξ_n − ξ_(n−1)]`,
    /// `b_n` the same with `m D_n(mx)`; `ξ_n = ψ_n + i η_n` (`η_n = x y_n(x)`). Valid for
    /// `0 < x ≤ MAX_SIZE_PARAMETER`, any finite `m` with `Re m > 0`, `Im m ≥ 0`.
    pub fn compute(m: Complex64, x: f64) -> Result<Self, MieError> {
        check_x(x)?;
        check_refractive_index(m)?;
        if x < SMALL_X {
            return Ok(Self::small(m, x));
        }
        let n = n_terms(x);
        let mut dmx = Vec::new();
        d_downward(m * x, n, &mut dmx);
        let mut dx = Vec::new();
        d_downward_real(x, n, &mut dx);
        let mut psis = Vec::new();
        psi_table(x, n, &dx, &mut psis);
        let (sin_x, cos_x) = x.sin_cos();
        let inv_x = 1.0 / x;
        let inv_m = 1.0 / m;
        let mut a = Vec::with_capacity(n);
        let mut b = Vec::with_capacity(n);
        // η_0 = −cos x, η_1 = −cos x / x − sin x (upward: η grows with n).
        let mut psi_prev = psis[0];
        let mut eta_prev = -cos_x;
        let mut eta = -cos_x * inv_x - sin_x;
        for k in 1..=n {
            let kx = k as f64 * inv_x;
            let psi = psis[k];
            let xi = Complex64::new(psi, eta);
            let xi_prev = Complex64::new(psi_prev, eta_prev);
            let t = dmx[k] * inv_m + kx;
            a.push((t * psi - psi_prev) / (t * xi - xi_prev));
            let t = dmx[k] * m + kx;
            b.push((t * psi - psi_prev) / (t * xi - xi_prev));
            let eta_next = (2 * k + 1) as f64 * inv_x * eta - eta_prev;
            eta_prev = eta;
            eta = eta_next;
            psi_prev = psi;
        }
        Ok(MieCoefficients {
            x,
            a,
            b,
            lossless: m.im == 0.0,
            small: None,
        })
    }

    /// The small-particle expansions (Bohren & Huffman 1983, §5.1, to order x⁶):
    ///
    /// ```text
    /// a_1 = −(2i x³/3) K − (2i x⁵/5) (m²−2)/(m²+2) K + (4x⁶/9) K²,   K = (m²−1)/(m²+2)
    /// b_1 = −(i x⁵/45) (m²−1),   a_2 = −(i x⁵/15) (m²−1)/(2m²+3),   b_2 = O(x⁷)
    /// ```
    ///
    /// (the x⁶ term is the leading real part of `a_1` for a lossless sphere: Qext = Qsca).
    fn small(m: Complex64, x: f64) -> Self {
        let i = Complex64::new(0.0, 1.0);
        let m2 = m * m;
        let k = (m2 - 1.0) / (m2 + 2.0);
        let x2 = x * x;
        let alpha1 = -i * (2.0 / 3.0) * k - i * (2.0 / 5.0) * x2 * (m2 - 2.0) / (m2 + 2.0) * k
            + (4.0 / 9.0) * x2 * x * k * k;
        let beta1 = -i * x2 / 45.0 * (m2 - 1.0);
        let alpha2 = -i * x2 / 15.0 * (m2 - 1.0) / (2.0 * m2 + 3.0);
        let x3 = x2 * x;
        MieCoefficients {
            x,
            a: vec![alpha1 * x3, alpha2 * x3],
            b: vec![beta1 * x3, Complex64::new(0.0, 0.0)],
            lossless: m.im == 0.0,
            small: Some([alpha1, beta1, alpha2]),
        }
    }

    /// Coefficients of a perfectly conducting sphere (the limit |m| → ∞, MIEV0's `PERFCT`):
    /// `a_n = (n ψ_n/x − ψ_(n−1)) / (n ξ_n/x − ξ_(n−1))`, `b_n = ψ_n / ξ_n` (BH Eq. 4.53 with
    /// `D_n(mx)/m → 0`, `m D_n(mx) → ∞`).
    pub fn perfect_conductor(x: f64) -> Result<Self, MieError> {
        check_x(x)?;
        let n = n_terms(x);
        let mut dx = Vec::new();
        d_downward_real(x, n, &mut dx);
        let mut psis = Vec::new();
        psi_table(x, n, &dx, &mut psis);
        let (sin_x, cos_x) = x.sin_cos();
        let inv_x = 1.0 / x;
        let mut a = Vec::with_capacity(n);
        let mut b = Vec::with_capacity(n);
        let mut psi_prev = psis[0];
        let mut eta_prev = -cos_x;
        let mut eta = -cos_x * inv_x - sin_x;
        for (k, &psi) in psis.iter().enumerate().skip(1) {
            let kx = k as f64 * inv_x;
            let xi = Complex64::new(psi, eta);
            let xi_prev = Complex64::new(psi_prev, eta_prev);
            a.push((kx * psi - psi_prev) / (kx * xi - xi_prev));
            b.push(psi / xi);
            let eta_next = (2 * k + 1) as f64 * inv_x * eta - eta_prev;
            eta_prev = eta;
            eta = eta_next;
            psi_prev = psi;
        }
        Ok(MieCoefficients {
            x,
            a,
            b,
            lossless: true,
            small: None,
        })
    }

    /// Number of terms N.
    pub fn len(&self) -> usize {
        self.a.len()
    }

    /// Always false (N ≥ 1); present for clippy's `len_without_is_empty`.
    pub fn is_empty(&self) -> bool {
        self.a.is_empty()
    }

    /// Efficiencies and asymmetry (BH Eqs. 4.61, 4.62, 4.74 and §4.5):
    ///
    /// ```text
    /// Qext  = (2/x²) Σ (2n+1) Re(a_n + b_n)
    /// Qsca  = (2/x²) Σ (2n+1) (|a_n|² + |b_n|²)        (= Qext exactly for a lossless sphere)
    /// Qback = (1/x²) |Σ (2n+1) (−1)ⁿ (a_n − b_n)|²
    /// g Qsca = (4/x²) Σ [ n(n+2)/(n+1) Re(a_n a*_(n+1) + b_n b*_(n+1)) + (2n+1)/(n(n+1)) Re(a_n b*_n) ]
    /// ```
    pub fn efficiencies(&self) -> MieResult {
        if let Some(s) = self.small {
            return self.small_efficiencies(s);
        }
        let n = self.a.len();
        let mut ext = 0.0;
        let mut sca = 0.0;
        let mut back = Complex64::new(0.0, 0.0);
        let mut gsum = 0.0;
        for i in 0..n {
            let nf = (i + 1) as f64;
            let c = 2.0 * nf + 1.0;
            let (an, bn) = (self.a[i], self.b[i]);
            ext += c * (an.re + bn.re);
            sca += c * (an.norm_sqr() + bn.norm_sqr());
            let d = c * (an - bn);
            back += if i % 2 == 0 { -d } else { d };
            gsum += c / (nf * (nf + 1.0)) * (an * bn.conj()).re;
            if i + 1 < n {
                let (an1, bn1) = (self.a[i + 1], self.b[i + 1]);
                gsum += nf * (nf + 2.0) / (nf + 1.0) * (an * an1.conj() + bn * bn1.conj()).re;
            }
        }
        let x2 = self.x * self.x;
        let qext = 2.0 * ext / x2;
        let qsca = if self.lossless { qext } else { 2.0 * sca / x2 };
        let g = if sca > 0.0 {
            4.0 * gsum / x2 / (2.0 * sca / x2)
        } else {
            0.0
        };
        let ssa = if qext > 0.0 { qsca / qext } else { 1.0 };
        MieResult {
            qext,
            qsca,
            qback: back.norm_sqr() / x2,
            g,
            ssa,
            n_terms: n,
        }
    }

    /// The sums above with `a_1 = x³α_1`, `b_1 = x³β_1`, `a_2 = x³α_2`, `b_2 = 0`, the powers of
    /// x taken out: Qext = 2x Σ, Qsca = 2x⁴ Σ, Qback = x⁴ |…|², g free of x.
    fn small_efficiencies(&self, [alpha1, beta1, alpha2]: [Complex64; 3]) -> MieResult {
        let x = self.x;
        let sca = 3.0 * (alpha1.norm_sqr() + beta1.norm_sqr()) + 5.0 * alpha2.norm_sqr();
        let x4 = x * x * x * x;
        let qsca = 2.0 * x4 * sca;
        // A lossless sphere's Re a_1 is its x⁶ term; |a_1|² is as accurate and the same number.
        let qext = if self.lossless {
            qsca
        } else {
            2.0 * x * (3.0 * (alpha1.re + beta1.re) + 5.0 * alpha2.re)
        };
        let back = -3.0 * (alpha1 - beta1) + 5.0 * alpha2;
        let gsum = 1.5 * (alpha1 * (alpha2 + beta1).conj()).re;
        MieResult {
            qext,
            qsca,
            qback: x4 * back.norm_sqr(),
            g: if sca > 0.0 { 2.0 * gsum / sca } else { 0.0 },
            // From the scaled sums: Qsca/Qext = x³ Σ|·|² / Σ Re(·), which underflows to the
            // correct 0 for an absorbing sphere where Qext itself would be 0.
            ssa: if self.lossless {
                1.0
            } else {
                let ext = 3.0 * (alpha1.re + beta1.re) + 5.0 * alpha2.re;
                if ext > 0.0 {
                    (x * x * x * sca / ext).min(1.0)
                } else {
                    1.0
                }
            },
            n_terms: self.a.len(),
        }
    }

    /// Amplitude functions `S1(μ)`, `S2(μ)` (Wiscombe's convention, see the module doc) at the
    /// cosines `mu` of the scattering angle:
    ///
    /// ```text
    /// S1 = Σ (2n+1)/(n(n+1)) (a_n π_n + b_n τ_n)*,   S2 = Σ (2n+1)/(n(n+1)) (a_n τ_n + b_n π_n)*
    /// π_n = ((2n−1) μ π_(n−1) − n π_(n−2)) / (n−1),   τ_n = n μ π_n − (n+1) π_(n−1)   (BH Eq. 4.47)
    /// ```
    pub fn amplitudes(&self, mu: &[f64]) -> Result<(Vec<Complex64>, Vec<Complex64>), MieError> {
        if let Some(&bad) = mu.iter().find(|u| !(u.abs() <= 1.0)) {
            return Err(MieError::Cosine(bad));
        }
        let mut s1 = Vec::with_capacity(mu.len());
        let mut s2 = Vec::with_capacity(mu.len());
        for &u in mu {
            let (p, q) = amplitude_at(&self.a, &self.b, u);
            s1.push(p);
            s2.push(q);
        }
        Ok((s1, s2))
    }
}

/// `S1(μ)`, `S2(μ)` (Wiscombe's) from the coefficients `a`, `b` (BH's): see
/// [`MieCoefficients::amplitudes`].
fn amplitude_at(a: &[Complex64], b: &[Complex64], mu: f64) -> (Complex64, Complex64) {
    let mut s1 = Complex64::new(0.0, 0.0);
    let mut s2 = Complex64::new(0.0, 0.0);
    let mut pi_prev = 0.0;
    let mut pi = 1.0;
    for i in 0..a.len() {
        let nf = (i + 1) as f64;
        let tau = nf * mu * pi - (nf + 1.0) * pi_prev;
        let c = (2.0 * nf + 1.0) / (nf * (nf + 1.0));
        let (an, bn) = (a[i], b[i]);
        s1 += c * (an * pi + bn * tau);
        s2 += c * (an * tau + bn * pi);
        let pi_next = ((2.0 * nf + 1.0) * mu * pi - (nf + 1.0) * pi_prev) / nf;
        pi_prev = pi;
        pi = pi_next;
    }
    (s1.conj(), s2.conj())
}

impl MieCoefficients {
    /// The scattering matrix of this sphere at the cosines `mu`, normalised like the phase
    /// function (F11 = 2(|S1|² + |S2|²)/(x² Qsca), ½∫F11 dμ = 1): F_ij = 4 S_ij/(x² Qsca) with
    /// Bohren & Huffman's S_ij (eq. 4.77) from their amplitudes (the conjugates of
    /// [`Self::amplitudes`]), through [`four_s_from_s_pm`]. For a sphere F22 = F11 and
    /// F44 = F33.
    pub fn matrix(&self, mu: &[f64]) -> Result<Vec<MatrixElements>, MieError> {
        let (s1, s2) = self.amplitudes(mu)?;
        let mut norm = 1.0 / (self.x * self.x * self.efficiencies().qsca);
        // A small sphere: the amplitudes divided by x³ and x² Qsca by x⁶, which underflow
        // neither (F does not depend on the scale).
        let (s1, s2) = match self.small {
            Some([alpha1, beta1, alpha2]) => {
                let sca = 3.0 * (alpha1.norm_sqr() + beta1.norm_sqr()) + 5.0 * alpha2.norm_sqr();
                norm = 1.0 / (2.0 * sca);
                let zero = Complex64::new(0.0, 0.0);
                mu.iter()
                    .map(|&u| amplitude_at(&[alpha1, alpha2], &[beta1, zero], u))
                    .unzip()
            }
            None => (s1, s2),
        };
        Ok(s1
            .iter()
            .zip(&s2)
            .map(|(w1, w2)| {
                // Wiscombe's amplitudes are the conjugates of BH's.
                let (a1, a2) = (w1.conj(), w2.conj());
                let [s11, s12, s33, s34] = four_s_from_s_pm(a1 + a2, a1 - a2);
                MatrixElements {
                    f11: s11 * norm,
                    f22: s11 * norm,
                    f33: s33 * norm,
                    f44: s33 * norm,
                    f12: s12 * norm,
                    f34: s34 * norm,
                }
            })
            .collect())
    }
}

/// 4 S11, 4 S12, 4 S33, 4 S34 of Bohren & Huffman (1983, eq. 4.77),
///
/// ```text
/// S11 = ½(|S2|² + |S1|²),  S12 = ½(|S2|² − |S1|²),  S33 = Re(S1 S2*),  S34 = Im(S2 S1*),
/// ```
///
/// from S± = S1 ± S2 of **their** amplitudes (the size integral forms S± by matrix products;
/// with Wiscombe's conjugate amplitudes S34 changes sign, the others do not). With
/// S1 = (S+ + S−)/2 and S2 = (S+ − S−)/2:
///
/// ```text
/// |S1|² + |S2|² = (|S+|² + |S−|²)/2                 → 4 S11 = |S+|² + |S−|²
/// |S2|² − |S1|² = −Re(S+ S−*)                       → 4 S12 = −2 Re(S+ S−*)
/// S1 S2* = (|S+|² − |S−|² − 2i Im(S+ S−*))/4         → 4 S33 = |S+|² − |S−|²
/// S2 S1* = (|S+|² − |S−|² + 2i Im(S+ S−*))/4         → 4 S34 = 2 Im(S+ S−*)
/// ```
///
/// (S+ S−* − S− S+* = 2i Im(S+ S−*) is imaginary, so it drops from the real parts.) The first
/// sum is written in the order the phase function has always been summed in, so that its
/// numbers do not change.
#[inline]
pub(crate) fn four_s_from_s_pm(sp: Complex64, sm: Complex64) -> [f64; 4] {
    let (p_re, p_im, m_re, m_im) = (sp.re, sp.im, sm.re, sm.im);
    let plus = p_re * p_re + p_im * p_im;
    let minus = m_re * m_re + m_im * m_im;
    [
        p_re * p_re + p_im * p_im + m_re * m_re + m_im * m_im,
        -2.0 * (p_re * m_re + p_im * m_im),
        plus - minus,
        2.0 * (p_im * m_re - p_re * m_im),
    ]
}

/// The scattering matrix of a sphere (normalised like its phase function) at the cosines `mu`:
/// see [`MieCoefficients::matrix`].
pub fn mie_matrix(m: Complex64, x: f64, mu: &[f64]) -> Result<Vec<MatrixElements>, MieError> {
    MieCoefficients::compute(m, x)?.matrix(mu)
}

/// Efficiencies, backscatter and asymmetry of a sphere: see [`MieCoefficients::efficiencies`].
///
/// `m`: refractive index relative to the medium, imaginary part ≥ 0 meaning absorption;
/// `x = 2πr/λ` in (0, [`MAX_SIZE_PARAMETER`]].
///
/// ```
/// use num_complex::Complex64;
/// let r = lidarsim::particles::mie::mie(Complex64::new(1.5, 1.0), 1.0).unwrap();
/// assert!((r.qext - 2.336321).abs() < 1e-6); // Wiscombe (1979), MIEV0 test case 14
/// ```
pub fn mie(m: Complex64, x: f64) -> Result<MieResult, MieError> {
    Ok(MieCoefficients::compute(m, x)?.efficiencies())
}

/// Amplitude functions `S1`, `S2` at the cosines `mu` (Wiscombe's normalisation and phase,
/// `Qext = 4 Re S1(1)/x²`): see [`MieCoefficients::amplitudes`].
pub fn mie_amplitudes(
    m: Complex64,
    x: f64,
    mu: &[f64],
) -> Result<(Vec<Complex64>, Vec<Complex64>), MieError> {
    MieCoefficients::compute(m, x)?.amplitudes(mu)
}

/// Parse a complex refractive index written `1.33`, `1.33+0i`, `1.5+1e-3i` or `1.5+0.001j`
/// (imaginary part ≥ 0 means absorption). The error message says what was expected.
pub fn parse_refractive_index(text: &str) -> Result<Complex64, String> {
    let t = text.trim();
    let bad = || {
        format!(
            "`{text}` is not a refractive index: write n or n+ki, e.g. 1.33, 1.33+0.0i, 1.5+1e-3i (k ≥ 0 means absorption)"
        )
    };
    let parse = |s: &str| -> Result<f64, String> {
        let v: f64 = s.trim().parse().map_err(|_| bad())?;
        if v.is_finite() { Ok(v) } else { Err(bad()) }
    };
    let m = if let Some(body) = t.strip_suffix(['i', 'j']) {
        // Split at the last sign that is not a leading sign or an exponent sign.
        let bytes = body.as_bytes();
        let split = (1..bytes.len())
            .rev()
            .find(|&i| {
                (bytes[i] == b'+' || bytes[i] == b'-') && !matches!(bytes[i - 1], b'e' | b'E')
            })
            .ok_or_else(bad)?;
        let re = parse(&body[..split])?;
        let im_text = &body[split..];
        let im = if im_text == "+" || im_text == "-" {
            return Err(bad());
        } else {
            parse(im_text)?
        };
        Complex64::new(re, im)
    } else {
        Complex64::new(parse(t)?, 0.0)
    };
    if m.im < 0.0 {
        return Err(format!(
            "`{text}`: the imaginary part must be ≥ 0 (lidarsim writes m = n + ik with k ≥ 0 for absorption; MIEV0/miepython write the same index as n − ik)"
        ));
    }
    // Each part against its range, so that the message names the part at fault.
    use crate::input::{Bounds, check_finite_range};
    check_finite_range(m.re, Bounds::positive(MAX_REFRACTIVE_INDEX_PART))
        .map_err(|e| format!("`{text}`: the real part {e}"))?;
    check_finite_range(m.im, Bounds::closed(0.0, MAX_REFRACTIVE_INDEX_PART))
        .map_err(|e| format!("`{text}`: the imaginary part {e}"))?;
    check_refractive_index(m).map_err(|e| format!("`{text}`: {e}"))?;
    Ok(m)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn c(re: f64, im: f64) -> Complex64 {
        Complex64::new(re, im)
    }

    #[test]
    fn lentz_matches_downward_recurrence_from_far_start() {
        // D_n(z) from a start far above n (D = 0 at n + 200) must agree with Lentz's value.
        for z in [c(1.5, 0.0), c(13.3, 0.01), c(100.0, 100.0), c(0.01, 0.0)] {
            let n = 30;
            let mut d = c(0.0, 0.0);
            for k in (n + 1..=n + 300).rev() {
                let kz = k as f64 / z;
                d = kz - 1.0 / (d + kz);
            }
            let l = lentz_dn(z, n);
            assert!((l - d).norm() <= 1e-12 * d.norm(), "{z}: {l} vs {d}");
        }
    }

    #[test]
    fn optical_theorem_and_lossless_identity() {
        // Qext from the sum equals 4 Re S1(0)/x² (optical theorem); for real m, Re a_n = |a_n|².
        for (m, x) in [
            (c(1.33, 0.0), 7.0),
            (c(1.5, 0.1), 30.0),
            (c(0.75, 0.0), 3.0),
        ] {
            let k = MieCoefficients::compute(m, x).unwrap();
            let r = k.efficiencies();
            let (s1, s2) = k.amplitudes(&[1.0, -1.0]).unwrap();
            assert!((4.0 * s1[0].re / (x * x) - r.qext).abs() < 1e-12 * r.qext);
            assert!((s1[0] - s2[0]).norm() < 1e-12 * s1[0].norm());
            assert!((4.0 * s1[1].norm_sqr() / (x * x) - r.qback).abs() < 1e-10 * r.qback);
            if m.im == 0.0 {
                for a in &k.a {
                    assert!((a.re - a.norm_sqr()).abs() < 1e-12);
                }
            }
        }
    }

    #[test]
    fn parses_refractive_indices() {
        assert_eq!(parse_refractive_index("1.33").unwrap(), c(1.33, 0.0));
        assert_eq!(parse_refractive_index("1.33+0.0i").unwrap(), c(1.33, 0.0));
        assert_eq!(parse_refractive_index("1.5+1e-3i").unwrap(), c(1.5, 1e-3));
        assert_eq!(
            parse_refractive_index("1.3205+1.28e-6i").unwrap(),
            c(1.3205, 1.28e-6)
        );
        assert_eq!(parse_refractive_index("1.5e0+2E-1j").unwrap(), c(1.5, 0.2));
        for bad in [
            "",
            "abc",
            "1.33+i",
            "1.33-0.1i",
            "0+0.1i",
            "1.33+0.1",
            "1..3",
        ] {
            assert!(parse_refractive_index(bad).is_err(), "{bad}");
        }
    }

    /// The Rayleigh limit (Bohren & Huffman 1983, §5.2): with K = (m²−1)/(m²+2),
    /// S1 = −i x³ K, S2 = −i x³ K cos θ in their convention (Wiscombe's are the conjugates),
    /// Qext = 4x Im K, Qsca = (8/3) x⁴ |K|², Qback = 4 x⁴ |K|², and the Rayleigh matrix
    /// F11 = ¾(1+μ²), F12 = −¾(1−μ²), F33 = 3μ/2, F34 = 0. At x = 10⁻²⁰⁰, x³ and x⁴ underflow:
    /// amplitudes, Qsca and Qback are a correct 0, Qext and the matrix stay finite.
    #[test]
    fn tiny_spheres_reach_the_rayleigh_limit() {
        for m in [c(1.33, 0.01), c(1.5, 0.0), c(3.0, 4.0)] {
            let k = (m * m - 1.0) / (m * m + 2.0);
            for x in [1e-6 * 0.999, 1e-9, 1e-200, 5e-324] {
                let coef = MieCoefficients::compute(m, x).unwrap();
                let mu = [1.0, 0.5, 0.0, -1.0];
                let (s1, s2) = coef.amplitudes(&mu).unwrap();
                let x3 = x * x * x;
                for (j, u) in mu.iter().enumerate() {
                    let want1 = (-Complex64::i() * x3 * k).conj();
                    let want2 = want1 * *u;
                    for (got, want) in [(s1[j], want1), (s2[j], want2)] {
                        assert!(got.re.is_finite() && got.im.is_finite(), "{m} {x}: {got}");
                        assert!(
                            (got - want).norm() <= 1e-9 * want1.norm(),
                            "{m} x={x} mu={u}: {got} vs {want}"
                        );
                    }
                }
                let e = coef.efficiencies();
                let x4 = x * x * x * x;
                let qsca = 8.0 / 3.0 * x4 * k.norm_sqr();
                let qext = if m.im > 0.0 { 4.0 * x * k.im } else { qsca };
                for (got, want, what) in [
                    (e.qext, qext, "qext"),
                    (e.qsca, qsca, "qsca"),
                    (e.qback, 4.0 * x4 * k.norm_sqr(), "qback"),
                ] {
                    assert!(
                        // (+1e-320: at x = 5e-324 Qext is a subnormal number, a few ulp.)
                        got.is_finite() && (got - want).abs() <= 1e-9 * want + 1e-320,
                        "{m} x={x} {what}: {got} vs {want}"
                    );
                }
                assert!(e.g.abs() <= 1e-9 && e.ssa.is_finite(), "{m} {x}: {e:?}");
                for (f, u) in coef.matrix(&mu).unwrap().iter().zip(mu) {
                    let want = [0.75 * (1.0 + u * u), -0.75 * (1.0 - u * u), 1.5 * u, 0.0];
                    for (got, want) in [f.f11, f.f12, f.f33, f.f34].iter().zip(want) {
                        assert!((got - want).abs() <= 1e-9, "{m} x={x} mu={u}: {f:?}");
                    }
                }
            }
        }
    }

    /// The small-particle expansions against the series where both hold (x = 10⁻⁴: the
    /// expansions' error is of order x², the series' ~10⁻¹² there), and for a lossless sphere's
    /// Qext = Qsca (the x⁶ term) at x = 10⁻², where the expansion is good to ~x² = 10⁻⁴.
    #[test]
    fn small_particle_expansions_match_the_series() {
        for m in [c(1.33, 0.01), c(1.5, 0.0), c(3.0, 4.0), c(0.75, 0.0)] {
            let x = 1e-4;
            let (series, small) = (
                MieCoefficients::compute(m, x).unwrap(),
                MieCoefficients::small(m, x),
            );
            assert!(series.small.is_none());
            let mu = [1.0, 0.3, -1.0];
            let (a1, a2) = series.amplitudes(&mu).unwrap();
            let (b1, b2) = small.amplitudes(&mu).unwrap();
            for j in 0..mu.len() {
                assert!((a1[j] - b1[j]).norm() <= 1e-7 * a1[0].norm(), "{m}");
                assert!((a2[j] - b2[j]).norm() <= 1e-7 * a1[0].norm(), "{m}");
            }
            let (es, ep) = (series.efficiencies(), small.efficiencies());
            for (p, q) in [(es.qext, ep.qext), (es.qsca, ep.qsca), (es.qback, ep.qback)] {
                assert!((p - q).abs() <= 1e-6 * p, "{m}: {es:?} vs {ep:?}");
            }
            if m.im == 0.0 {
                let x = 1e-2;
                let (es, ep) = (
                    MieCoefficients::compute(m, x).unwrap().efficiencies(),
                    MieCoefficients::small(m, x).efficiencies(),
                );
                assert!(
                    (es.qext - ep.qext).abs() <= 1e-3 * es.qext,
                    "{es:?} vs {ep:?}"
                );
            }
        }
    }

    #[test]
    fn rejects_bad_input() {
        assert!(mie(c(1.33, -0.1), 1.0).is_err());
        assert!(mie(c(0.0, 0.0), 1.0).is_err());
        assert!(mie(c(1.33, 0.0), 0.0).is_err());
        assert!(mie(c(1.33, 0.0), f64::NAN).is_err());
        assert!(mie(c(1.33, 0.0), 2e5).is_err());
        assert!(mie_amplitudes(c(1.33, 0.0), 1.0, &[1.5]).is_err());
    }
}
