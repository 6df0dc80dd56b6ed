//! Time-resolved Monte Carlo transport of photon packets through the optical atmosphere.
//!
//! Consumes a [`Scene`] (lidar, gates, settings) and its [`OpticalAtmosphere`]; produces
//! [`Returns`] by channel × FOV × range gate × scattering order with standard errors, plus a
//! flux tally (energy leaving up, down, absorbed, cut) and run counters.
//!
//! This module drives batches and merges them; `photon.rs` follows one photon from top to
//! bottom. Photons are split into fixed batches; batch i draws from its own random stream
//! ([`crate::rng::streams`]) and scores into its own buffer; buffers are folded in batch order.
//! The numbers therefore depend on the scene and the seed, never on the thread count.

mod cone;
mod crossing;
mod photon;
mod stokes;
mod tally;
#[cfg(test)]
mod testing;

use std::io::IsTerminal;
use std::time::{Duration, Instant};

use glam::DVec3;
use rayon::prelude::*;
use thiserror::Error;

use crate::aperture::{self, Aperture};
use crate::optics::OpticalAtmosphere;
use crate::particles::matrix::{MatrixElements, ScatteringMatrix};
use crate::returns::{Combination, Returns};
use crate::rng::{self, Stream};
use crate::scene::{BeamProfile, Polarisation, Scene};

pub use tally::Flux;
use tally::{Accumulator, TallyShape};

/// Default probability of detector-directed importance sampling.
pub const DDIS_EPSILON: f64 = 0.3;
/// Default probability of drawing the first collision uniformly in range.
pub const RANGE_STRATIFICATION: f64 = 0.5;
/// Default reference phase-function value of alignment splitting
/// ([`TransportOptions::alignment_splitting`]).
pub const ALIGNMENT_SPLITTING: f64 = 1.0;
/// Default reference phase-function value of Russian roulette's alignment importance
/// ([`TransportOptions::roulette_alignment`]).
pub const ROULETTE_ALIGNMENT: f64 = 10.0;
/// Most copies alignment splitting makes of a photon at one collision.
pub(crate) const ALIGNMENT_MAX_COPIES: usize = 64;
/// DDIS is used where the scattering point is seen from the receiver within the widest field
/// of view plus a margin: the widest forward-peak half-width of the layer's forward-peaked
/// scatterers (the angle at which a phase function falls to half its forward value; C.1
/// droplets at 1064 nm: 37.5 mrad), at least this [rad]. A photon scattered there can still
/// reach the fields of view lower down in one forward scattering, and without DDIS's weight
/// its natural turns into the forward peak toward the receiver are the spikes DDIS exists to
/// remove; much further out, a photon sent toward the receiver stays outside the fields of
/// view (the line to the receiver keeps its angle to the axis). Chosen on C.1
/// (`validation/ms_efficiency`, 28 Nov): margins of 20–40 mrad gave the 10 mrad field of
/// view's deep gates 1.4× the figure of merit of 10 mrad, 60 mrad no more for 10 % more time.
const DDIS_MARGIN_MIN_RAD: f64 = 0.01;
/// Steps in μ of the scan for a phase function's largest backward value ([`backward_max`]).
const BACKWARD_MAX_STEPS: usize = 20_000;
/// Angular step [rad] of the scan for a phase function's forward half-width (then bisected).
const HALF_WIDTH_STEP_RAD: f64 = 1e-3;
/// Phase functions whose forward value P(0°) exceeds this get DDIS (Rayleigh, 1.5, does not).
const DDIS_FORWARD_PEAK: f64 = 5.0;
/// Optical depth to the receiver (least over the scattering classes) beyond which DDIS is not
/// used (`photon`).
const DDIS_MAX_TAU: f64 = 30.0;
/// Cone estimate: legs x → y shorter than this are left to the ordinary local estimate at y
/// (the kernel 1/|x − y|² stays bounded by its inverse square) [m].
const CONE_MIN_LEG_M: f64 = 1.0;
/// Cone estimate: only for FOV annuli whose footprint on the forward-peaked layers has a radius
/// below this scattering optical depth (outer half-angle × range × σ_s). Measured on C.1
/// (`lidarsim bench --depth`): there the cone estimate multiplies the figure of merit of the
/// 0.5–2 mrad fields of view (radius 0.005–0.022) by up to 100 and lowers it for 5 and 10 mrad
/// (0.056, 0.11), where enough collisions land inside the field of view anyway; at 2 mrad the
/// crossing estimate does as well, and the cone estimate, made within one footprint of the
/// widest annulus it serves, then costs less (28 Nov: 0.03 → 0.02, 7 % less time, the 0.5–1
/// mrad figures of merit unchanged within their scatter).
const CONE_MAX_FOOTPRINT_TAU: f64 = 0.02;
/// Cone estimate: made at every collision within this many footprints (of the widest annulus it
/// serves) of the axis, and with probability falling as 1/ρ beyond.
const CONE_RATE_FOOTPRINTS: f64 = 1.0;
/// Cone estimate: scale of its second, wide density along the ray, in units of the distance of
/// the collision from the ray (at least CONE_MIN_LEG_M): 1/20 rad is a forward peak's width.
const CONE_WIDE_SCALE: f64 = 20.0;

/// Run counters, summed over batches.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct RunStats {
    /// Photon packets emitted.
    pub photons: u64,
    /// Scattering events in the atmosphere.
    pub collisions: u64,
    /// Reflections at the surface.
    pub surface_reflections: u64,
    /// Local estimates that reached a gate inside a field of view.
    pub local_estimates: u64,
    /// Photons ended by Russian roulette.
    pub roulette_kills: u64,
    /// Photons ended because no gate could still receive them.
    pub cut: u64,
    /// Photons that left the atmosphere.
    pub escaped: u64,
    /// Photons ended with zero weight (a range-stratified collision where nothing scatters).
    pub zero_weight: u64,
    /// Copies made by splitting heavy photons.
    pub splits: u64,
}

impl RunStats {
    fn add(&mut self, o: &RunStats) {
        self.photons += o.photons;
        self.collisions += o.collisions;
        self.surface_reflections += o.surface_reflections;
        self.local_estimates += o.local_estimates;
        self.roulette_kills += o.roulette_kills;
        self.cut += o.cut;
        self.escaped += o.escaped;
        self.zero_weight += o.zero_weight;
        self.splits += o.splits;
    }
}

/// How to run the transport.
#[derive(Debug, Clone)]
pub struct TransportOptions {
    /// Photon packets (rounded up to a whole number per batch).
    pub photons: u64,
    /// Random seed.
    pub seed: u64,
    /// Number of batches (≥ 2).
    pub batches: usize,
    /// Worker threads (0: all cores).
    pub threads: usize,
    /// Highest order tallied separately.
    pub max_order: u32,
    /// Also tally the energy leaving the scene and absorbed in it (costs a layer walk per
    /// flight).
    pub flux_tally: bool,
    /// Show a progress bar on a terminal for runs longer than about a second.
    pub progress: bool,
    /// Probability ε of detector-directed importance sampling at a scattering near the
    /// receiver's line of sight (0 turns it off).
    pub ddis_epsilon: f64,
    /// Probability β of drawing the first collision uniformly in range over the gated window
    /// instead of from the exponential (0 turns it off).
    pub range_stratification: f64,
    /// Alignment splitting: where DDIS applies, a photon whose weight times the phase
    /// function toward the receiver, w·P(Θ_rx) (P per 4π sr), exceeds twice this value is
    /// split before it scatters into n = ⌈w·P(Θ_rx)/value⌉ copies (at most 64), each drawing
    /// its own new direction (0 turns it off; unbiased either way).
    pub alignment_splitting: f64,
    /// Russian roulette's alignment importance: where DDIS applies, a photon travelling toward
    /// the receiver with P(Θ_rx) (per 4π sr) above this value is played at the weight
    /// w·P(Θ_rx)/value instead of w, so that photons heading for the fields of view are spared
    /// (0 plays every photon at its weight; unbiased either way; `docs/transport.md` step 7).
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
    /// Linear combinations of channels to report as well (laser lines from their quadrature
    /// nodes), folded batch by batch so that their standard errors are right.
    pub combinations: Vec<Combination>,
    /// Pairs (a, b), a < b, of `combinations` whose covariance is folded too (the on- and
    /// off-line returns); only these, as their number grows with the square of the lines.
    pub combination_pairs: Vec<(usize, usize)>,
}

