//! Phase functions: evaluation toward the receiver and sampling of scattering angles.
//!
//! Conventions: `mu = cos Θ`, Θ the scattering angle between the incident and the scattered
//! direction (Θ = 0 forward, Θ = π backward). Every phase function is normalised to 4π over the
//! sphere, ∫ P dΩ = 2π ∫₋₁¹ P(μ) dμ = 4π, so an isotropic scatterer has P = 1 and the density of
//! scattered directions per steradian is P/(4π). Samplers take a uniform number `u ∈ [0, 1)`, not
//! an RNG, so tests can invert them; the azimuth is sampled by the caller.
//!
//! | variant | P(μ) | sampling |
//! |---|---|---|
//! | isotropic | 1 | μ = 2u − 1 |
//! | Rayleigh | 3/(4(1+2γ)) [(1+3γ) + (1−γ)μ²] | exact: the cubic CDF solved by Cardano |
//! | Henyey-Greenstein | (1−g²)/(1+g²−2gμ)^{3/2} | exact inverse CDF |
//! | double HG | f HG(g₁) + (1−f) HG(g₂) | pick a lobe, then exact |
//! | tabulated | linear in μ between nodes | inverse CDF (quadratic in a segment) with a guide table |

use thiserror::Error;

use super::table::PhaseTable;

/// A phase-function parameter outside its domain.
#[derive(Debug, Clone, PartialEq, Error)]
#[non_exhaustive]
pub enum PhaseError {
    /// Henyey-Greenstein asymmetry must satisfy |g| < 1 (g = ±1 is a delta function).
    #[error("asymmetry parameter g = {0} must satisfy -1 < g < 1")]
    Asymmetry(f64),
    /// A lobe weight outside [0, 1].
    #[error("lobe weight f = {0} must lie in [0, 1]")]
    LobeWeight(f64),
    /// Rayleigh depolarisation factor outside [0, 0.5).
    #[error("depolarisation factor rho_n = {0} must lie in [0, 0.5)")]
    Depolarisation(f64),
    /// A table that integrates to zero.
    #[error("the phase-function table has no positive values")]
    EmptyTable,
    /// Nodes that do not make a table: what is wrong with them.
    #[error("phase-function table: {0}")]
    Nodes(&'static str),
}

/// A phase function (normalised to 4π); see the module documentation.
#[derive(Debug, Clone, PartialEq)]
pub enum PhaseFunction {
    /// P = 1.
    Isotropic,
    /// Molecular (Rayleigh-Cabannes with depolarisation), see [`RayleighPhase`].
    Rayleigh(RayleighPhase),
    /// Henyey-Greenstein.
    HenyeyGreenstein(HenyeyGreenstein),
    /// Two Henyey-Greenstein lobes: `f` HG(`g1`) + (1 − `f`) HG(`g2`).
    DoubleHenyeyGreenstein {
        /// Weight of the first lobe, in [0, 1].
        f: f64,
        /// First lobe.
        hg1: HenyeyGreenstein,
        /// Second lobe.
        hg2: HenyeyGreenstein,
    },
    /// A table, linear in μ between nodes.
    Tabulated(Box<TabulatedPhase>),
}

impl PhaseFunction {
    /// Double Henyey-Greenstein with validated parameters.
    pub fn double_hg(f: f64, g1: f64, g2: f64) -> Result<Self, PhaseError> {
        if !(0.0..=1.0).contains(&f) {
            return Err(PhaseError::LobeWeight(f));
        }
        Ok(PhaseFunction::DoubleHenyeyGreenstein {
            f,
            hg1: HenyeyGreenstein::new(g1)?,
            hg2: HenyeyGreenstein::new(g2)?,
        })
    }

    /// P(μ), normalised to 4π over the sphere.
    #[inline]
    pub fn eval(&self, mu: f64) -> f64 {
        match self {
            PhaseFunction::Isotropic => 1.0,
            PhaseFunction::Rayleigh(r) => r.eval(mu),
            PhaseFunction::HenyeyGreenstein(hg) => hg.eval(mu),
            PhaseFunction::DoubleHenyeyGreenstein { f, hg1, hg2 } => {
                f * hg1.eval(mu) + (1.0 - f) * hg2.eval(mu)
            }
            PhaseFunction::Tabulated(t) => t.eval(mu),
        }
    }

    /// Sample μ = cos Θ from the phase function given a uniform `u ∈ [0, 1)`.
    #[inline]
    pub fn sample(&self, u: f64) -> f64 {
        match self {
            PhaseFunction::Isotropic => 2.0 * u - 1.0,
            PhaseFunction::Rayleigh(r) => r.sample(u),
            PhaseFunction::HenyeyGreenstein(hg) => hg.sample(u),
            PhaseFunction::DoubleHenyeyGreenstein { f, hg1, hg2 } => {
                // Reuse u: below f it is uniform on [0, f), above on [f, 1).
                if u < *f {
                    hg1.sample(u / f)
                } else {
                    hg2.sample((u - f) / (1.0 - f))
                }
            }
            PhaseFunction::Tabulated(t) => t.sample(u),
        }
    }

    /// Sample μ as [`Self::sample`] does, with P(μ) (for a table, a by-product of the
    /// inversion: no second search of its nodes).
    #[inline]
    pub fn sample_with_value(&self, u: f64) -> (f64, f64) {
        match self {
            PhaseFunction::Tabulated(t) => t.sample_with_value(u),
            _ => {
                let mu = self.sample(u);
                (mu, self.eval(mu))
            }
        }
    }

    /// Asymmetry parameter g = ⟨μ⟩ = ½ ∫ P μ dμ.
    pub fn asymmetry(&self) -> f64 {
        match self {
            PhaseFunction::Isotropic | PhaseFunction::Rayleigh(_) => 0.0,
            PhaseFunction::HenyeyGreenstein(hg) => hg.g,
            PhaseFunction::DoubleHenyeyGreenstein { f, hg1, hg2 } => f * hg1.g + (1.0 - f) * hg2.g,
            PhaseFunction::Tabulated(t) => t.asymmetry,
        }
    }

    /// P(180°), the value the single-scatter lidar equation needs.
    pub fn backscatter(&self) -> f64 {
        self.eval(-1.0)
    }

    /// The probabilities that a scattering angle's cosine lies below and above `c`:
    /// (F(μ), 1 − F(μ)), each computed without cancellation where it is small (F near
    /// μ = −1, 1 − F near μ = 1), so that the probability of a narrow cone about either pole is
    /// right to rounding however peaked the function.
    pub fn tails(&self, c: Cosine) -> (f64, f64) {
        match self {
            PhaseFunction::Isotropic => (0.5 * c.one_plus, 0.5 * c.one_minus),
            PhaseFunction::Rayleigh(r) => r.tails(c),
            PhaseFunction::HenyeyGreenstein(hg) => hg.tails(c),
            PhaseFunction::DoubleHenyeyGreenstein { f, hg1, hg2 } => {
                let (a1, b1) = hg1.tails(c);
                let (a2, b2) = hg2.tails(c);
                (f * a1 + (1.0 - f) * a2, f * b1 + (1.0 - f) * b2)
            }
            PhaseFunction::Tabulated(t) => t.tails(c),
        }
    }

    /// The mean of P over the scattering angles Θ ∈ [`theta_lo`, `theta_hi`] ⊂ [0, π] (the
    /// band of directions between the two cones about the incident direction), per unit solid
    /// angle: 2 [F(cos θ_lo) − F(cos θ_hi)]/(cos θ_lo − cos θ_hi). The receiver's aperture seen
    /// from close by spans such a band (`crate::aperture`); a band reaching a pole is the cap
    /// about it, whose mean is exact. With `theta_lo == theta_hi`, P there.
    pub fn band_mean(&self, theta_lo: f64, theta_hi: f64) -> f64 {
        let (lo, hi) = (Cosine::of_angle(theta_lo), Cosine::of_angle(theta_hi));
        // cos θ_lo − cos θ_hi = 2 sin((θ_lo + θ_hi)/2) sin((θ_hi − θ_lo)/2), without cancellation.
        let width = 2.0 * (0.5 * (theta_lo + theta_hi)).sin() * (0.5 * (theta_hi - theta_lo)).sin();
        if !(width > 0.0) {
            return self.eval(lo.mu);
        }
        // The band's probability, from the tails that are small where the band is.
        let mass = if lo.mu <= 0.0 {
            self.tails(lo).0 - self.tails(hi).0
        } else if hi.mu >= 0.0 {
            self.tails(hi).1 - self.tails(lo).1
        } else {
            1.0 - self.tails(hi).0 - self.tails(lo).1
        };
        2.0 * mass.max(0.0) / width
    }

