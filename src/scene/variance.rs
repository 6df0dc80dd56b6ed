//! The Monte Carlo's variance reductions: part of a scene's [`Simulation`](super::Simulation)
//! settings, not of its description (the scene file has no keys for them; `lidarsim run
//! --ddis-epsilon` and the benchmarks set them). Every setting leaves the results unbiased; the
//! methods are derived in `docs/transport.md`.

/// Default probability of detector-directed importance sampling.
pub const DDIS_EPSILON: f64 = 0.3;
/// Default probability of drawing the first collision uniformly in range.
pub const RANGE_STRATIFICATION: f64 = 0.5;
/// Default reference phase-function value of alignment splitting
/// ([`VarianceReduction::alignment_splitting`]).
pub const ALIGNMENT_SPLITTING: f64 = 1.0;
/// Default reference phase-function value of Russian roulette's alignment importance
/// ([`VarianceReduction::roulette_alignment`]).
pub const ROULETTE_ALIGNMENT: f64 = 10.0;

/// How the Monte Carlo reduces its variance.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VarianceReduction {
    /// Probability ε of detector-directed importance sampling at a scattering near the
    /// receiver's line of sight (0 turns it off).
    pub ddis_epsilon: f64,
    /// Probability β of drawing the first collision uniformly in range over the gated window
    /// instead of from the exponential (0 turns it off).
    pub range_stratification: f64,
    /// Alignment splitting: where DDIS applies, a photon whose weight times the phase
    /// function toward the receiver, w·P(Θ_rx) (P per 4π sr), exceeds twice this value is
    /// split before it scatters into n = ⌈w·P(Θ_rx)/value⌉ copies (at most 64), each drawing
    /// its own new direction (0 turns it off).
    pub alignment_splitting: f64,
    /// Russian roulette's alignment importance: where DDIS applies, a photon travelling toward
    /// the receiver with P(Θ_rx) (per 4π sr) above this value is played at the weight
    /// w·P(Θ_rx)/value instead of w, so that photons heading for the fields of view are spared
    /// (0 plays every photon at its weight; `docs/transport.md` step 7).
    pub roulette_alignment: f64,
    /// Score orders ≥ 2 in optically narrow fields of view also by the cone estimate (a last
    /// scattering drawn inside the field of view, `docs/transport.md` step 6a), not only when
    /// collisions happen to land there.
    pub cone_estimate: bool,
    /// Score orders ≥ 2 in the fields of view the cone estimate does not serve by the crossing
    /// estimate: at every flight from a scattering, the walk's next local estimate in expectation
    /// over where along the flight it collides inside them (`docs/transport.md` step 6b), not
    /// only when it happens to collide there.
    pub crossing_estimate: bool,
    /// Where DDIS applies, also the DDIS crossing: a direction drawn about the receiver's at
    /// every such scattering and the crossing estimate along it (`docs/transport.md` step 6c).
    pub ddis_crossing: bool,
}

impl Default for VarianceReduction {
    fn default() -> Self {
        VarianceReduction {
            ddis_epsilon: DDIS_EPSILON,
            range_stratification: RANGE_STRATIFICATION,
            alignment_splitting: ALIGNMENT_SPLITTING,
            roulette_alignment: ROULETTE_ALIGNMENT,
            cone_estimate: true,
            crossing_estimate: true,
            ddis_crossing: true,
        }
    }
}

impl VarianceReduction {
    /// None at all: the plain analogue walk with local estimates (the benchmarks' reference).
    pub fn none() -> Self {
        VarianceReduction {
            ddis_epsilon: 0.0,
            range_stratification: 0.0,
            alignment_splitting: 0.0,
            roulette_alignment: 0.0,
            cone_estimate: false,
            crossing_estimate: false,
            ddis_crossing: false,
        }
    }
}