impl TransportOptions {
    /// The scene's own settings.
    pub fn from_scene(scene: &Scene) -> Self {
        let s = &scene.simulation;
        TransportOptions {
            photons: s.photons,
            seed: s.seed,
            batches: s.batches,
            threads: s.threads,
            max_order: s.max_order,
            flux_tally: false,
            progress: false,
            ddis_epsilon: DDIS_EPSILON,
            range_stratification: RANGE_STRATIFICATION,
            alignment_splitting: ALIGNMENT_SPLITTING,
            roulette_alignment: ROULETTE_ALIGNMENT,
            cone_estimate: true,
            crossing_estimate: true,
            ddis_crossing: true,
            combinations: Vec::new(),
            combination_pairs: Vec::new(),
        }
    }
}

/// A problem running the transport.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum TransportError {
    /// The worker pool could not be built.
    #[error("cannot start {0} worker threads: {1}")]
    Threads(usize, String),
    /// Nonsensical options.
    #[error("transport options: {0}")]
    Options(String),
}

/// What a transport run produces.
#[derive(Debug, Clone)]
pub struct McResult {
    /// Received energy by channel, FOV, gate and order, with standard errors.
    pub returns: Returns,
    /// The combined channels of [`TransportOptions::combinations`], with standard errors and the
    /// covariances of [`TransportOptions::combination_pairs`] (`None` without combinations).
    pub combined: Option<Returns>,
    /// Energy leaving the scene per channel, as a fraction of the emitted energy (zero unless
    /// the flux tally was on).
    pub flux: Flux,
    /// Standard errors of `flux`.
    pub flux_stderr: Flux,
    /// Co- and cross-polarised returns, when the lidar's light is polarised.
    pub polarised: Option<PolarisedMc>,
    /// Counters.
    pub stats: RunStats,
    /// Wall-clock time of the transport \[s\].
    pub wall_s: f64,
    /// Photons actually traced.
    pub photons: u64,
    /// Worker threads used.
    pub threads: usize,
}

/// The co- and cross-polarised parts of a set of returns (their sum is the total), and the
/// covariance of the two means bin by bin, for the depolarisation ratio's error.
#[derive(Debug, Clone)]
pub struct Polarised {
    /// What a sphere's single backscatter returns (`docs/transport.md`, "Polarisation").
    pub co: Returns,
    /// The rest.
    pub cross: Returns,
    /// Covariance of the means of `co` and `cross` \[J²\], index [`Returns::index`].
    pub cov_j2: Vec<f64>,
}

/// Polarised Monte Carlo returns: per channel, and per combination of channels (laser lines).
#[derive(Debug, Clone)]
pub struct PolarisedMc {
    /// The monochromatic channels.
    pub channels: Polarised,
    /// The combinations of [`TransportOptions::combinations`], if any.
    pub combined: Option<Polarised>,
}

/// How a polarised run's tallies are laid out: co-polarised returns as channels 0..n, cross
/// as n..2n; the accumulator then folds, as combinations, per channel its total, co and cross
/// (3n), and per user combination its total, co and cross (3m); its pairs are (co, cross) of
/// each channel, then of each user combination, then the user's own pairs of totals.
#[derive(Debug, Clone)]
struct PolarisedLayout {
    n: usize,
    m: usize,
}

impl PolarisedLayout {
    /// The combinations and pairs the accumulator folds for `n` channels, `user` combinations
    /// and `user_pairs` of them.
    fn combinations(
        n: usize,
        user: &[Combination],
        user_pairs: &[(usize, usize)],
    ) -> (Self, Vec<Combination>, Vec<(usize, usize)>) {
        let m = user.len();
        let mut c = Vec::with_capacity(3 * (n + m));
        for (part, terms) in [
            ("total", [1.0, 1.0]),
            ("co", [1.0, 0.0]),
            ("cross", [0.0, 1.0]),
        ] {
            for k in 0..n {
                c.push(Combination {
                    name: format!("{part} {k}"),
                    terms: [(k, terms[0]), (n + k, terms[1])]
                        .into_iter()
                        .filter(|(_, w)| *w != 0.0)
                        .collect(),
                });
            }
        }
        for (part, on) in [
            ("total", [true, true]),
            ("co", [true, false]),
            ("cross", [false, true]),
        ] {
            for u in user {
                let mut terms = Vec::new();
                for (k, w) in &u.terms {
                    if on[0] {
                        terms.push((*k, *w));
                    }
                    if on[1] {
                        terms.push((n + k, *w));
                    }
                }
                c.push(Combination {
                    name: format!("{part} {}", u.name),
                    terms,
                });
            }
        }
        let mut pairs: Vec<(usize, usize)> = (0..n).map(|k| (n + k, 2 * n + k)).collect();
        pairs.extend((0..m).map(|j| (3 * n + m + j, 3 * n + 2 * m + j)));
        pairs.extend(user_pairs.iter().map(|(a, b)| (3 * n + a, 3 * n + b)));
        (PolarisedLayout { n, m }, c, pairs)
    }
}

/// Channels `start..start + n` of a set of returns, named `names`.
fn channel_slice(r: &Returns, start: usize, names: &[String]) -> Returns {
    let b = r.bins_per_channel();
    let mut out = Returns::zeros(
        r.source,
        names.to_vec(),
        r.fov_full_angle_mrad.clone(),
        r.range_m.clone(),
        r.orders.clone(),
    );
    let span = start * b..(start + names.len()) * b;
    out.energy_j.copy_from_slice(&r.energy_j[span.clone()]);
    out.stderr_j.copy_from_slice(&r.stderr_j[span]);
    out
}

/// The covariances of pairs `first..first + count` of `r`, one channel's bins after another.
fn pair_covariances(r: &Returns, first: usize, count: usize) -> Vec<f64> {
    let b = r.bins_per_channel();
    r.covariance
        .as_ref()
        .map(|c| c.cov_j2[first * b..(first + count) * b].to_vec())
        .unwrap_or_else(|| vec![f64::NAN; count * b])
}

/// Read-only set-up shared by all batches.
pub(crate) struct Setup<'a> {
    atm: &'a OpticalAtmosphere,
    receiver: DVec3,
    axis: DVec3,
    axis_e1: DVec3,
    axis_e2: DVec3,
    beam_half_angle_rad: f64,
    beam_profile: BeamProfile,
    /// cos of FOV half-angles, narrowest first.
    fov_cos: Vec<f64>,
    /// Cosine of the widest half-angle.
    fov_cos_widest: f64,
    has_layers: bool,
    bottom_m: f64,
    top_m: f64,
    shape: TallyShape,
    gate_start_m: f64,
    gate_width_m: f64,
    r_end_m: f64,
    max_order: u32,
    surface: Option<Vec<f64>>,
    flux_tally: bool,
    /// Cumulative vertical extinction optical depth at the receiver altitude, per channel.
    tau_rx: Vec<f64>,
    /// Free-path samplers, one per scattering class (channels whose scatterers, coefficients and
    /// phase functions are the same); class 0 holds channel 0. One class is the common case
    /// (grey scattering: on/off lines); with more, each collision and each scattering angle is
    /// drawn from the mixture of the classes' densities (`photon` module docs).
    classes: Vec<ScatterClass>,
    /// Detector-directed importance sampling: probability ε, the layers whose phase function
    /// has a forward peak worth it, and per layer the cone around the receiver axis where it is
    /// used there (cosine of its half-angle; [`DDIS_MARGIN_MIN_RAD`]).
    ddis_epsilon: f64,
    forward_peaked: Vec<bool>,
    ddis_cos: Vec<f64>,
    /// Per layer, the largest value of the phase function DDIS samples from (`mean_phase`) over
    /// the backward hemisphere, μ ≤ 0: a bound on P(Θ_rx) for a photon travelling away from
    /// the receiver, which spares evaluating it where it cannot matter (`photon`).
    backward_max: Vec<f64>,
    /// Alignment splitting's reference phase-function value (0: off).
    align_split: f64,
    /// Russian roulette's alignment importance: its reference phase-function value (0: off).
    roulette_align: f64,
    /// Probability β of drawing the first collision uniformly in range over the gates.
    stratify: f64,
    /// Cone estimate on (for some annulus), the annuli it serves, and the solid angle of each
    /// FOV annulus (narrowest first).
    cone: bool,
    cone_annuli: Vec<usize>,
    annulus_sr: Vec<f64>,
    /// Tangent of the widest cone annulus's half-angle (`Setup::cone_rate`).
    cone_tan: f64,
    /// Crossing estimate: the first annulus it serves (it serves the wider ones too; the number
    /// of annuli when off), and tan² of the half-angles of the cones bounding its region (the
    /// inner 0 when it starts at the narrowest).
    crossing_from: usize,
    crossing_tan2: [f64; 2],
    /// DDIS crossing at every DDIS scattering (`photon::Tracer::score_ddis_crossing`).
    ddis_crossing: bool,
    /// Polarised transport: the receiver's analyser (`None`: scalar transport), and the
    /// scattering matrix of each of the atmosphere's phase functions (same index).
    analyser: Option<stokes::Analyser>,
    matrices: Vec<ScatteringMatrix>,
    /// The aperture seen from close by: where, per layer, the local estimates use the energy
    /// it collects instead of the point-receiver value (`crate::aperture`).
    aperture: Aperture,
}