    /// The largest relative curvature of P in the scattering angle, max |∂²P/∂Θ²|/P [rad⁻²]
    /// (for a table, from second differences over its nodes, values below 1e-3 counted as
    /// 1e-3): the mean of P over a cone of half-angle α differs from its value at the cone's
    /// axis by about κα²/4, so a point estimate toward a receiver that subtends α is right to
    /// a relative ε for α ≤ √(4ε/κ) (`crate::aperture`). Henyey-Greenstein:
    /// 3|g|/(1 − |g|)², at its peak; Rayleigh at most 2; isotropic 0.
    pub fn curvature(&self) -> f64 {
        match self {
            PhaseFunction::Isotropic => 0.0,
            PhaseFunction::Rayleigh(_) => 2.0,
            PhaseFunction::HenyeyGreenstein(hg) => hg.curvature(),
            PhaseFunction::DoubleHenyeyGreenstein { f, hg1, hg2 } => {
                // A lobe of zero weight adds nothing; otherwise the mixture's relative
                // curvature is at most the larger lobe's.
                let c1 = if *f > 0.0 { hg1.curvature() } else { 0.0 };
                let c2 = if *f < 1.0 { hg2.curvature() } else { 0.0 };
                c1.max(c2)
            }
            PhaseFunction::Tabulated(t) => t.curvature,
        }
    }
}

/// A cosine μ = cos Θ with 1 + μ and 1 − μ, each accurate to rounding even where it is tiny
/// (near the poles, where forming 1 ± μ from μ would lose every digit).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Cosine {
    /// cos Θ.
    pub mu: f64,
    /// 1 + cos Θ = 2 cos²(Θ/2).
    pub one_plus: f64,
    /// 1 − cos Θ = 2 sin²(Θ/2).
    pub one_minus: f64,
}

impl Cosine {
    /// The cosine of an angle Θ ∈ [0, π] \[rad\].
    pub fn of_angle(theta: f64) -> Self {
        let (s, c) = (0.5 * theta).sin_cos();
        Cosine {
            mu: theta.cos(),
            one_plus: 2.0 * c * c,
            one_minus: 2.0 * s * s,
        }
    }
}

/// Henyey-Greenstein phase function with asymmetry g (Henyey & Greenstein 1941, ApJ 93, 70).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HenyeyGreenstein {
    g: f64,
}

impl HenyeyGreenstein {
    /// A validated HG phase function: −1 < g < 1 (never clamped).
    pub fn new(g: f64) -> Result<Self, PhaseError> {
        if g.is_finite() && g.abs() < 1.0 {
            Ok(Self { g })
        } else {
            Err(PhaseError::Asymmetry(g))
        }
    }

    /// The asymmetry parameter.
    pub fn g(&self) -> f64 {
        self.g
    }

    /// P(μ) = (1 − g²)/(1 + g² − 2gμ)^{3/2}, written without cancellation as |g| → 1:
    /// 1 − g² = (1 − g)(1 + g) and 1 + g² − 2gμ = (1 − g)² + 2g(1 − μ) for g ≥ 0
    /// ((1 + g)² − 2g(1 + μ) for g < 0), sums of non-negative terms. Accurate to rounding for
    /// |g| up to 1 − 1e-12 (unit test `hg_at_extreme_asymmetry`, against 60-digit values),
    /// where P(1) ≈ 2e24.
    #[inline]
    pub fn eval(&self, mu: f64) -> f64 {
        let g = self.g;
        // A cosine from a dot product can round to just outside [−1, 1]; at |g| → 1 the
        // denominator's (1 ∓ g)² is then no larger than that rounding (1e-16 at g = 1 − 1e-8),
        // and the difference went negative: NaN in every run through such a layer.
        let mu = mu.clamp(-1.0, 1.0);
        let d = if g >= 0.0 {
            (1.0 - g) * (1.0 - g) + 2.0 * g * (1.0 - mu)
        } else {
            (1.0 + g) * (1.0 + g) - 2.0 * g * (1.0 + mu)
        };
        (1.0 - g) * (1.0 + g) / (d * d.sqrt())
    }

    /// (F(μ), 1 − F(μ)): F(μ) = (1 − g²)/(2g) [D^{−1/2} − 1/(1 + g)], D = 1 + g² − 2gμ,
    /// written without the division by g and without cancellation at either pole:
    /// F = (1 − g)(1 + μ)/(√D (1 + g + √D)) and 1 − F = (1 + g)(1 − μ)/(√D (1 − g + √D)),
    /// with D as in [`Self::eval`].
    pub fn tails(&self, c: Cosine) -> (f64, f64) {
        let g = self.g;
        let d = if g >= 0.0 {
            (1.0 - g) * (1.0 - g) + 2.0 * g * c.one_minus
        } else {
            (1.0 + g) * (1.0 + g) - 2.0 * g * c.one_plus
        };
        let r = d.sqrt();
        (
            (1.0 - g) * c.one_plus / (r * (1.0 + g + r)),
            (1.0 + g) * c.one_minus / (r * (1.0 - g + r)),
        )
    }

    /// Relative curvature at the peak: −∂² ln P/∂Θ² = 3|g|/(1 − |g|)² at Θ = 0 (g > 0) or
    /// π (g < 0), from P ∝ ((1 − |g|)² + |g|Θ²)^{−3/2} near it.
    pub fn curvature(&self) -> f64 {
        let a = self.g.abs();
        3.0 * a / ((1.0 - a) * (1.0 - a))
    }

    /// Exact inverse of the CDF in μ: μ = [1 + g² − s²]/(2g), s = (1 − g²)/(1 − g + 2gu),
    /// evaluated for g > 0 as μ = 1 − (1 − g)(1 − u)(s + 1 − g)/(1 − g + 2gu) (the same
    /// number, with no difference of nearly equal terms as g → 1), and for g < 0 through the
    /// symmetry μ_g(u) = −μ_{−g}(1 − u). μ is then right to the double's resolution for |g| up to
    /// 1 − 1e-12 (`hg_at_extreme_asymmetry`) and down to 0, where this form, unlike the first,
    /// divides by nothing small (`hg_sampling_is_exact_at_tiny_asymmetry`).
    #[inline]
    pub fn sample(&self, u: f64) -> f64 {
        let g = self.g;
        let (a, v) = if g > 0.0 { (g, u) } else { (-g, 1.0 - u) };
        let q = 1.0 - a + 2.0 * a * v;
        let s = (1.0 - a) * (1.0 + a) / q;
        let mu = 1.0 - (1.0 - a) * (1.0 - v) * (s + 1.0 - a) / q;
        (if g > 0.0 { mu } else { -mu }).clamp(-1.0, 1.0)
    }
}

/// Molecular phase function with depolarisation (Chandrasekhar 1950; Bucholtz 1995, Eq. 12):
/// P(μ) = 3/(4(1+2γ)) [(1+3γ) + (1−γ)μ²], γ = ρ_n/(2 − ρ_n).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RayleighPhase {
    gamma: f64,
}

impl RayleighPhase {
    /// From the depolarisation factor ρ_n (0 ≤ ρ_n < 0.5; air ≈ 0.027–0.045).
    pub fn from_depolarisation(rho_n: f64) -> Result<Self, PhaseError> {
        if !(0.0..0.5).contains(&rho_n) {
            return Err(PhaseError::Depolarisation(rho_n));
        }
        Ok(Self {
            gamma: rho_n / (2.0 - rho_n),
        })
    }

    /// γ = ρ_n/(2 − ρ_n).
    pub fn gamma(&self) -> f64 {
        self.gamma
    }

    /// P(μ).
    #[inline]
    pub fn eval(&self, mu: f64) -> f64 {
        let g = self.gamma;
        0.75 / (1.0 + 2.0 * g) * ((1.0 + 3.0 * g) + (1.0 - g) * mu * mu)
    }

    /// (F(μ), 1 − F(μ)): F(μ) = 3/(8(1+2γ)) (1 + μ) [(1+3γ) + (1−γ)(μ² − μ + 1)/3], and
    /// 1 − F(μ) = F(−μ) by symmetry.
    pub fn tails(&self, c: Cosine) -> (f64, f64) {
        let g = self.gamma;
        let k = 3.0 / (8.0 * (1.0 + 2.0 * g));
        let m2 = c.mu * c.mu;
        (
            k * c.one_plus * ((1.0 + 3.0 * g) + (1.0 - g) * (m2 - c.mu + 1.0) / 3.0),
            k * c.one_minus * ((1.0 + 3.0 * g) + (1.0 - g) * (m2 + c.mu + 1.0) / 3.0),
        )
    }

