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
mod fold;
mod index;
mod jacobian;
pub(crate) mod lanes;
mod photon;
mod plan;
mod setup;
mod stokes;
mod tally;
#[cfg(test)]
mod testing;

use std::time::Instant;

use glam::DVec3;
use rayon::prelude::*;
use thiserror::Error;

use crate::aperture::{self, Aperture};
use crate::optics::OpticalAtmosphere;
use crate::particles::matrix::{MatrixElements, ScatteringMatrix};
use crate::returns::{Combination, Returns};
use crate::rng::{self, Stream};
use crate::scene::{BeamProfile, Polarisation, Scene};

pub use fold::Fold;
use fold::PolarisedLayout;
pub use jacobian::{JacobianQuantity, Jacobians};
pub use plan::{BatchTally, Plan, STOP_CHECK_PHOTONS};
pub(crate) use setup::Setup;
pub use tally::Flux;
use tally::{Accumulator, TallyShape};

pub use crate::scene::{
    ALIGNMENT_SPLITTING, DDIS_EPSILON, RANGE_STRATIFICATION, ROULETTE_ALIGNMENT, VarianceReduction,
};
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

/// What the transport tallies besides the returns of the scene's channels, fields of view,
/// gates and orders: the layout of its tallies. How it runs (photons, seed, batches, threads,
/// orders, variance reduction) is the scene's [`Simulation`](crate::scene::Simulation).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct TallyLayout {
    /// Also tally the energy leaving the scene and absorbed in it (costs a layer walk per
    /// flight).
    pub flux: bool,
    /// Linear combinations of channels to report as well (laser lines from their quadrature
    /// nodes), folded batch by batch so that their standard errors are right.
    pub combinations: Vec<Combination>,
    /// Pairs (a, b), a < b, of `combinations` whose covariance is folded too (the on- and
    /// off-line returns); only these, as their number grows with the square of the lines.
    pub combination_pairs: Vec<(usize, usize)>,
}

/// A caller's report of progress: batches folded, of all the run's ([`run_plan`]). Called from
/// the thread that folds, after each chunk of batches; the command line draws a bar with it.
pub type Progress<'a> = &'a dyn Fn(usize, usize);

/// A [`Progress`] that reports nothing.
pub fn quiet(_done: usize, _total: usize) {}

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
    /// The run was stopped before its end ([`Plan::stop_when`]).
    #[error("the run was stopped before its end")]
    Stopped,
}

/// What a transport run produces.
#[derive(Debug, Clone)]
pub struct McResult {
    /// Received energy by channel, FOV, gate and order, with standard errors.
    pub returns: Returns,
    /// The combined channels of [`TallyLayout::combinations`], with standard errors and the
    /// covariances of [`TallyLayout::combination_pairs`] (`None` without combinations).
    pub combined: Option<Returns>,
    /// Energy leaving the scene per channel, as a fraction of the emitted energy (zero unless
    /// the flux tally was on).
    pub flux: Flux,
    /// Standard errors of `flux`.
    pub flux_stderr: Flux,
    /// Co- and cross-polarised returns, when the lidar's light is polarised.
    pub polarised: Option<PolarisedMc>,
    /// Derivatives of the returns with respect to the layers' properties, when the scene
    /// asks for them (`[simulation] jacobians`).
    pub jacobians: Option<Jacobians>,
    /// The same for the combinations of [`TallyLayout::combinations`] (the laser lines).
    pub jacobians_combined: Option<Jacobians>,
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
    /// The combinations of [`TallyLayout::combinations`], if any.
    pub combined: Option<Polarised>,
}

/// Run the Monte Carlo transport of a scene (its settings: `scene.simulation`) through its
/// optical atmosphere, tallying `layout`, quietly.
pub fn run(
    scene: &Scene,
    atm: &OpticalAtmosphere,
    layout: &TallyLayout,
) -> Result<McResult, TransportError> {
    run_plan(&Plan::new(scene, atm, layout)?, &quiet)
}

/// Trace every batch of a plan on its thread pool and fold them in order, reporting the
/// batches folded to `progress`.
pub fn run_plan(plan: &Plan, progress: Progress) -> Result<McResult, TransportError> {
    let batches = plan.batches;
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(plan.threads)
        .build()
        .map_err(|e| TransportError::Threads(plan.threads, e.to_string()))?;
    let threads = pool.current_num_threads();

    let mut fold = plan.fold();
    let started = Instant::now();
    // Chunks keep at most a few batch buffers alive, and no more than the memory limit allows;
    // their size does not change the numbers.
    let per_batch = plan.setup.shape.len()
        + plan
            .setup
            .jac
            .as_ref()
            .map_or(0, |j| j.len(&plan.setup.shape));
    let chunk = (4 * threads)
        .min(crate::limits::MAX_LIVE_TALLY_VALUES / per_batch.max(1))
        .max(1);
    let mut start = 0;
    while start < batches {
        let end = (start + chunk).min(batches);
        let results: Vec<BatchTally> = pool.install(|| {
            (start..end)
                .into_par_iter()
                .map(|b| plan.trace_batch(b))
                .collect()
        });
        if plan.stopped() {
            return Err(TransportError::Stopped);
        }
        for t in results {
            fold.add(t)?;
        }
        start = end;
        progress(start, batches);
    }
    fold.finish(started.elapsed().as_secs_f64(), threads)
}

#[cfg(test)]
mod tests;