/// The free-path density of one scattering class: its cumulative vertical scattering optical
/// depth at the layer edges and its σ_s per layer (those of its first channel).
pub(crate) struct ScatterClass {
    channel: usize,
    cum: Vec<f64>,
    sigma: Vec<f64>,
    /// 1/σ per layer (0 where σ = 0): the inverse optical depth without a division.
    inv_sigma: Vec<f64>,
}

impl ScatterClass {
    fn of_channel(atm: &OpticalAtmosphere, k: usize) -> Self {
        let nch = atm.n_channels;
        let sigma: Vec<f64> = (0..atm.n_layers())
            .map(|l| atm.sigma_s_per_m[l * nch + k])
            .collect();
        ScatterClass {
            channel: k,
            cum: (0..atm.edges_m.len())
                .map(|e| atm.cum_tau_s[e * nch + k])
                .collect(),
            inv_sigma: sigma
                .iter()
                .map(|s| if *s > 0.0 { 1.0 / s } else { 0.0 })
                .collect(),
            sigma,
        }
    }
}

/// One representative channel per scattering class, channel 0 first. A channel joins the class
/// of the first representative it scatters like: the column's scattering optical depths within
/// [`CLASS_TAU_TOLERANCE`], and in every layer where either scatters appreciably (layer optical
/// depth above [`CLASS_LAYER_TAU`]) every scatterer's coefficient within a factor 2 of the
/// representative's and its phase function within a factor 2 at every angle. Within a class
/// the ALIS ratio weights stay near 1 (on/off lines, whose Rayleigh scattering differs by 1e-5,
/// are one class; so are 532 and 1064 nm through thin aerosol); between classes they could be
/// anything, so each class gets its own free-path density and the transport samples their
/// mixture.
fn scatter_classes(atm: &OpticalAtmosphere) -> Vec<usize> {
    let nch = atm.n_channels;
    let top = atm.edges_m.len().saturating_sub(1);
    let similar = |r: usize, k: usize| {
        let column = (atm.cum_tau_s[top * nch + k] - atm.cum_tau_s[top * nch + r]).abs();
        column <= CLASS_TAU_TOLERANCE
            && atm.components.iter().enumerate().all(|(l, comps)| {
                let dz = atm.edges_m[l + 1] - atm.edges_m[l];
                let tau = |ch: usize| atm.sigma_s_per_m[l * nch + ch] * dz;
                tau(r).max(tau(k)) <= CLASS_LAYER_TAU
                    || comps.iter().all(|c| {
                        let (a, b) = (c.sigma_s_per_m[r], c.sigma_s_per_m[k]);
                        let coefficient =
                            (a == b) || (a > 0.0 && b > 0.0 && a <= 2.0 * b && b <= 2.0 * a);
                        coefficient
                            && (c.phase[r] == c.phase[k]
                                || similar_phase(
                                    &atm.phases[c.phase[r] as usize],
                                    &atm.phases[c.phase[k] as usize],
                                ))
                    })
            })
    };
    let mut reps = vec![0];
    if !atm.grey_scattering {
        for k in 1..nch {
            if !reps.iter().any(|&r| similar(r, k)) {
                reps.push(k);
            }
        }
    }
    reps
}

/// Largest difference of column scattering optical depth within one scattering class: the
/// ALIS weight e^{−(τ_k − τ_r)} of a path through the column then stays within e^{±0.5} or so.
const CLASS_TAU_TOLERANCE: f64 = 0.5;
/// Layer scattering optical depth below which the coefficients and phase functions of a class
/// may differ by any factor (few collisions happen there).
const CLASS_LAYER_TAU: f64 = 0.1;

/// The half-width of a phase function's forward peak: the scattering angle [rad] at which it
/// first falls to half its forward value P(0°), π if it never does. A scan in steps of
/// [`HALF_WIDTH_STEP_RAD`] finds the first step below half, bisection the angle within it.
fn forward_half_width(phase: impl Fn(f64) -> f64) -> f64 {
    use std::f64::consts::PI;
    let half = 0.5 * phase(1.0);
    let below = |theta: f64| phase(theta.cos()) <= half;
    let steps = (PI / HALF_WIDTH_STEP_RAD).ceil() as usize;
    let Some(i) = (1..=steps).find(|&i| below((i as f64 * HALF_WIDTH_STEP_RAD).min(PI))) else {
        return PI;
    };
    let (mut lo, mut hi) = (
        (i - 1) as f64 * HALF_WIDTH_STEP_RAD,
        (i as f64 * HALF_WIDTH_STEP_RAD).min(PI),
    );
    for _ in 0..30 {
        let mid = 0.5 * (lo + hi);
        if below(mid) { hi = mid } else { lo = mid }
    }
    hi
}

/// The largest value of a phase function over the backward hemisphere, μ ∈ [−1, 0]: its
/// greatest value on a grid of [`BACKWARD_MAX_STEPS`] steps in μ, raised by the largest change
/// between neighbouring grid points (so that a peak between them is still bounded), and
/// never below the value at μ = 0 or −1.
fn backward_max(phase: impl Fn(f64) -> f64) -> f64 {
    let values: Vec<f64> = (0..=BACKWARD_MAX_STEPS)
        .map(|i| phase(-(i as f64) / BACKWARD_MAX_STEPS as f64))
        .collect();
    let top = values.iter().fold(0.0f64, |m, v| m.max(*v));
    let jump = values
        .windows(2)
        .fold(0.0f64, |m, w| m.max((w[1] - w[0]).abs()));
    top + jump
}

/// Two phase functions within a factor 2 of each other at every scattering angle (361 angles,
/// uniform in Θ).
fn similar_phase(
    p: &crate::particles::phase::PhaseFunction,
    q: &crate::particles::phase::PhaseFunction,
) -> bool {
    (0..=360).all(|i| {
        let mu = (std::f64::consts::PI * i as f64 / 360.0).cos();
        let (a, b) = (p.eval(mu), q.eval(mu));
        a <= 2.0 * b && b <= 2.0 * a
    })
}