    /// Exact inverse CDF. F(μ) = 3/(8(1+2γ)) [(1+3γ)(μ+1) + (1−γ)(μ³+1)/3] = u is the depressed
    /// cubic μ³ + pμ + q = 0 with p = 3(1+3γ)/(1−γ) > 0, which has one real root (Cardano).
    #[inline]
    pub fn sample(&self, u: f64) -> f64 {
        let g = self.gamma;
        let p = 3.0 * (1.0 + 3.0 * g) / (1.0 - g);
        let c = (1.0 + 3.0 * g) + (1.0 - g) / 3.0 - 8.0 * (1.0 + 2.0 * g) * u / 3.0;
        let q = 3.0 * c / (1.0 - g);
        let d = (0.25 * q * q + p * p * p / 27.0).sqrt();
        // Take the cube root of the larger-magnitude term to avoid cancellation; the other root
        // term is −p/(3A) because their product is −p/3.
        let a = if q >= 0.0 {
            -(0.5 * q + d).cbrt()
        } else {
            (-0.5 * q + d).cbrt()
        };
        (a - p / (3.0 * a)).clamp(-1.0, 1.0)
    }
}

/// Number of cells of the sampling guide table (in u).
const SAMPLE_GUIDE_CELLS: usize = 8192;
const _: () = assert!(SAMPLE_GUIDE_CELLS.is_power_of_two());
/// The evaluation guide's cells (per hemisphere) in t = 1 − |μ|: 2^EVAL_GUIDE_BITS per binade
/// from 2^−EVAL_GUIDE_BINADES to 1, one cell below (t < 2^−40: Θ < 1.4e-6 rad from a pole) and
/// one above.
const EVAL_GUIDE_BITS: u32 = 7;
const EVAL_GUIDE_BINADES: u64 = 40;
const EVAL_GUIDE_CELLS: usize = ((EVAL_GUIDE_BINADES as usize) << EVAL_GUIDE_BITS) + 2;

/// The evaluation guide's cell of t = 1 − |μ| ∈ [0, 1], read off the bits of the double: its
/// exponent and top EVAL_GUIDE_BITS mantissa bits, so cells are equal in ln t (relative width
/// 2^−7 of t, 2^−8 of the angle near a pole, where t ≈ Θ²/2; at most 0.26° wide, between 60°
/// and 90° from the pole) without a square root.
#[inline]
fn eval_guide_cell(t: f64) -> usize {
    let below = ((1023 - EVAL_GUIDE_BINADES) << EVAL_GUIDE_BITS) - 1;
    let key = t.to_bits() >> (52 - EVAL_GUIDE_BITS);
    (key.saturating_sub(below) as usize).min(EVAL_GUIDE_CELLS - 1)
}

/// The least t of the evaluation guide's cell c (0 for cell 0).
fn eval_guide_cell_start(c: usize) -> f64 {
    if c == 0 {
        return 0.0;
    }
    let below = ((1023 - EVAL_GUIDE_BINADES) << EVAL_GUIDE_BITS) - 1;
    f64::from_bits((c as u64 + below) << (52 - EVAL_GUIDE_BITS))
}

/// Segment lookup on nodes μ_i (strictly increasing from −1 to 1) dense at both poles: cells
/// equal in ln(1 − μ) for μ ≥ 0 and in ln(1 + μ) for μ < 0, found from the bits of the double
/// ([`eval_guide_cell`]), each holding the segment at its edge farthest from the pole; then a
/// short walk toward the pole. O(1) on average, for tables resolved finely at the forward peak
/// and in the glory alike. (Cells equal in sin(Θ/2), as before 28 Nov 2026, cost a square root
/// per evaluation.)
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct SegmentGuide {
    /// Segment index per cell of t = 1 − μ (μ ≥ 0).
    fwd: Vec<u32>,
    /// Segment index per cell of t = 1 + μ (μ < 0).
    bwd: Vec<u32>,
}

impl SegmentGuide {
    /// For the nodes `mu` (at least two).
    pub(crate) fn new(mu: &[f64]) -> Self {
        let n = mu.len();
        let segment_of = |m: f64| -> usize {
            // Largest i with mu[i] <= m, capped to the last segment.
            let i = mu.partition_point(|&x| x <= m);
            i.saturating_sub(1).min(n - 2)
        };
        // Each cell's least μ: forward, at its largest t (the next cell's start); backward, at
        // its least t.
        let fwd = (0..EVAL_GUIDE_CELLS)
            .map(|c| segment_of(1.0 - eval_guide_cell_start(c + 1)) as u32)
            .collect();
        let bwd = (0..EVAL_GUIDE_CELLS)
            .map(|c| segment_of(eval_guide_cell_start(c) - 1.0) as u32)
            .collect();
        SegmentGuide { fwd, bwd }
    }

    /// The guide's first guess for μ: the segment holding the least μ of μ's cell.
    #[inline]
    fn start(&self, mu: f64) -> usize {
        if mu >= 0.0 {
            self.fwd[eval_guide_cell(1.0 - mu)] as usize
        } else {
            self.bwd[eval_guide_cell(1.0 + mu)] as usize
        }
    }

    /// The segment i of `mu` (the nodes it was built for) with μ_i ≤ μ ≤ μ_{i+1}.
    #[inline]
    pub(crate) fn segment(&self, mu_nodes: &[f64], mu: f64) -> usize {
        let last = mu_nodes.len() - 2;
        let mut i = self.start(mu);
        // Rounding in t can start one segment high; step back, then walk up.
        while i > 0 && mu_nodes[i] > mu {
            i -= 1;
        }
        while i < last && mu_nodes[i + 1] < mu {
            i += 1;
        }
        i
    }
}

/// A tabulated phase function, linear in μ between nodes, normalised to exactly 4π.
///
/// Sampling inverts the exact CDF of that piecewise-linear function (a quadratic in each
/// segment), so sampled angles follow exactly the function that [`TabulatedPhase::eval`] returns.
/// Two guide tables make both O(1) on average:
/// * sampling: cells equal in probability map u to the first segment that can hold it, so the
///   forward peak, which holds most of the probability, is spread over many cells;
/// * evaluation: cells equal in ln(1 − μ) for the forward hemisphere and in ln(1 + μ) for the
///   backward one, narrowest at their pole, so the densely tabulated forward peak and the
///   backscatter (glory) region are resolved as finely as the table itself.
#[derive(Debug, Clone, PartialEq)]
pub struct TabulatedPhase {
    /// Nodes μ_i, strictly increasing from −1 to 1.
    mu: Vec<f64>,
    /// P(μ_i), normalised so that ½ ∫ P dμ = 1.
    p: Vec<f64>,
    /// Slope of P in each segment.
    slope: Vec<f64>,
    /// CDF at nodes, cdf[0] = 0, cdf[n-1] = 1.
    cdf: Vec<f64>,
    /// 1 − CDF at nodes, summed from the forward end (accurate where it is small).
    ccdf: Vec<f64>,
    sample_guide: Vec<u32>,
    /// Segment lookup for evaluation.
    guide: SegmentGuide,
    asymmetry: f64,
    /// [`PhaseFunction::curvature`].
    curvature: f64,
}

impl TabulatedPhase {
    /// From nodes in angle (degrees, increasing from 0 to 180) and values; the values are
    /// rescaled so the function integrates to exactly 4π (linear in μ between nodes).
    pub fn from_angles(theta_deg: &[f64], phase: &[f64]) -> Result<Self, PhaseError> {
        Ok(Self::from_angles_scaled(theta_deg, phase)?.0)
    }

    /// [`Self::from_angles`], with the factor by which the values were multiplied to integrate
    /// to exactly 4π (a scattering-matrix table rescales its other elements by the same factor).
    pub(crate) fn from_angles_scaled(
        theta_deg: &[f64],
        phase: &[f64],
    ) -> Result<(Self, f64), PhaseError> {
        // What a file's reader checks (particles::table) holds here too, for tables built in code.
        let bad = if theta_deg.len() != phase.len() {
            Some("as many values as angles are needed")
        } else if theta_deg.len() < 2 {
            Some("at least two angles (0 and 180) are needed")
        } else if theta_deg[0] != 0.0 || theta_deg[theta_deg.len() - 1] != 180.0 {
            Some("the angles must run from exactly 0 to exactly 180 degrees")
        } else if theta_deg.windows(2).any(|w| !(w[1] > w[0])) {
            Some("the angles must strictly increase")
        } else if phase.iter().any(|v| !(v.is_finite() && *v >= 0.0)) {
            Some("the values must be finite and non-negative")
        } else {
            None
        };
        if let Some(why) = bad {
            return Err(PhaseError::Nodes(why));
        }
        let p: Vec<f64> = phase.iter().rev().copied().collect();
        Self::from_mu(mu_nodes(theta_deg), p)
    }

    /// From a validated [`PhaseTable`].
    pub fn from_table(table: &PhaseTable) -> Result<Self, PhaseError> {
        Self::from_angles(&table.theta_deg, &table.phase_4pi)
    }