impl Setup<'_> {
    /// Order bin: exact orders 1..=max_order, then the overflow bin.
    #[inline]
    fn order_bin(&self, order: u32) -> usize {
        (order.min(self.max_order + 1) - 1) as usize
    }

    /// Phase function of the scatterer mixture of `layer` for channel k at μ.
    #[inline]
    fn mixture_phase(&self, layer: usize, k: usize, mu: f64) -> f64 {
        let comps = &self.atm.components[layer];
        if comps.len() == 1 {
            return self.atm.phases[comps[0].phase[k] as usize].eval(mu);
        }
        let total = self.atm.sigma_s_per_m[layer * self.atm.n_channels + k];
        if total <= 0.0 {
            return 0.0;
        }
        comps
            .iter()
            .map(|c| c.sigma_s_per_m[k] * self.atm.phases[c.phase[k] as usize].eval(mu))
            .sum::<f64>()
            / total
    }

    /// The phase function a local estimate toward the receiver uses: its value at μ, or
    /// close to the receiver its mean over the aperture's band (`crate::aperture`).
    #[inline]
    fn receiver_phase(&self, layer: usize, k: usize, mu: f64, band: Option<(f64, f64)>) -> f64 {
        match band {
            None => self.mixture_phase(layer, k, mu),
            Some(b) => self.mixture_band(layer, k, b),
        }
    }

    /// Polarised estimates close to the receiver: the factor that turns the scattering
    /// matrix's F₁₁ at μ into its mean over the aperture's band (the other elements scaled
    /// alike); 0 where F₁₁(μ) is 0.
    fn band_over_point(&self, layer: usize, k: usize, mu: f64, band: Option<(f64, f64)>) -> f64 {
        let Some(b) = band else { return 1.0 };
        let point = self.mixture_phase(layer, k, mu);
        if point > 0.0 {
            self.mixture_band(layer, k, b) / point
        } else {
            0.0
        }
    }

    /// [`Self::mixture_phase`] averaged over a band of scattering angles (`crate::aperture`).
    fn mixture_band(&self, layer: usize, k: usize, band: (f64, f64)) -> f64 {
        let atm = self.atm;
        let comps = &atm.components[layer];
        if comps.len() == 1 {
            return atm.phases[comps[0].phase[k] as usize].band_mean(band.0, band.1);
        }
        aperture::mixture_band_mean(
            comps
                .iter()
                .map(|c| (c.sigma_s_per_m[k], &*atm.phases[c.phase[k] as usize])),
            atm.sigma_s_per_m[layer * atm.n_channels + k],
            band,
        )
    }

    /// The phase function at μ of the scatterers of `layer` in the density the scattering angle
    /// is drawn from: one scattering class, its own; several, the mean of those that scatter
    /// there (0 where none does).
    #[inline]
    fn mean_phase(&self, layer: usize, mu: f64) -> f64 {
        if self.classes.len() == 1 {
            return self.mixture_phase(layer, 0, mu);
        }
        let (sum, n) = self
            .classes
            .iter()
            .filter(|c| c.sigma[layer] > 0.0)
            .fold((0.0, 0usize), |(sum, n), c| {
                (sum + self.mixture_phase(layer, c.channel, mu), n + 1)
            });
        if n > 0 { sum / n as f64 } else { 0.0 }
    }

    /// Scattering matrix of the scatterer mixture of `layer` for channel k at μ (weighted as
    /// [`Self::mixture_phase`], so its F₁₁ is that phase function).
    #[inline]
    fn mixture_matrix(&self, layer: usize, k: usize, mu: f64) -> MatrixElements {
        let comps = &self.atm.components[layer];
        if comps.len() == 1 {
            return self.matrices[comps[0].phase[k] as usize].eval(mu);
        }
        let total = self.atm.sigma_s_per_m[layer * self.atm.n_channels + k];
        let mut m = MatrixElements::non_depolarising(0.0);
        if total <= 0.0 {
            return m;
        }
        for c in comps {
            let w = c.sigma_s_per_m[k] / total;
            let e = self.matrices[c.phase[k] as usize].eval(mu);
            m.f11 += w * e.f11;
            m.f22 += w * e.f22;
            m.f33 += w * e.f33;
            m.f44 += w * e.f44;
            m.f12 += w * e.f12;
            m.f34 += w * e.f34;
        }
        m
    }

    /// Extinction optical depth from altitude z (cumulative value `t_here`) to the receiver along
    /// a straight line with vertical direction cosine `omega_z` and length d.
    #[inline]
    fn tau_to_receiver(
        &self,
        z: f64,
        omega_z: f64,
        d: f64,
        layer: usize,
        k: usize,
        t_here: f64,
    ) -> f64 {
        if omega_z.abs() < 1e-12 {
            let atm = self.atm;
            if atm.n_layers() == 0 || z < atm.bottom_m() || z > atm.top_m() {
                return 0.0;
            }
            let i = layer * atm.n_channels + k;
            return (atm.sigma_s_per_m[i] + atm.sigma_a_per_m[i]) * d;
        }
        (t_here - self.tau_rx[k]).abs() / omega_z.abs()
    }

    /// Cumulative vertical scattering optical depth of class `c` at altitude z.
    #[inline]
    fn class_tau_at(&self, c: usize, z: f64) -> f64 {
        if !self.has_layers {
            return 0.0;
        }
        let cls = &self.classes[c];
        let z = z.clamp(self.bottom_m, self.top_m);
        let e = &self.atm.edges_m;
        let l = e
            .partition_point(|x| *x <= z)
            .saturating_sub(1)
            .min(cls.sigma.len() - 1);
        cls.cum[l] + (z - e[l]) * cls.sigma[l]
    }

    /// [`Self::class_tau_at`] at the end `z_end` of a flight that ends `end`: at the top or
    /// bottom without a search.
    #[inline]
    fn class_tau_at_end(&self, c: usize, end: photon::End, z_end: f64) -> f64 {
        let cum = &self.classes[c].cum;
        match end {
            _ if !self.has_layers => 0.0,
            photon::End::Top => cum[cum.len() - 1],
            photon::End::Bottom | photon::End::Surface => cum[0],
            photon::End::Cut => self.class_tau_at(c, z_end),
        }
    }

    /// Altitude (and its layer) at which a photon leaving a point of cumulative class-`c`
    /// scattering optical depth `t0` with direction cosine μ ≠ 0 has accumulated τ*.
    ///
    /// `hint` is the layer the flight starts in: the collision is usually in it (always, in a
    /// single cloud layer), and checking it first spares the search.
    #[inline]
    fn altitude_at_tau(
        &self,
        c: usize,
        t0: f64,
        mu: f64,
        tau_star: f64,
        hint: usize,
    ) -> (f64, usize) {
        let cls = &self.classes[c];
        let target = t0 + tau_star * mu;
        let n = cls.sigma.len();
        // The layer: the last edge at or below the target going up (strictly below it going
        // down), capped to the last layer; edges below the first count as the first.
        let below = |cum: f64| {
            if mu > 0.0 {
                cum <= target
            } else {
                cum < target
            }
        };
        let l = if hint < n
            && (hint == 0 || below(cls.cum[hint]))
            && (hint == n - 1 || !below(cls.cum[hint + 1]))
        {
            hint
        } else {
            cls.cum
                .partition_point(|c| below(*c))
                .saturating_sub(1)
                .min(n - 1)
        };
        let e = &self.atm.edges_m;
        let z = if cls.sigma[l] > 0.0 {
            e[l] + (target - cls.cum[l]) * cls.inv_sigma[l]
        } else {
            e[l]
        };
        (z.clamp(e[l], e[l + 1]), l)
    }
}

/// One batch's raw tallies, before normalisation: what a shard stores and a rank sends. Folding
/// these in batch order ([`Fold`]) gives the same numbers however they were computed.
#[derive(Debug, Clone, PartialEq)]
pub struct BatchTally {
    /// Batch index, 0-based.
    pub index: usize,
    /// Annulus × exact-order bins (gate × order bin × annulus × channel, channel fastest), in
    /// units of weight × geometric factor per photon of the batch, summed.
    pub bins: Vec<f64>,
    /// Flux tally of the batch (zeros unless asked for), summed weights.
    pub flux: Flux,
    /// Counters of the batch.
    pub stats: RunStats,
}

/// A validated transport run, ready to trace any of its batches: the read-only set-up shared by
/// all batches plus what is needed to fold them. [`run`] is `Plan::new`, every batch in parallel,
/// and a [`Fold`] in batch order; sharded and distributed runs use the same three steps.
pub struct Plan<'a> {
    setup: Setup<'a>,
    fov_order: Vec<usize>,
    batches: usize,
    per_batch: u64,
    /// The random stream each batch starts from (computed once: batch b's is b jumps on).
    streams: Vec<rng::Rng>,
    threads: usize,
    progress: bool,
    /// Energy per photon reaching the detector, per unit weight × geometric factor.
    scale: f64,
    flux_scale: f64,
    combinations: Vec<Combination>,
    combination_pairs: Vec<(usize, usize)>,
    channels: Vec<String>,
    fov_full_angle_mrad: Vec<f64>,
    range_m: Vec<f64>,
    /// The user's combinations' names, and the layout of a polarised run's tallies.
    combination_names: Vec<String>,
    polarised: Option<PolarisedLayout>,
}

impl<'a> Plan<'a> {
    /// Check the options against the scene and build the shared set-up.
    pub fn new(
        scene: &Scene,
        atm: &'a OpticalAtmosphere,
        opts: &TransportOptions,
    ) -> Result<Self, TransportError> {
        if opts.batches < 2 || opts.photons < opts.batches as u64 {
            return Err(TransportError::Options(format!(
                "{} photons in {} batches: need at least 2 batches and one photon per batch",
                opts.photons, opts.batches
            )));
        }
        // The limits a scene is validated against, again for options built by hand.
        use crate::input::check_count;
        use crate::limits::{
            MAX_BATCHES, MAX_PHOTONS, MAX_RETURN_BINS, MAX_THREADS, check_product,
        };
        check_count(opts.batches as u64, 2, MAX_BATCHES)
            .and_then(|_| check_count(opts.photons, 1, MAX_PHOTONS))
            .and_then(|_| check_count(opts.threads as u64, 0, MAX_THREADS))
            .and_then(|_| check_count(opts.max_order.into(), 1, 1000))
            .map_err(TransportError::Options)?;
        // The variance reductions' settings (the command line checks its own; these are for
        // options built in code): probabilities below 1, reference values finite and ≥ 0.
        for (name, value, below_one) in [
            ("ddis_epsilon", opts.ddis_epsilon, true),
            ("range_stratification", opts.range_stratification, true),
            ("alignment_splitting", opts.alignment_splitting, false),
            ("roulette_alignment", opts.roulette_alignment, false),
        ] {
            if !(value >= 0.0 && value.is_finite() && (!below_one || value < 1.0)) {
                return Err(TransportError::Options(format!(
                    "{name} = {value}: must be finite and at least 0{}",
                    if below_one { ", and below 1" } else { "" }
                )));
            }
        }
        // A polarised run folds co, cross and total of every series.
        let n_pol_series = if scene.lidar.polarisation == Polarisation::None {
            1
        } else {
            3
        };
        let n_series = n_pol_series
            * (scene.channels.len() + opts.combinations.len() + opts.combination_pairs.len());
        check_product(
            "the returns",
            &[
                ("gates", scene.gates.count as u64),
                (
                    "fields of view",
                    scene.lidar.fov_full_angle_mrad.len() as u64,
                ),
                ("order bins", u64::from(opts.max_order) + 2),
                ("channels, combinations and pairs", n_series as u64),
            ],
            MAX_RETURN_BINS,
        )
        .map_err(TransportError::Options)?;
        let lidar = &scene.lidar;
        let nch = scene.channels.len();
        if let Some(c) = opts
            .combinations
            .iter()
            .find(|c| c.terms.iter().any(|(k, w)| *k >= nch || !w.is_finite()))
        {
            return Err(TransportError::Options(format!(
                "combination `{}` refers to a channel beyond the {nch} channels or has a non-finite coefficient",
                c.name
            )));
        }
        let n_combos = opts.combinations.len();
        if let Some((a, b)) = opts
            .combination_pairs
            .iter()
            .find(|(a, b)| !(a < b && *b < n_combos))
        {
            return Err(TransportError::Options(format!(
                "combination pair ({a}, {b}) is not two distinct combinations of the {n_combos}"
            )));
        }
        let axis = lidar.axis();
        let (axis_e1, axis_e2) = axis.any_orthonormal_pair();
        let receiver = DVec3::new(0.0, 0.0, lidar.altitude_m);

        // FOV annuli: narrowest first.
        let mut fov_order: Vec<usize> = (0..lidar.fov_full_angle_mrad.len()).collect();
        fov_order.sort_by(|a, b| {
            lidar.fov_full_angle_mrad[*a].total_cmp(&lidar.fov_full_angle_mrad[*b])
        });
        let fov_cos: Vec<f64> = fov_order
            .iter()
            .map(|i| (0.5e-3 * lidar.fov_full_angle_mrad[*i]).cos())
            .collect();

        // A polarised run tallies co-polarised returns as channels 0..n and cross as n..2n.
        let polarised_run = lidar.polarisation != Polarisation::None;
        let shape = TallyShape {
            n_gates: scene.gates.count,
            n_order_bins: opts.max_order as usize + 1,
            n_fov: fov_order.len(),
            n_channels: if polarised_run { 2 * nch } else { nch },
        };
        let n_layers = atm.n_layers();
        let widest = fov_cos.last().copied().unwrap_or(1.0);
        let widest_fov_mrad = lidar
            .fov_full_angle_mrad
            .iter()
            .fold(0.0f64, |m, f| m.max(*f));
        let setup = Setup {
            atm,
            fov_cos_widest: widest,
            has_layers: atm.n_layers() > 0,
            bottom_m: atm.bottom_m(),
            top_m: atm.top_m(),
            receiver,
            axis,
            axis_e1,
            axis_e2,
            beam_half_angle_rad: 0.5e-3 * lidar.beam_divergence_full_angle_mrad,
            beam_profile: lidar.beam_profile,
            fov_cos,
            shape,
            gate_start_m: scene.gates.start_m,
            gate_width_m: scene.gates.width_m,
            r_end_m: scene.gates.end_m(),
            max_order: opts.max_order,
            surface: scene.surface.as_ref().map(|s| s.albedo.clone()),
            flux_tally: opts.flux_tally,
            tau_rx: (0..nch)
                .map(|k| {
                    let (s, a) = atm.cumulative_tau(receiver.z, k);
                    s + a
                })
                .collect(),
            classes: scatter_classes(atm)
                .into_iter()
                .map(|k| ScatterClass::of_channel(atm, k))
                .collect(),
            ddis_epsilon: opts.ddis_epsilon,
            forward_peaked: vec![false; n_layers],
            ddis_cos: vec![1.0; n_layers],
            backward_max: vec![f64::INFINITY; n_layers],
            align_split: opts.alignment_splitting,
            roulette_align: opts.roulette_alignment,
            stratify: opts.range_stratification,
            cone: false,
            cone_annuli: Vec::new(),
            annulus_sr: Vec::new(),
            cone_tan: 0.0,
            crossing_from: 0,
            crossing_tan2: [0.0; 2],
            ddis_crossing: opts.ddis_crossing,
            analyser: match lidar.polarisation {
                Polarisation::None => None,
                Polarisation::Linear => Some(stokes::Analyser::Linear(axis_e1)),
                Polarisation::Circular => Some(stokes::Analyser::Circular),
            },
            matrices: atm.matrices.iter().map(|m| (**m).clone()).collect(),
            aperture: Aperture::new(lidar.telescope_diameter_m, atm),
        };
        // Which layers get DDIS: a forward-peaked scatterer mixture (in any class).
        let mut setup = setup;
        setup.forward_peaked = (0..n_layers)
            .map(|l| {
                !atm.components[l].is_empty()
                    && setup
                        .classes
                        .iter()
                        .any(|c| setup.mixture_phase(l, c.channel, 1.0) > DDIS_FORWARD_PEAK)
            })
            .collect();
        // Per phase function (once: a profile of thousands of thin layers shares a few), its
        // forward half-width and its backward bound; then per layer from its scatterers.
        let half_width: Vec<f64> = atm
            .phases
            .iter()
            .map(|p| forward_half_width(|mu| p.eval(mu)))
            .collect();
        let back_bound: Vec<f64> = atm
            .phases
            .iter()
            .map(|p| backward_max(|mu| p.eval(mu)))
            .collect();
        // A layer's backward bound: per class, its scatterers' bounds weighted by their shares
        // of the class's scattering (a bound on the mixture, whose largest value cannot exceed
        // that sum); the largest over the classes bounds their mean, `mean_phase`.
        setup.backward_max = (0..n_layers)
            .map(|l| {
                setup
                    .classes
                    .iter()
                    .filter(|c| c.sigma[l] > 0.0)
                    .map(|c| {
                        let k = c.channel;
                        atm.components[l]
                            .iter()
                            .map(|comp| comp.sigma_s_per_m[k] * back_bound[comp.phase[k] as usize])
                            .sum::<f64>()
                            * c.inv_sigma[l]
                    })
                    .fold(0.0f64, f64::max)
            })
            .collect();
        // DDIS's margin in a layer: the widest forward half-width among its forward-peaked
        // scatterers (a droplet's, not the air's around it), at least DDIS_MARGIN_MIN_RAD.
        setup.ddis_cos = (0..n_layers)
            .map(|l| {
                let margin = if setup.forward_peaked[l] {
                    setup
                        .classes
                        .iter()
                        .flat_map(|c| {
                            atm.components[l]
                                .iter()
                                .map(move |comp| comp.phase[c.channel])
                        })
                        .filter(|&i| atm.phases[i as usize].eval(1.0) > DDIS_FORWARD_PEAK)
                        .map(|i| half_width[i as usize])
                        .fold(DDIS_MARGIN_MIN_RAD, f64::max)
                } else {
                    DDIS_MARGIN_MIN_RAD
                };
                (0.5e-3 * widest_fov_mrad + margin)
                    .min(std::f64::consts::PI)
                    .cos()
            })
            .collect();
        setup.annulus_sr = (0..setup.fov_cos.len())
            .map(|a| {
                let inner = if a == 0 { 1.0 } else { setup.fov_cos[a - 1] };
                2.0 * std::f64::consts::PI * (inner - setup.fov_cos[a])
            })
            .collect();
        // The cone estimate for the annuli whose footprint on every forward-peaked layer is
        // optically narrow: there collisions inside the field of view are rare (clouds,
        // aerosol seen with narrow fields of view); in Rayleigh air and wide fields of view the
        // walk's own local estimates do well.
        if opts.cone_estimate {
            let footprint = |cos_outer: f64| -> f64 {
                let tan_a = (1.0 - cos_outer * cos_outer).max(0.0).sqrt() / cos_outer;
                (0..n_layers)
                    .filter(|l| setup.forward_peaked[*l])
                    .map(|l| {
                        // Farthest range of the layer along the axis (slant: /|axis.z|).
                        let far = [atm.edges_m[l], atm.edges_m[l + 1]]
                            .iter()
                            .map(|z| ((z - receiver.z) / axis.z.abs().max(1e-6)).abs())
                            .fold(0.0f64, f64::max);
                        let sigma = setup.classes[0].sigma[l];
                        tan_a * far * sigma
                    })
                    .fold(0.0f64, f64::max)
            };
            setup.cone_annuli = (0..setup.fov_cos.len())
                .filter(|&a| {
                    setup.annulus_sr[a] > 0.0
                        && setup.forward_peaked.iter().any(|f| *f)
                        && footprint(setup.fov_cos[a]) <= CONE_MAX_FOOTPRINT_TAU
                })
                .collect();
        }
        setup.cone = !setup.cone_annuli.is_empty();
        if let Some(&a) = setup.cone_annuli.iter().max() {
            let c = setup.fov_cos[a];
            setup.cone_tan = (1.0 - c * c).max(0.0).sqrt() / c;
        }
        // The crossing estimate for every annulus wider than the cone estimate's.
        let n_fov = setup.fov_cos.len();
        setup.crossing_from = if opts.crossing_estimate && setup.has_layers {
            setup.cone_annuli.iter().map(|a| a + 1).max().unwrap_or(0)
        } else {
            n_fov
        };
        if setup.crossing_from < n_fov {
            let tan2 = |c: f64| (1.0 - c * c).max(0.0) / (c * c);
            setup.crossing_tan2 = [
                if setup.crossing_from == 0 {
                    0.0
                } else {
                    tan2(setup.fov_cos[setup.crossing_from - 1])
                },
                tan2(setup.fov_cos[n_fov - 1]),
            ];
        }
        let setup = setup;

        let batches = opts.batches;
        let per_batch = opts.photons.div_ceil(batches as u64);
        let (polarised, combinations, combination_pairs) = if polarised_run {
            let (layout, c, p) =
                PolarisedLayout::combinations(nch, &opts.combinations, &opts.combination_pairs);
            (Some(layout), c, p)
        } else {
            (
                None,
                opts.combinations.clone(),
                opts.combination_pairs.clone(),
            )
        };
        Ok(Plan {
            setup,
            fov_order,
            batches,
            per_batch,
            streams: rng::streams(opts.seed, Stream::Transport, batches),
            threads: opts.threads,
            progress: opts.progress,
            scale: lidar.pulse_energy_j * lidar.optical_efficiency * lidar.telescope_area_m2()
                / per_batch as f64,
            flux_scale: 1.0 / per_batch as f64,
            combinations,
            combination_pairs,
            combination_names: opts.combinations.iter().map(|c| c.name.clone()).collect(),
            polarised,
            channels: scene.channels.iter().map(|c| c.name.clone()).collect(),
            fov_full_angle_mrad: lidar.fov_full_angle_mrad.clone(),
            range_m: (0..scene.gates.count)
                .map(|i| scene.gates.centre_m(i))
                .collect(),
        })
    }