    fn from_mu(mu: Vec<f64>, mut p: Vec<f64>) -> Result<(Self, f64), PhaseError> {
        let n = mu.len();
        // ∫ P dμ by the trapezoid rule, exact for P linear in μ.
        let mut cdf = vec![0.0; n];
        for i in 1..n {
            cdf[i] = cdf[i - 1] + 0.5 * (p[i - 1] + p[i]) * (mu[i] - mu[i - 1]);
        }
        let total = cdf[n - 1];
        if !(total > 0.0) {
            return Err(PhaseError::EmptyTable);
        }
        let scale = 2.0 / total;
        p.iter_mut().for_each(|v| *v *= scale);
        cdf.iter_mut().for_each(|v| *v /= total);
        cdf[n - 1] = 1.0;
        let slope: Vec<f64> = (0..n - 1)
            .map(|i| (p[i + 1] - p[i]) / (mu[i + 1] - mu[i]))
            .collect();
        // Probability of each segment, summed from the forward end for 1 − CDF.
        let mut ccdf = vec![0.0; n];
        for i in (0..n - 1).rev() {
            ccdf[i] = ccdf[i + 1] + 0.25 * (p[i] + p[i + 1]) * (mu[i + 1] - mu[i]);
        }
        let curvature = table_curvature(&mu, &p, &slope);

        // ⟨μ⟩ = ½ ∫ P μ dμ, exact for P linear in μ: ∫ (a + b t)(μ_i + t) dt over [0, h].
        let mut asymmetry = 0.0;
        for i in 0..n - 1 {
            let h = mu[i + 1] - mu[i];
            let (a, b) = (p[i], slope[i]);
            asymmetry += a * mu[i] * h + (a + b * mu[i]) * h * h / 2.0 + b * h * h * h / 3.0;
        }
        asymmetry *= 0.5;

        // Sampling guide: cell c covers u ∈ [c/G, (c+1)/G); store the segment holding c/G.
        let mut sample_guide = Vec::with_capacity(SAMPLE_GUIDE_CELLS + 1);
        let mut seg = 0usize;
        for c in 0..=SAMPLE_GUIDE_CELLS {
            let u = c as f64 / SAMPLE_GUIDE_CELLS as f64;
            while seg < n - 2 && cdf[seg + 1] <= u {
                seg += 1;
            }
            sample_guide.push(seg as u32);
        }

        let guide = SegmentGuide::new(&mu);

        Ok((
            TabulatedPhase {
                mu,
                p,
                slope,
                cdf,
                ccdf,
                sample_guide,
                guide,
                asymmetry,
                curvature,
            },
            scale,
        ))
    }

    /// Number of nodes.
    pub fn len(&self) -> usize {
        self.mu.len()
    }

    /// True for a table without nodes (never, after construction).
    pub fn is_empty(&self) -> bool {
        self.mu.is_empty()
    }

    /// Asymmetry parameter.
    pub fn asymmetry(&self) -> f64 {
        self.asymmetry
    }

    /// The nodes μ_i (increasing from −1 to 1) and P(μ_i). P is linear in μ between them, so its
    /// largest value over an interval lies at an end or at a node inside
    /// (`lidar_eq::multiple_scattering_bound`).
    pub fn nodes(&self) -> (&[f64], &[f64]) {
        (&self.mu, &self.p)
    }

    /// The segment i with μ_i ≤ μ ≤ μ_{i+1}.
    #[inline]
    fn segment(&self, mu: f64) -> usize {
        self.guide.segment(&self.mu, mu)
    }

    /// P(μ), linear in μ between nodes.
    #[inline]
    pub fn eval(&self, mu: f64) -> f64 {
        let mu = mu.clamp(-1.0, 1.0);
        let i = self.segment(mu);
        self.p[i] + self.slope[i] * (mu - self.mu[i])
    }

    /// (F(μ), 1 − F(μ)) of the piecewise-linear function: within segment i, F = cdf_i +
    /// (p_i t + s_i t²/2)/2 with t = μ − μ_i, and 1 − F = ccdf_{i+1} + (p_{i+1} v − s_i v²/2)/2
    /// with v = μ_{i+1} − μ (P integrates to 2 over μ). In the first and last segments t and v
    /// come from 1 + μ and 1 − μ, exact near the poles.
    pub fn tails(&self, c: Cosine) -> (f64, f64) {
        let n = self.mu.len();
        let i = self.segment(c.mu.clamp(-1.0, 1.0));
        let t = if i == 0 {
            c.one_plus
        } else {
            c.mu - self.mu[i]
        }
        .max(0.0);
        let v = if i == n - 2 {
            c.one_minus
        } else {
            self.mu[i + 1] - c.mu
        }
        .max(0.0);
        let s = self.slope[i];
        (
            self.cdf[i] + 0.5 * (self.p[i] * t + 0.5 * s * t * t),
            self.ccdf[i + 1] + 0.5 * (self.p[i + 1] * v - 0.5 * s * v * v),
        )
    }

    /// Sample μ by inverting the CDF.
    #[inline]
    pub fn sample(&self, u: f64) -> f64 {
        self.sample_with_value(u).0
    }

    /// Sample μ by inverting the CDF, with P(μ) from the segment the inversion found.
    #[inline]
    pub fn sample_with_value(&self, u: f64) -> (f64, f64) {
        let cell = ((u * SAMPLE_GUIDE_CELLS as f64) as usize).min(SAMPLE_GUIDE_CELLS);
        // The cell's entry holds its start c/G, and c/G ≤ u exactly (G a power of two: u·G and
        // c/G are exact), so the segment is never below it: walk up only.
        let mut i = self.sample_guide[cell] as usize;
        let last = self.mu.len() - 2;
        while i < last && self.cdf[i + 1] <= u {
            i += 1;
        }
        // Within segment i solve ½ b t² + a t = A for t = μ − μ_i, with A the probability mass
        // still needed, times 2 (P integrates to 2 over μ). The stable root is 2A/(a + √(a²+2bA)).
        let area = 2.0 * (u - self.cdf[i]).max(0.0);
        let a = self.p[i];
        let b = self.slope[i];
        let disc = (a * a + 2.0 * b * area).max(0.0);
        let denom = a + disc.sqrt();
        let h = self.mu[i + 1] - self.mu[i];
        let t = if denom > 0.0 {
            (2.0 * area / denom).min(h)
        } else {
            0.0
        };
        ((self.mu[i] + t).clamp(-1.0, 1.0), a + b * t)
    }
}

/// [`PhaseFunction::curvature`] of a table P linear in μ between nodes μ_i (increasing from
/// −1 to 1) with values p_i and slopes s_i: the largest of the second divided differences in
/// angle over three neighbouring nodes (the pole nodes mirrored: P is even about each pole)
/// and the curvature of each segment itself, |s_i cos Θ| (P = p_i + s_i (cos Θ − μ_i)), each
/// relative to the smallest value it involves (at least 1e-3, so that zeros do not make every
/// table "unresolved"). A peak narrower than the nodes' spacing still shows: it is one node far
/// above its neighbours.
fn table_curvature(mu: &[f64], p: &[f64], slope: &[f64]) -> f64 {
    const FLOOR: f64 = 1e-3;
    let n = mu.len();
    // Angles from 1 ∓ μ near the poles (acos loses them there).
    let theta: Vec<f64> = mu
        .iter()
        .map(|&m| {
            if m >= 0.0 {
                2.0 * (0.5 * (1.0 - m)).sqrt().asin()
            } else {
                std::f64::consts::PI - 2.0 * (0.5 * (1.0 + m)).sqrt().asin()
            }
        })
        .collect();
    let mut kappa = 0.0f64;
    for i in 0..n - 1 {
        let low = p[i].min(p[i + 1]).max(FLOOR);
        let c = mu[i].abs().max(mu[i + 1].abs());
        kappa = kappa.max(slope[i].abs() * c / low);
    }
    for i in 0..n {
        // Neighbours in angle: θ decreases with i (μ increases).
        let (a, b) = match (i.checked_sub(1), (i + 1 < n).then_some(i + 1)) {
            (Some(a), Some(b)) => (a, b),
            (None, Some(b)) => (b, b),
            (Some(a), None) => (a, a),
            (None, None) => continue,
        };
        let (h1, h2) = ((theta[a] - theta[i]).abs(), (theta[i] - theta[b]).abs());
        if !(h1 > 0.0 && h2 > 0.0) {
            continue;
        }
        let d2 = 2.0 * ((p[b] - p[i]) / h2 - (p[i] - p[a]) / h1) / (h1 + h2);
        let low = p[i].min(p[a]).min(p[b]).max(FLOOR);
        kappa = kappa.max(d2.abs() / low);
    }
    kappa
}