    /// Number of batches.
    pub fn batches(&self) -> usize {
        self.batches
    }

    /// Photons traced per batch.
    pub fn photons_per_batch(&self) -> u64 {
        self.per_batch
    }

    /// Values in one batch's tally buffer ([`BatchTally::bins`]): what a batch costs in memory
    /// and on the wire.
    pub fn tally_len(&self) -> usize {
        self.setup.shape.len()
    }

    /// Monochromatic channels of the run (the length of each part of [`BatchTally::flux`]).
    pub fn channels(&self) -> usize {
        self.channels.len()
    }

    /// Trace batch `index` from its own random stream: the same tallies on any thread, process
    /// or machine. `index` < [`Plan::batches`].
    pub fn trace_batch(&self, index: usize) -> BatchTally {
        self.trace_batch_with(index, &mut self.streams[index].clone())
    }

    fn trace_batch_with(&self, index: usize, rng: &mut rng::Rng) -> BatchTally {
        // One channel (single-wavelength cloud and aerosol studies): the tracer compiled for
        // it; the same numbers, faster.
        if self.setup.atm.n_channels == 1 {
            self.trace_batch_by::<true>(index, rng)
        } else {
            self.trace_batch_by::<false>(index, rng)
        }
    }

    fn trace_batch_by<const ONE_CHANNEL: bool>(
        &self,
        index: usize,
        rng: &mut rng::Rng,
    ) -> BatchTally {
        let mut tracer = photon::Tracer::<ONE_CHANNEL>::new(&self.setup);
        for _ in 0..self.per_batch {
            tracer.trace(rng);
        }
        BatchTally {
            index,
            bins: tracer.bins,
            flux: tracer.flux,
            stats: tracer.stats,
        }
    }

    /// An empty fold of this plan's batches.
    pub fn fold(&self) -> Fold<'_> {
        Fold {
            acc: Accumulator::new(
                self.setup.shape,
                self.channels.len(),
                self.fov_order.clone(),
            )
            .with_combinations(self.combinations.clone(), self.combination_pairs.clone()),
            plan: self,
            stats: RunStats::default(),
            next: 0,
        }
    }
}

/// Batches folded in order into running means and second moments.
pub struct Fold<'p> {
    plan: &'p Plan<'p>,
    acc: Accumulator,
    stats: RunStats,
    next: usize,
}

impl Fold<'_> {
    /// Index of the batch expected next.
    pub fn next_index(&self) -> usize {
        self.next
    }

    /// Fold the next batch. Batches must come in order, each once, with this plan's shape.
    pub fn add(&mut self, mut batch: BatchTally) -> Result<(), TransportError> {
        let shape = self.plan.setup.shape;
        let n = self.plan.channels.len();
        if batch.index != self.next {
            return Err(TransportError::Options(format!(
                "batch {} folded where batch {} was expected",
                batch.index, self.next
            )));
        }
        if batch.bins.len() != shape.len() || batch.flux.parts().iter().any(|p| p.len() != n) {
            return Err(TransportError::Options(format!(
                "batch {} has {} bins where the run has {}",
                batch.index,
                batch.bins.len(),
                shape.len()
            )));
        }
        let (scale, flux_scale) = (self.plan.scale, self.plan.flux_scale);
        batch.bins.iter_mut().for_each(|v| *v *= scale);
        for part in batch.flux.parts_mut() {
            part.iter_mut().for_each(|v| *v *= flux_scale);
        }
        self.acc.add_batch(&batch.bins, &batch.flux);
        self.stats.add(&batch.stats);
        self.next += 1;
        Ok(())
    }

    /// Means and standard errors once every batch is in; `wall_s` and `threads` describe how
    /// the batches were computed.
    pub fn finish(self, wall_s: f64, threads: usize) -> Result<McResult, TransportError> {
        let plan = self.plan;
        if self.next != plan.batches {
            return Err(TransportError::Options(format!(
                "{} of {} batches folded",
                self.next, plan.batches
            )));
        }
        // A polarised run's accumulator knows co as channels 0..n and cross as n..2n.
        let tally_names: Vec<String> = match &plan.polarised {
            None => plan.channels.clone(),
            Some(_) => ["co", "cross"]
                .iter()
                .flat_map(|p| plan.channels.iter().map(move |c| format!("{c} {p}")))
                .collect(),
        };
        let (returns, flux, flux_stderr, combined) = self.acc.finish(
            tally_names,
            plan.fov_full_angle_mrad.clone(),
            plan.range_m.clone(),
        );
        let (returns, combined, polarised) = match (&plan.polarised, combined) {
            (Some(l), Some(all)) => {
                let (n, m) = (l.n, l.m);
                let names = &plan.channels;
                let user = &plan.combination_names;
                let channels = Polarised {
                    co: channel_slice(&all, n, names),
                    cross: channel_slice(&all, 2 * n, names),
                    cov_j2: pair_covariances(&all, 0, n),
                };
                let (combined, combined_pol) = if m > 0 {
                    let mut totals = channel_slice(&all, 3 * n, user);
                    let pairs = &plan.combination_pairs[n + m..];
                    totals.covariance = Some(crate::returns::Covariance {
                        pairs: pairs.iter().map(|(a, b)| (a - 3 * n, b - 3 * n)).collect(),
                        cov_j2: pair_covariances(&all, n + m, pairs.len()),
                    });
                    let pol = Polarised {
                        co: channel_slice(&all, 3 * n + m, user),
                        cross: channel_slice(&all, 3 * n + 2 * m, user),
                        cov_j2: pair_covariances(&all, n, m),
                    };
                    (Some(totals), Some(pol))
                } else {
                    (None, None)
                };
                (
                    channel_slice(&all, 0, names),
                    combined,
                    Some(PolarisedMc {
                        channels,
                        combined: combined_pol,
                    }),
                )
            }
            (_, combined) => (returns, combined, None),
        };
        Ok(McResult {
            returns,
            combined,
            flux,
            flux_stderr,
            polarised,
            stats: self.stats,
            wall_s,
            photons: plan.per_batch * plan.batches as u64,
            threads,
        })
    }
}

/// Run the Monte Carlo transport of a scene through its optical atmosphere.
pub fn run(
    scene: &Scene,
    atm: &OpticalAtmosphere,
    opts: &TransportOptions,
) -> Result<McResult, TransportError> {
    run_plan(&Plan::new(scene, atm, opts)?)
}