/// The nodes μ = cos θ of a table given at angles `theta_deg` (increasing from 0 to 180), in
/// increasing order (reversed), with 0° and 180° mapped to exactly 1 and −1.
pub(crate) fn mu_nodes(theta_deg: &[f64]) -> Vec<f64> {
    theta_deg
        .iter()
        .rev()
        .map(|t| {
            if *t == 180.0 {
                -1.0
            } else if *t == 0.0 {
                1.0
            } else {
                t.to_radians().cos()
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt, SeedableRng};
    use rand_xoshiro::Xoshiro256PlusPlus;

    /// ½ ∫ f(μ) dμ by composite Simpson on many points (independent of the code's quadrature).
    fn half_integral(f: impl Fn(f64) -> f64, n: usize) -> f64 {
        let h = 2.0 / n as f64;
        let mut s = f(-1.0) + f(1.0);
        for i in 1..n {
            let x = -1.0 + i as f64 * h;
            s += if i % 2 == 1 { 4.0 } else { 2.0 } * f(x);
        }
        0.5 * s * h / 3.0
    }

    fn all_analytic() -> Vec<(&'static str, PhaseFunction)> {
        vec![
            ("isotropic", PhaseFunction::Isotropic),
            (
                "rayleigh",
                PhaseFunction::Rayleigh(RayleighPhase::from_depolarisation(0.0279).unwrap()),
            ),
            (
                "hg 0.85",
                PhaseFunction::HenyeyGreenstein(HenyeyGreenstein::new(0.85).unwrap()),
            ),
            (
                "hg -0.5",
                PhaseFunction::HenyeyGreenstein(HenyeyGreenstein::new(-0.5).unwrap()),
            ),
            ("dhg", PhaseFunction::double_hg(0.9, 0.8, -0.4).unwrap()),
        ]
    }

    #[test]
    fn analytic_phase_functions_are_normalised_with_the_stated_g() {
        for (name, pf) in all_analytic() {
            let norm = half_integral(|m| pf.eval(m), 200_000);
            assert!((norm - 1.0).abs() < 1e-6, "{name}: {norm}");
            let g = half_integral(|m| m * pf.eval(m), 200_000);
            assert!(
                (g - pf.asymmetry()).abs() < 1e-6,
                "{name}: {g} vs {}",
                pf.asymmetry()
            );
            // The public accessor of a lobe's parameter is that mean cosine too.
            if let PhaseFunction::HenyeyGreenstein(hg) = &pf {
                assert!((g - hg.g()).abs() < 1e-6, "{name}: {g} vs g() = {}", hg.g());
            }
        }
    }

    #[test]
    fn rayleigh_backscatter_matches_bucholtz() {
        // P(180°) = 3(1+γ)/(2(1+2γ)), and γ is the molecular linear depolarisation ratio of
        // the backscatter (shared/data/rayleigh: P180 and delta_mol at 355, 532, 1064 nm).
        for (rho_n, p180, delta_mol) in [
            (0.0301, 1.47776, 0.01528),
            (0.02842, 1.47898, 0.0144148),
            (0.0273, 1.4798, 0.0138389),
        ] {
            let r = RayleighPhase::from_depolarisation(rho_n).unwrap();
            assert!(
                (r.eval(-1.0) - p180).abs() < 1e-5,
                "ρ_n {rho_n}: {}",
                r.eval(-1.0)
            );
            assert!(
                (r.gamma() - delta_mol).abs() < 1e-6,
                "ρ_n {rho_n}: {}",
                r.gamma()
            );
        }
    }

    #[test]
    fn hg_sampling_is_exact_at_tiny_asymmetry() {
        // For |g| ≤ 1e-6, P = 1 + 3gμ + O(g²) and the CDF is F(μ) = (μ + 1)/2 + 3g(μ² − 1)/4
        // to 1e-12: the sample must invert it to that level, not fall back to isotropy (which
        // is off by 3g(1 − μ²)/4, up to 3.8e-7 at g = 5e-7).
        for g in [5e-7, -5e-7, 1e-9, -1e-12, 0.0] {
            let hg = HenyeyGreenstein::new(g).unwrap();
            for i in 0..=20 {
                let u = i as f64 / 20.0;
                let mu = hg.sample(u);
                let f = 0.5 * (mu + 1.0) + 0.75 * g * (mu * mu - 1.0);
                assert!((f - u).abs() < 1e-12, "g {g}, u {u}: F(μ) = {f}");
            }
        }
    }

    #[test]
    fn samplers_invert_their_cdf() {
        // F(sample(u)) = u, with F by independent numerical integration of eval. (Double HG
        // picks a lobe first, so it is not an inverse CDF; the chi-square tests cover it.)
        for (name, pf) in all_analytic().into_iter().filter(|(n, _)| *n != "dhg") {
            for &u in &[0.001, 0.1, 0.37, 0.5, 0.8, 0.999] {
                let mu = pf.sample(u);
                let n = 20_000;
                let h = (mu + 1.0) / n as f64;
                let mut f = 0.5 * (pf.eval(-1.0) + pf.eval(mu));
                for i in 1..n {
                    f += pf.eval(-1.0 + i as f64 * h);
                }
                let cdf = 0.5 * f * h;
                assert!((cdf - u).abs() < 1e-5, "{name}: F(sample({u})) = {cdf}");
            }
        }
    }

    #[test]
    fn tabulated_reproduces_its_nodes_and_hg() {
        // Tabulate HG(0.7) on a fine angular grid; the table must evaluate back to HG and
        // integrate (after its own normalisation) to the HG's g.
        let hg = HenyeyGreenstein::new(0.7).unwrap();
        let theta: Vec<f64> = (0..=3600).map(|i| i as f64 * 0.05).collect();
        let p: Vec<f64> = theta
            .iter()
            .map(|t| hg.eval(t.to_radians().cos()))
            .collect();
        let tab = TabulatedPhase::from_angles(&theta, &p).unwrap();
        for (t, pv) in theta.iter().zip(&p).step_by(37) {
            let e = tab.eval(t.to_radians().cos());
            assert!((e - pv).abs() < 1e-4 * pv, "θ={t}: {e} vs {pv}");
        }
        assert!((tab.asymmetry() - 0.7).abs() < 1e-5, "{}", tab.asymmetry());
        let norm = half_integral(|m| tab.eval(m), 400_000);
        assert!((norm - 1.0).abs() < 1e-6, "{norm}");
    }

    #[test]
    fn tabulated_asymmetry_is_exact_for_a_linear_phase_function() {
        // P(μ) = 1 + 3gμ is linear, so a table of it on any nodes is the function itself, and
        // its mean cosine ½∫Pμ dμ is g exactly (to rounding). Uneven nodes, so that every term
        // of the per-segment integral counts.
        let g = 0.3;
        let theta = [0.0, 10.0, 35.0, 60.0, 90.0, 125.0, 150.0, 171.0, 180.0];
        let p: Vec<f64> = theta
            .iter()
            .map(|t: &f64| 1.0 + 3.0 * g * t.to_radians().cos())
            .collect();
        let tab = TabulatedPhase::from_angles(&theta, &p).unwrap();
        assert!((tab.asymmetry() - g).abs() < 1e-15, "{}", tab.asymmetry());
        for mu in [-1.0, -0.3, 0.0, 0.55, 1.0] {
            let e = tab.eval(mu);
            assert!((e - (1.0 + 3.0 * g * mu)).abs() < 1e-15, "μ = {mu}: {e}");
        }
    }

    #[test]
    fn evaluation_guide_cells_start_where_documented() {
        // 128 cells per binade of t from 2^−40 to 1: cell 1 + 128k + m starts at
        // t = 2^(k−40)(1 + m/128), exactly; below 2^−40 is cell 0, and t = 1 the last cell.
        assert_eq!(eval_guide_cell(0.0), 0);
        assert_eq!(eval_guide_cell_start(0), 0.0);
        for k in 0..EVAL_GUIDE_BINADES as i32 {
            for m in 0..128 {
                let c = 1 + 128 * k as usize + m;
                let t = 2f64.powi(k - 40) * (1.0 + m as f64 / 128.0);
                let below_t = f64::from_bits(t.to_bits() - 1);
                assert_eq!(eval_guide_cell(t), c, "t = {t:e}");
                assert_eq!(eval_guide_cell(below_t), c - 1, "t = {below_t:e}");
                assert_eq!(eval_guide_cell_start(c), t, "cell {c}");
            }
        }
        assert_eq!(eval_guide_cell(1.0), EVAL_GUIDE_CELLS - 1);
        assert_eq!(eval_guide_cell_start(EVAL_GUIDE_CELLS - 1), 1.0);
    }

    #[test]
    fn dense_evaluator_reproduces_every_node_of_the_c1_table() {
        // The evaluator must resolve the forward peak and the glory at 180° (nodes 0.01° apart)
        // exactly as tabulated: every node, after the normalisation to exactly 4π.
        let t = crate::particles::builtin_table("bissonnette_c1_1064nm").unwrap();
        let tab = TabulatedPhase::from_table(&t).unwrap();
        let scale = 1.0 / t.normalisation();
        for (th, p) in t.theta_deg.iter().zip(&t.phase_4pi) {
            let mu = if *th == 180.0 {
                -1.0
            } else {
                th.to_radians().cos()
            };
            let e = tab.eval(mu);
            assert!(
                (e / (p * scale) - 1.0).abs() < 1e-9,
                "θ = {th}: {e} vs {}",
                p * scale
            );
        }
        assert!((tab.eval(-1.0) - 0.64154 * scale).abs() < 1e-4);
    }

    #[test]
    fn sampling_guide_holds_the_segment_of_each_cells_start() {
        // Cell c of the sampling guide starts at u = c/G; its entry must be the segment whose
        // CDF interval holds that u (found here by bisection), so that the walk from it is
        // short. A wrong entry would still sample right, only slowly: this is what sees it.
        let t = crate::particles::builtin_table("bissonnette_c1_1064nm").unwrap();
        let tab = TabulatedPhase::from_table(&t).unwrap();
        let last = tab.mu.len() - 2;
        assert_eq!(tab.sample_guide.len(), SAMPLE_GUIDE_CELLS + 1);
        for (c, &guess) in tab.sample_guide.iter().enumerate() {
            let u = c as f64 / SAMPLE_GUIDE_CELLS as f64;
            let answer = (tab.cdf.partition_point(|&x| x <= u) - 1).min(last);
            assert_eq!(guess as usize, answer, "cell {c}, u = {u}");
        }
    }

    #[test]
    fn evaluation_guide_starts_within_a_few_segments_of_the_answer() {
        // What makes `eval` O(1): 128 cells per binade of t = 1 − |μ| are at most 2^−8 of the
        // angle wide near a pole (t ≈ Θ²/2) and 0.26° between 60° and 90° from it
        // (dΘ = dt/sin Θ, dt = 1/256), and the C.1 table's nodes are 0.01° apart up to 1°
        // (where a cell is 0.004° wide) and 0.25° apart beyond 60°, so a cell holds at most 3
        // nodes: the guess is at most 3 segments below the answer, or 1 above it by rounding.
        let t = crate::particles::builtin_table("bissonnette_c1_1064nm").unwrap();
        let tab = TabulatedPhase::from_table(&t).unwrap();
        let n = 200_000;
        for j in 0..=n {
            let mu = -1.0 + 2.0 * j as f64 / n as f64;
            let answer = tab
                .mu
                .partition_point(|&x| x <= mu)
                .saturating_sub(1)
                .min(tab.mu.len() - 2);
            assert_eq!(tab.segment(mu), answer, "μ = {mu}");
            let start = tab.guide.start(mu);
            assert!(
                start <= answer + 1 && answer <= start + 3,
                "μ = {mu}: guess {start}, answer {answer}"
            );
        }
    }

    #[test]
    fn tabulated_sampling_inverts_the_cdf_exactly() {
        let hg = HenyeyGreenstein::new(0.9).unwrap();
        let theta: Vec<f64> = (0..=1800).map(|i| i as f64 * 0.1).collect();
        let p: Vec<f64> = theta
            .iter()
            .map(|t| hg.eval(t.to_radians().cos()))
            .collect();
        let tab = TabulatedPhase::from_angles(&theta, &p).unwrap();
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(3);
        for _ in 0..2000 {
            let u: f64 = rng.random();
            let mu = tab.sample(u);
            // CDF at mu: sum of whole segments plus the partial one, from the nodes.
            let i = tab.segment(mu);
            let t = mu - tab.mu[i];
            let cdf = tab.cdf[i] + 0.5 * (tab.p[i] * t + 0.5 * tab.slope[i] * t * t);
            assert!((cdf - u).abs() < 1e-12, "u={u}: {cdf}");
            // The value that comes with the sample is the table's own P(μ) there.
            let (mu2, p_mu) = tab.sample_with_value(u);
            assert_eq!(mu2, mu);
            let p_eval = tab.eval(mu);
            assert!(
                (p_mu - p_eval).abs() <= 1e-12 * p_eval,
                "u={u}: {p_mu} vs {p_eval}"
            );
        }
    }

    #[test]
    fn constructors_reject_out_of_domain_parameters() {
        assert_eq!(HenyeyGreenstein::new(1.0), Err(PhaseError::Asymmetry(1.0)));
        assert!(HenyeyGreenstein::new(f64::NAN).is_err());
        assert_eq!(
            PhaseFunction::double_hg(1.5, 0.5, 0.1),
            Err(PhaseError::LobeWeight(1.5))
        );
        assert!(RayleighPhase::from_depolarisation(0.6).is_err());
        assert_eq!(
            TabulatedPhase::from_angles(&[0.0, 180.0], &[0.0, 0.0]),
            Err(PhaseError::EmptyTable)
        );
        // Nodes that make no table are refused, not a panic or a silent table.
        let bad: [(&[f64], &[f64]); 7] = [
            (&[], &[]),
            (&[0.0], &[1.0]),
            (&[0.0, 180.0], &[1.0]),
            (&[0.0, 90.0], &[1.0, 1.0]),
            (&[0.0, 120.0, 60.0, 180.0], &[1.0; 4]),
            (&[0.0, 90.0, 90.0, 180.0], &[1.0; 4]),
            (&[0.0, 90.0, 180.0], &[1.0, f64::NAN, 1.0]),
        ];
        for (theta, p) in bad {
            assert!(
                matches!(
                    TabulatedPhase::from_angles(theta, p),
                    Err(PhaseError::Nodes(_))
                ),
                "{theta:?} {p:?}"
            );
        }
        assert!(TabulatedPhase::from_angles(&[0.0, 90.0, 180.0], &[2.0, -1.0, 1.0]).is_err());
        assert!(TabulatedPhase::from_angles(&[1.0, 180.0], &[1.0, 1.0]).is_err());
    }

    /// The tails of HG's CDF near both poles at |g| up to 1 − 1e-12, against 60-digit values:
    /// each tail to 1e-10 relative where it is below ½ (the side computed without
    /// cancellation), to 1e-15 absolute where it is near 1.
    #[test]
    fn hg_tails_at_extreme_asymmetry() {
        for (g, theta, below, above) in HG_TAILS {
            let (f, q) = HenyeyGreenstein::new(g)
                .unwrap()
                .tails(Cosine::of_angle(theta));
            for (got, want, side) in [(f, below, "F"), (q, above, "1 − F")] {
                let ok = if want < 0.5 {
                    (got / want - 1.0).abs() < 1e-10
                } else {
                    (got - want).abs() < 1e-15
                };
                assert!(ok, "g {g} θ {theta}: {side} = {got:e}, want {want:e}");
            }
        }
    }

    /// Every phase function's tails are its CDF in μ (the closed forms and the table's own
    /// piecewise integral, written here) and its complement: F + (1 − F) = 1.
    #[test]
    fn tails_are_the_cdf_and_its_complement() {
        let c1 = crate::particles::builtin_table("bissonnette_c1_1064nm").unwrap();
        let table = PhaseFunction::Tabulated(Box::new(TabulatedPhase::from_table(&c1).unwrap()));
        let c1_cdf = table_cdf(&c1);
        type Cdf<'a> = Box<dyn Fn(f64) -> f64 + 'a>;
        let mut cases: Vec<(&str, PhaseFunction, Cdf<'_>)> = vec![
            (
                "isotropic",
                PhaseFunction::Isotropic,
                Box::new(|m: f64| 0.5 * (m + 1.0)),
            ),
            (
                "rayleigh",
                PhaseFunction::Rayleigh(RayleighPhase::from_depolarisation(0.0279).unwrap()),
                Box::new(|m| rayleigh_cdf(0.0279 / (2.0 - 0.0279), m)),
            ),
            (
                "hg 0.85",
                PhaseFunction::HenyeyGreenstein(HenyeyGreenstein::new(0.85).unwrap()),
                Box::new(|m| hg_cdf(0.85, m)),
            ),
            (
                "dhg",
                PhaseFunction::double_hg(0.9, 0.8, -0.4).unwrap(),
                Box::new(|m| 0.9 * hg_cdf(0.8, m) + 0.1 * hg_cdf(-0.4, m)),
            ),
        ];
        cases.push(("c1 table", table, Box::new(c1_cdf)));
        for (name, p, cdf) in &cases {
            for i in 0..=400 {
                let theta = std::f64::consts::PI * i as f64 / 400.0;
                let c = Cosine::of_angle(theta);
                let (f, q) = p.tails(c);
                let want = cdf(c.mu);
                assert!(
                    (f - want).abs() < 1e-12,
                    "{name} θ {theta}: F {f} vs {want}"
                );
                assert!(
                    (f + q - 1.0).abs() < 1e-14,
                    "{name} θ {theta}: F + Q = {}",
                    f + q
                );
            }
        }
    }

    /// The band mean is the mean of P over the band, per solid angle: against Simpson's rule
    /// on P(cos θ) sin θ over θ ∈ [θ_lo, θ_hi] (20 000 intervals), for bands across the
    /// sphere, about each pole and inside one table segment, 1e-7 relative.
    #[test]
    fn band_mean_is_the_mean_over_the_band() {
        let c1 = crate::particles::builtin_table("bissonnette_c1_1064nm").unwrap();
        let mut all = all_analytic();
        all.push((
            "c1 table",
            PhaseFunction::Tabulated(Box::new(TabulatedPhase::from_table(&c1).unwrap())),
        ));
        let simpson = |f: &dyn Fn(f64) -> f64, a: f64, b: f64| {
            let n = 20_000;
            let h = (b - a) / n as f64;
            let mut s = f(a) + f(b);
            for i in 1..n {
                s += f(a + i as f64 * h) * if i % 2 == 1 { 4.0 } else { 2.0 };
            }
            s * h / 3.0
        };
        let bands = [
            (0.0, 1e-3),
            (0.0, 0.3),
            (0.2, 0.25),
            (1.0, 2.0),
            (0.0, std::f64::consts::PI),
            (3.0, std::f64::consts::PI),
            (std::f64::consts::PI - 1e-3, std::f64::consts::PI),
        ];
        for (name, p) in &all {
            for (lo, hi) in bands {
                let got = p.band_mean(lo, hi);
                let (m_hi, m_lo) = (f64::cos(lo), f64::cos(hi));
                let want = simpson(&|t| p.eval(t.cos()) * t.sin(), lo, hi) / (m_hi - m_lo);
                assert!(
                    (got / want - 1.0).abs() < 1e-7,
                    "{name} [{lo}, {hi}]: {got} vs {want}"
                );
            }
            // A band of zero width is the value there.
            assert_eq!(p.band_mean(1.0, 1.0), p.eval(f64::cos(1.0)));
        }
    }

    /// The curvature scale: Henyey-Greenstein's 3g/(1 − g)² against −∂² ln P/∂Θ² at the peak
    /// by central differences; a fine table of HG(0.9) reports HG's own (to 5 %); a table with
    /// a one-node spike of 1e12 reports at least 1e12 (the peak its nodes hold, which no
    /// aperture resolves).
    #[test]
    fn curvature_of_peaks() {
        for g in [0.5, 0.9, -0.95] {
            let hg = HenyeyGreenstein::new(g).unwrap();
            let peak = if g > 0.0 { 0.0 } else { std::f64::consts::PI };
            let h = 1e-3 * (1.0 - f64::abs(g));
            let lnp = |t: f64| hg.eval(f64::cos(t)).ln();
            // ln P is even about the pole: (ln P(h) − ln P(0)) · 2/h².
            let numeric = -2.0 * (lnp(peak + h) - lnp(peak)) / (h * h);
            let numeric = if g > 0.0 {
                numeric
            } else {
                -2.0 * (lnp(peak - h) - lnp(peak)) / (h * h)
            };
            let kappa = PhaseFunction::HenyeyGreenstein(hg).curvature();
            assert!(
                (kappa / numeric - 1.0).abs() < 1e-3,
                "g {g}: {kappa} vs {numeric}"
            );
        }
        let hg = HenyeyGreenstein::new(0.9).unwrap();
        let theta: Vec<f64> = (0..=18000).map(|i| i as f64 * 0.01).collect();
        let p: Vec<f64> = theta
            .iter()
            .map(|t| hg.eval(t.to_radians().cos()))
            .collect();
        let table =
            PhaseFunction::Tabulated(Box::new(TabulatedPhase::from_angles(&theta, &p).unwrap()));
        let want = PhaseFunction::HenyeyGreenstein(hg).curvature();
        assert!(
            (table.curvature() / want - 1.0).abs() < 0.05,
            "table of HG(0.9): {} vs {want}",
            table.curvature()
        );
        let spike =
            TabulatedPhase::from_angles(&[0.0, 90.0, 179.999999, 180.0], &[1.0, 1.0, 1.0, 1e12])
                .unwrap();
        assert!(spike.curvature > 1e12, "{}", spike.curvature);
    }

    const HG_TAILS: [(f64, f64, f64, f64); 30] = [
        (
            0.999999999999,
            1e-09,
            0.0009999773778144462,
            0.9990000226221856,
        ),
        (
            0.999999999999,
            1e-06,
            9.99977378291481e-07,
            0.9999990000226217,
        ),
        (
            0.999999999999,
            0.001,
            9.99477931007484e-10,
            0.999999999000522,
        ),
        (
            0.999999999999,
            std::f64::consts::FRAC_PI_2,
            2.0710219962850597e-13,
            0.9999999999997929,
        ),
        (
            0.999999999999,
            3.141591653589793,
            6.249861742534102e-26,
            1.0,
        ),
        (
            0.999999999999,
            3.1415926525897935,
            6.249858753269917e-32,
            1.0,
        ),
        (-0.999999999999, 1e-09, 1.0, 6.249861739255492e-32),
        (-0.999999999999, 1e-06, 1.0, 6.24986173925614e-26),
        (-0.999999999999, 0.001, 1.0, 6.249862390282821e-20),
        (
            -0.999999999999,
            std::f64::consts::FRAC_PI_2,
            0.9999999999997929,
            2.0710219962850592e-13,
        ),
        (
            -0.999999999999,
            3.141591653589793,
            0.999999000022622,
            9.99977378029244e-07,
        ),
        (
            -0.999999999999,
            3.1415926525897935,
            0.999000022383307,
            0.0009999776166930196,
        ),
        (0.99999999, 1e-09, 0.9950371902839376, 0.004962809716062456),
        (0.99999999, 1e-06, 0.009999495187727277, 0.9900005048122728),
        (0.99999999, 0.001, 9.995000566339156e-06, 0.9999900049994337),
        (
            0.99999999,
            std::f64::consts::FRAC_PI_2,
            2.071067842982771e-09,
            0.9999999979289321,
        ),
        (0.99999999, 3.141591653589793, 6.250000097183431e-22, 1.0),
        (0.99999999, 3.1415926525897935, 6.249997107853071e-28, 1.0),
        (-0.99999999, 1e-09, 1.0, 6.250000093904747e-28),
        (-0.99999999, 1e-06, 1.0, 6.2500000939053975e-22),
        (-0.99999999, 0.001, 0.9999999999999993, 6.25000074494649e-16),
        (
            -0.99999999,
            std::f64::consts::FRAC_PI_2,
            0.9999999979289321,
            2.0710678429827705e-09,
        ),
        (
            -0.99999999,
            3.141591653589793,
            0.9900005048148948,
            0.009999495185105244,
        ),
        (
            -0.99999999,
            3.1415926525897935,
            0.004962807362611057,
            0.995037192637389,
        ),
        (0.9999, 1e-09, 0.9999999999500025, 4.999749999626158e-11),
        (0.9999, 1e-06, 0.9999500062491251, 4.9993750874882644e-05),
        (0.9999, 0.001, 0.09946362034819116, 0.9005363796518089),
        (
            0.9999,
            std::f64::consts::FRAC_PI_2,
            2.0712749305185805e-05,
            0.9999792872506948,
        ),
        (0.9999, 3.141591653589793, 6.250625050156449e-18, 1.0),
        (0.9999, 3.1415926525897935, 6.250622060527179e-24, 1.0),
    ];

    // 60-digit values from validation/hg_extremes/hg_reference.py (mpmath).
    const HG_VALUES: [(f64, f64, f64); 25] = [
        (0.999999999999, 1.0, 2.0000884898157956e+24),
        (0.999999999999, 0.9999999999990905, 815220.5796029889),
        (0.999999999999, 0.999, 2.2360185118320516e-08),
        (0.999999999999, 0.0, 7.070911387689452e-13),
        (0.999999999999, -1.0, 2.4999446957021964e-13),
        (-0.999999999999, 1.0, 2.4999446957021964e-13),
        (-0.999999999999, 0.9999999999990905, 2.4999446957039013e-13),
        (-0.999999999999, 0.999, 2.501820826757012e-13),
        (-0.999999999999, 0.0, 7.070911387689452e-13),
        (-0.999999999999, -1.0, 2.0000884898157956e+24),
        (0.99999999, 1.0, 1.999999969900963e+16),
        (0.99999999, 0.9999999999990905, 8151714036.240659),
        (0.99999999, 0.999, 0.00022360680110960026),
        (0.99999999, 0.0, 7.071067918106568e-09),
        (0.99999999, -1.0, 2.5000000375618986e-09),
        (-0.99999999, 1.0, 2.5000000375618986e-09),
        (-0.99999999, 0.9999999999990905, 2.500000037563604e-09),
        (-0.99999999, 0.999, 2.501876210149066e-09),
        (-0.99999999, 0.0, 7.071067918106568e-09),
        (-0.99999999, -1.0, 1.999999969900963e+16),
        (0.9999, 1.0, 199990000.00004405),
        (0.9999, 0.9999999999990905, 199935450.90509298),
        (0.9999, 0.999, 2.2362748356962396),
        (0.9999, 0.0, 7.07177494516062e-05),
        (0.9999, -1.0, 2.5002500187509747e-05),
    ];
    const HG_SAMPLES: [(f64, f64, f64); 20] = [
        (0.999999999999, 0.1, 4.949780997353133e-23),
        (0.999999999999, 0.5, 1.4999336355731913e-24),
        (0.999999999999, 0.9, 1.172787616292673e-25),
        (0.999999999999, 0.999999, 9.999572570140175e-31),
        (-0.999999999999, 0.1, 1.1727876162926735e-25),
        (-0.999999999999, 0.5, 1.4999336355731913e-24),
        (-0.999999999999, 0.9, 4.949780997353136e-23),
        (-0.999999999999, 0.999999, 4.999773785298662e-13),
        (0.99999999, 0.1, 4.949999649245135e-15),
        (0.99999999, 0.5, 1.5000000100742778e-16),
        (0.99999999, 0.9, 1.1728395228289962e-17),
        (0.99999999, 0.999999, 1.0000015150802895e-22),
        (-0.99999999, 0.1, 1.1728395228289965e-17),
        (-0.99999999, 0.5, 1.5000000100742778e-16),
        (-0.99999999, 0.9, 4.949999649245137e-15),
        (-0.99999999, 0.999999, 4.9503726632597405e-05),
        (0.9999, 0.1, 4.945997410710755e-07),
        (0.9999, 0.5, 1.4999499999996696e-08),
        (0.9999, 0.9, 1.172888205029545e-09),
        (0.9999, 0.999999, 1.0000515025306581e-14),
    ];

    /// HG at |g| up to 1 − 1e-12, against 60-digit arithmetic: P(μ) to 1e-12 relative (the
    /// textbook form gives NaN or garbage near the peak: 1 + g² − 2g cancels to rounding), and
    /// the sampled μ to two units of the double's last place at 1 (where 1 − μ can be 1e-24 and
    /// rounds to 0; the angle it stands for is 1e-12 rad), 1 − μ to 1e-12 relative where
    /// it is representable.
    #[test]
    fn hg_at_extreme_asymmetry() {
        for (g, mu, want) in HG_VALUES {
            let p = HenyeyGreenstein::new(g).unwrap().eval(mu);
            assert!(
                (p / want - 1.0).abs() < 1e-12,
                "g {g} μ {mu}: P {p:e}, want {want:e}"
            );
        }
        for (g, u, want) in HG_SAMPLES {
            let mu = HenyeyGreenstein::new(g).unwrap().sample(u);
            // want = 1 − μ for g > 0, 1 + μ for g < 0.
            let side = if g > 0.0 { 1.0 - mu } else { 1.0 + mu };
            assert!(
                (side - want).abs() <= 2.0 * f64::EPSILON,
                "g {g} u {u}: 1 ∓ μ = {side:e}, want {want:e}"
            );
            if want > 1e-3 {
                assert!(
                    (side / want - 1.0).abs() < 1e-12,
                    "g {g} u {u}: {side:e} vs {want:e}"
                );
            }
        }
    }

    /// Closed-form CDF in μ of HG (independent of the sampler's algebra).
    fn hg_cdf(g: f64, mu: f64) -> f64 {
        if g.abs() < 1e-12 {
            return 0.5 * (mu + 1.0);
        }
        (1.0 - g * g) / (2.0 * g) * (1.0 / (1.0 + g * g - 2.0 * g * mu).sqrt() - 1.0 / (1.0 + g))
    }

    /// Closed-form CDF in μ of the Rayleigh phase function.
    fn rayleigh_cdf(gamma: f64, mu: f64) -> f64 {
        3.0 / (8.0 * (1.0 + 2.0 * gamma))
            * ((1.0 + 3.0 * gamma) * (mu + 1.0) + (1.0 - gamma) * (mu.powi(3) + 1.0) / 3.0)
    }

    /// CDF of a table, linear in μ between its nodes, integrated here from the table's own
    /// numbers (not from `TabulatedPhase`).
    fn table_cdf(t: &PhaseTable) -> impl Fn(f64) -> f64 {
        let mut nodes: Vec<(f64, f64)> = t
            .theta_deg
            .iter()
            .zip(&t.phase_4pi)
            .map(|(a, p)| (a.to_radians().cos(), *p))
            .collect();
        nodes.reverse();
        let total: f64 = nodes
            .windows(2)
            .map(|w| 0.5 * (w[0].1 + w[1].1) * (w[1].0 - w[0].0))
            .sum();
        move |mu: f64| {
            let mut acc = 0.0;
            for w in nodes.windows(2) {
                let ((m0, p0), (m1, p1)) = (w[0], w[1]);
                if mu <= m0 {
                    break;
                }
                let top = mu.min(m1);
                let p_top = p0 + (p1 - p0) * (top - m0) / (m1 - m0);
                acc += 0.5 * (p0 + p_top) * (top - m0);
            }
            acc / total
        }
    }

    /// Chi-square test of 10⁶ sampled angles in bins that resolve the forward peak, at
    /// significance α = 0.001 (fixed seed, so the test is deterministic), and the sampled mean
    /// cosine against g within 4 standard errors.
    #[test]
    fn sampled_angles_follow_each_phase_function() {
        use statrs::distribution::{ChiSquared, ContinuousCDF};
        let rho = 0.0279;
        let gamma = rho / (2.0 - rho);
        let c1 = crate::particles::builtin_table("bissonnette_c1_1064nm").unwrap();
        let c1_cdf = table_cdf(&c1);
        type Cdf<'a> = Box<dyn Fn(f64) -> f64 + 'a>;
        let cases: Vec<(&str, PhaseFunction, Cdf)> = vec![
            (
                "isotropic",
                PhaseFunction::Isotropic,
                Box::new(|m| 0.5 * (m + 1.0)),
            ),
            (
                "rayleigh",
                PhaseFunction::Rayleigh(RayleighPhase::from_depolarisation(rho).unwrap()),
                Box::new(move |m| rayleigh_cdf(gamma, m)),
            ),
            (
                "hg 0.85",
                PhaseFunction::HenyeyGreenstein(HenyeyGreenstein::new(0.85).unwrap()),
                Box::new(|m| hg_cdf(0.85, m)),
            ),
            (
                "hg -0.5",
                PhaseFunction::HenyeyGreenstein(HenyeyGreenstein::new(-0.5).unwrap()),
                Box::new(|m| hg_cdf(-0.5, m)),
            ),
            (
                "double hg",
                PhaseFunction::double_hg(0.9, 0.8, -0.4).unwrap(),
                Box::new(|m| 0.9 * hg_cdf(0.8, m) + 0.1 * hg_cdf(-0.4, m)),
            ),
            (
                "C.1 table",
                PhaseFunction::Tabulated(Box::new(TabulatedPhase::from_table(&c1).unwrap())),
                Box::new(c1_cdf),
            ),
        ];
        // Bin edges in angle: fine in the forward peak, 2° elsewhere.
        let mut edges_deg: Vec<f64> = (0..20).map(|i| 0.05 * i as f64).collect();
        edges_deg.extend((0..18).map(|i| 1.0 + 0.5 * i as f64));
        edges_deg.extend((0..=85).map(|i| 10.0 + 2.0 * i as f64));
        let edges_mu: Vec<f64> = edges_deg
            .iter()
            .rev()
            .map(|d| d.to_radians().cos())
            .collect();
        let n = 1_000_000usize;
        for (name, pf, cdf) in &cases {
            let mut rng = Xoshiro256PlusPlus::seed_from_u64(11);
            let mut counts = vec![0usize; edges_mu.len() - 1];
            let (mut sum, mut sum2) = (0.0, 0.0);
            for _ in 0..n {
                let mu = pf.sample(rng.random());
                sum += mu;
                sum2 += mu * mu;
                let b = edges_mu
                    .partition_point(|e| *e <= mu)
                    .clamp(1, edges_mu.len() - 1)
                    - 1;
                counts[b] += 1;
            }
            let mut chi2 = 0.0;
            let mut dof = 0usize;
            for (b, c) in counts.iter().enumerate() {
                let expected = n as f64 * (cdf(edges_mu[b + 1]) - cdf(edges_mu[b]));
                assert!(
                    expected > 0.0 || *c == 0,
                    "{name}: bin {b} has samples and no probability"
                );
                if expected > 0.0 {
                    chi2 += (*c as f64 - expected).powi(2) / expected;
                    dof += 1;
                }
            }
            let critical = ChiSquared::new((dof - 1) as f64)
                .unwrap()
                .inverse_cdf(0.999);
            assert!(
                chi2 < critical,
                "{name}: χ² = {chi2:.1} ≥ {critical:.1} ({} dof)",
                dof - 1
            );
            let mean = sum / n as f64;
            let se = ((sum2 / n as f64 - mean * mean) / n as f64).sqrt();
            assert!(
                (mean - pf.asymmetry()).abs() < 4.0 * se,
                "{name}: ⟨μ⟩ = {mean} vs g = {}",
                pf.asymmetry()
            );
        }
    }
}