/// Trace every batch of a plan on its thread pool and fold them in order.
pub fn run_plan(plan: &Plan) -> Result<McResult, TransportError> {
    let batches = plan.batches;
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(plan.threads)
        .build()
        .map_err(|e| TransportError::Threads(plan.threads, e.to_string()))?;
    let threads = pool.current_num_threads();

    let mut fold = plan.fold();
    let started = Instant::now();
    let bar = indicatif::ProgressBar::hidden();
    bar.set_length(batches as u64);
    bar.set_style(
        indicatif::ProgressStyle::with_template(
            "{spinner} transport {bar:40} {pos}/{len} batches, {elapsed} (eta {eta})",
        )
        .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
    );
    let show_bar = plan.progress && std::io::stderr().is_terminal();

    // Chunks keep at most a few batch buffers alive, and no more than the memory limit allows;
    // their size does not change the numbers.
    let chunk = (4 * threads)
        .min(crate::limits::MAX_LIVE_TALLY_VALUES / plan.setup.shape.len().max(1))
        .max(1);
    let mut start = 0;
    while start < batches {
        let end = (start + chunk).min(batches);
        let results: Vec<BatchTally> = pool.install(|| {
            (start..end)
                .into_par_iter()
                .map(|b| {
                    let t = plan.trace_batch(b);
                    bar.inc(1);
                    t
                })
                .collect()
        });
        for t in results {
            fold.add(t)?;
        }
        if show_bar && bar.is_hidden() && started.elapsed() > Duration::from_secs(1) {
            bar.set_draw_target(indicatif::ProgressDrawTarget::stderr());
        }
        start = end;
    }
    bar.finish_and_clear();
    fold.finish(started.elapsed().as_secs_f64(), threads)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::particles::phase::{HenyeyGreenstein, PhaseFunction};
    use crate::transport::testing::{CLOUD, edited, with_setup};

    /// [`CLOUD`]'s lidar with a second channel "b" at 1064 nm, over layers `(base_m, top_m)`
    /// of extinctions `[a, b]` km⁻¹ and HG asymmetries `[g_a, g_b]` in the two channels, no air.
    fn two_channel_scene(layers: &[(f64, f64)], ext: [f64; 2], g: [f64; 2]) -> String {
        let head = CLOUD.split("[[layer]]").next().unwrap_or_default();
        let mut text = edited(
            head,
            &[(
                "wavelength_nm = 1064.0\n",
                "wavelength_nm = 1064.0\n[[channel]]\nname = \"b\"\nwavelength_nm = 1064.0\n",
            )],
        );
        for (i, (base, top)) in layers.iter().enumerate() {
            text += &format!(
                "[[layer]]\nname = \"l{i}\"\nbase_m = {base}\ntop_m = {top}\n\
                 extinction_per_km = [{}, {}]\nsingle_scattering_albedo = 1.0\n\
                 phase = [{{ kind = \"henyey_greenstein\", g = {} }}, \
                 {{ kind = \"henyey_greenstein\", g = {} }}]\n",
                ext[0], ext[1], g[0], g[1]
            );
        }
        text
    }

    /// Where a collision lands (`Setup::altitude_at_tau`), by its documented rule at the ties:
    /// a target optical depth exactly on a layer edge is in the layer above going up (the last
    /// edge at or below it) and in the layer below going down (the last edge strictly below);
    /// at the column's very top it is in the top layer (capped), whatever layer the flight
    /// starts in (`hint`, checked first). Three layers of optical depth 0.5 (cumulative 0,
    /// 0.5, 1, 1.5), so every target is exact.
    #[test]
    fn collisions_on_layer_edges_land_by_the_documented_rule() {
        let three = [(1000.0, 2000.0), (2000.0, 3000.0), (3000.0, 4000.0)];
        with_setup(
            &two_channel_scene(&three, [0.5, 0.5], [0.5, 0.5]),
            |s, atm| {
                let cum = &s.classes[0].cum;
                let e = &atm.edges_m;
                let n = cum.len() - 1;
                assert_eq!(n, 3);
                for hint in [0, 1, 2, n] {
                    // Up from the bottom to edge 2: layer 2, at its base.
                    assert_eq!(
                        s.altitude_at_tau(0, cum[0], 1.0, cum[2], hint),
                        (e[2], 2),
                        "{hint}"
                    );
                    // Down from the top to edge 2: layer 1, at its top.
                    let tau = cum[n] - cum[2];
                    assert_eq!(
                        s.altitude_at_tau(0, cum[n], -1.0, tau, hint),
                        (e[2], 1),
                        "{hint}"
                    );
                    // Up to the very top: the top layer.
                    assert_eq!(
                        s.altitude_at_tau(0, cum[0], 1.0, cum[n], hint),
                        (e[n], n - 1),
                        "{hint}"
                    );
                }
            },
        );
    }

    /// Scattering classes by their documented rule (`scatter_classes`): two channels share one
    /// where the columns' scattering optical depths differ by at most 0.5 and, in every layer
    /// of optical depth above 0.1, every scatterer's coefficients are within a factor 2 and its
    /// phase functions within a factor 2 at every angle.
    #[test]
    fn scatter_classes_follow_their_rule() {
        let cloud = [(1000.0, 1300.0)];
        let three = [(1000.0, 1300.0), (1300.0, 1600.0), (1600.0, 1900.0)];
        // What, layers, extinctions [km⁻¹], asymmetries, the classes expected.
        type Case<'a> = (&'a str, &'a [(f64, f64)], [f64; 2], [f64; 2], Vec<usize>);
        let cases: [Case; 7] = [
            // τ 0.3 and 0.45: within a factor 2, alike.
            ("factor 1.5", &cloud, [1.0, 1.5], [0.5, 0.5], vec![0]),
            // τ 0.12 and 0.39: the columns are close, the coefficients not.
            ("factor 3.25", &cloud, [0.4, 1.3], [0.5, 0.5], vec![0, 1]),
            (
                "factor 3.25, the other way",
                &cloud,
                [1.3, 0.4],
                [0.5, 0.5],
                vec![0, 1],
            ),
            // τ 0.03 and 0.09: too thin for the coefficients to matter.
            ("thin, factor 3", &cloud, [0.1, 0.3], [0.5, 0.5], vec![0]),
            // P(0°) 6 against 190.
            ("g 0.5 and 0.9", &cloud, [1.0, 1.0], [0.5, 0.9], vec![0, 1]),
            // Columns 4.5 and 4.95 through three layers: each layer alike, the columns close.
            (
                "three layers, close",
                &three,
                [5.0, 5.5],
                [0.5, 0.5],
                vec![0],
            ),
            // Columns 4.5 and 5.13: each layer alike (factor 1.14), the columns 0.63 apart.
            (
                "three layers, apart",
                &three,
                [5.0, 5.7],
                [0.5, 0.5],
                vec![0, 1],
            ),
        ];
        for (what, layers, ext, g, expect) in cases {
            with_setup(&two_channel_scene(layers, ext, g), |_, atm| {
                assert!(!atm.grey_scattering, "{what}");
                assert_eq!(scatter_classes(atm), expect, "{what}");
            });
        }
    }

    /// Phase functions alike within a factor 2 at every angle: a table equal to isotropic
    /// scattering within 2× at 0° and 180° but 4× it at 90° is not alike (the scan must reach
    /// the angles between the poles); HG g = 0.5 and 0.55 are (their ratio stays in 0.72–1.32).
    #[test]
    fn similar_phase_looks_at_every_angle() {
        use crate::particles::phase::TabulatedPhase;
        let iso = PhaseFunction::Isotropic;
        let bump = PhaseFunction::Tabulated(Box::new(
            TabulatedPhase::from_angles(
                &[0.0, 80.0, 90.0, 100.0, 180.0],
                &[1.0, 1.0, 6.0, 1.0, 1.0],
            )
            .unwrap(),
        ));
        assert!(bump.eval(1.0) > 0.5 && bump.eval(-1.0) > 0.5 && bump.eval(0.0) > 2.0);
        assert!(!similar_phase(&iso, &bump));
        assert!(similar_phase(&iso, &iso));
        let hg = |g| PhaseFunction::HenyeyGreenstein(HenyeyGreenstein::new(g).unwrap());
        assert!(similar_phase(&hg(0.5), &hg(0.55)));
        assert!(!similar_phase(&hg(0.5), &hg(0.9)));
    }

    /// The forward half-width of Henyey-Greenstein phase functions against the closed form:
    /// P(Θ)/P(0) = [(1 − g)²/(1 + g² − 2g cos Θ)]^{3/2} = ½ at
    /// cos Θ = (1 + g² − 2^{2/3}(1 − g)²)/(2g); isotropic scattering never falls to half.
    #[test]
    fn forward_half_width_of_henyey_greenstein() {
        for g in [0.3, 0.5, 0.85, 0.95, 0.999] {
            let hg = PhaseFunction::HenyeyGreenstein(HenyeyGreenstein::new(g).unwrap());
            let exact =
                ((1.0 + g * g - 2f64.powf(2.0 / 3.0) * (1.0 - g) * (1.0 - g)) / (2.0 * g)).acos();
            let found = forward_half_width(|mu| hg.eval(mu));
            assert!(
                (found - exact).abs() < 1e-9 * exact.max(1.0) + 1e-12,
                "g {g}: {found} against {exact}"
            );
        }
        let flat = forward_half_width(|_| 1.0);
        assert_eq!(flat, std::f64::consts::PI);
    }

    /// The backward hemisphere's bound is at least the phase function's largest value there and
    /// close to it: for the C.1 droplet table, every tabulated angle from 90° to 180° (the glory
    /// at 180° included), at most 10 % above the largest (the bound adds the largest change
    /// between neighbouring points of its grid, 0.046 on the glory's flank against a largest
    /// value of 0.64); for HG g = 0.85 the value at 90°, (1 − g²)/(1 + g²)^{3/2}, where it
    /// decreases monotonically toward the back, within 1 %.
    #[test]
    fn backward_bound_holds_and_is_tight() {
        let table = crate::particles::builtin_table("bissonnette_c1_1064nm").unwrap();
        let c1 = PhaseFunction::Tabulated(Box::new(
            crate::particles::phase::TabulatedPhase::from_table(&table).unwrap(),
        ));
        let largest = table
            .theta_deg
            .iter()
            .filter(|t| **t >= 90.0)
            .map(|t| c1.eval(t.to_radians().cos().min(0.0)))
            .fold(0.0f64, f64::max);
        let bound = backward_max(|mu| c1.eval(mu));
        assert!(
            bound >= largest && bound <= 1.1 * largest,
            "{bound} against {largest}"
        );
        let g: f64 = 0.85;
        let hg = PhaseFunction::HenyeyGreenstein(HenyeyGreenstein::new(g).unwrap());
        let at_90 = (1.0 - g * g) / (1.0 + g * g).powf(1.5);
        let bound = backward_max(|mu| hg.eval(mu));
        assert!(
            bound >= at_90 && bound <= 1.01 * at_90,
            "{bound} against {at_90}"
        );
    }

    /// The tracer compiled for one channel is the general one with its per-channel loops
    /// unrolled: on one-channel scenes (a cloud seen from the ground with every estimator on,
    /// the same polarised, and a cloud over a reflecting surface seen from above) both give the
    /// same tallies and counters, bit for bit, batch by batch.
    #[test]
    fn one_channel_tracer_is_the_general_one() {
        let polarised = edited(
            CLOUD,
            &[(
                "fov_full_angle_mrad = [1.0]",
                "fov_full_angle_mrad = [1.0, 5.0]\npolarisation = \"linear\"",
            )],
        );
        let from_above = edited(
            CLOUD,
            &[
                ("altitude_m = 0.0", "altitude_m = 2000.0"),
                ("zenith_angle_deg = 0.0", "zenith_angle_deg = 180.0"),
            ],
        ) + "[surface]\naltitude_m = 0.0\nalbedo = 0.3\n";
        for text in [CLOUD.to_string(), polarised, from_above] {
            let scene = Scene::from_toml(std::path::Path::new("scene.toml"), &text).unwrap();
            let atm = OpticalAtmosphere::build(&scene).unwrap();
            let mut opts = TransportOptions::from_scene(&scene);
            opts.photons = 6000;
            opts.batches = 3;
            let plan = Plan::new(&scene, &atm, &opts).unwrap();
            assert_eq!(plan.setup.atm.n_channels, 1);
            // Copies made by splitting follow the copy paths too.
            let (mut splits, mut reflections) = (0, 0);
            for index in 0..plan.batches() {
                let one = plan.trace_batch_by::<true>(index, &mut plan.streams[index].clone());
                let any = plan.trace_batch_by::<false>(index, &mut plan.streams[index].clone());
                assert!(one.stats.collisions > 0);
                splits += one.stats.splits;
                reflections += one.stats.surface_reflections;
                assert_eq!(one, any, "batch {index} of\n{text}");
            }
            assert!(splits > 0);
            assert_eq!(reflections > 0, text.contains("[surface]"));
        }
    }
}
