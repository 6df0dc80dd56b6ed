//! A scene from end to end: the stages of DESIGN §1 in order, as `lidarsim run` calls them.
//!
//! optics → analytic lidar equation → (retrieval set-up: fails before any photon is traced) →
//! Monte Carlo → line returns → signals → retrievals. Each step is a plain call of its stage;
//! a batch over many profiles can call the same stages directly.

use thiserror::Error;

use crate::input::InputError;
use crate::instrument::laser::LineReturns;
use crate::instrument::signals::{Signals, Telescope};
use crate::lidar_eq;
use crate::optics::{OpticalAtmosphere, OpticsError};
use crate::retrieval::{
    AssumedInstrument, LayerColumns, Method, Product, Quantity, ReferenceState, Retrieval,
    RetrievalError,
};
use crate::returns::{Order, Returns, Source};
use crate::scene::Scene;
use crate::transport::{self, McResult, TransportError, TransportOptions};

/// Everything a run of a scene produces.
#[derive(Debug, Clone)]
pub struct RunOutput {
    /// The optical atmosphere.
    pub atmosphere: OpticalAtmosphere,
    /// Analytic single scattering of every monochromatic channel.
    pub analytic: Returns,
    /// The same combined into line returns.
    pub analytic_lines: LineReturns,
    /// The Monte Carlo run, if it ran (channels, and lines in `combined`).
    pub mc: Option<McResult>,
    /// Whether the Monte Carlo ran, and why ([`crate::skip`]).
    pub monte_carlo: crate::skip::Decision,
    /// Monte Carlo line returns.
    pub mc_lines: Option<LineReturns>,
    /// Signals of each set of returns (analytic order 1; Monte Carlo order 1 and all orders),
    /// if the scene has a receiver.
    pub signals: Vec<Signals>,
    /// The retrieval set-up, if the scene asks for one.
    pub retrieval: Option<Retrieval>,
    /// Retrieved products, for every set of signals and field of view.
    pub products: Vec<Product>,
    /// Co- and cross-polarised line returns, when the lidar's light is polarised.
    pub polarised: Option<PolarisedLines>,
}

/// The co- and cross-polarised parts of the line returns of a run with polarised light.
#[derive(Debug, Clone)]
pub struct PolarisedLines {
    /// Analytic single scattering: co, cross.
    pub analytic: (Returns, Returns),
    /// Monte Carlo, if it ran: co, cross and the covariance of their means \[J²\] bin by bin
    /// ([`Returns::index`]).
    pub mc: Option<(Returns, Returns, Vec<f64>)>,
}

impl RunOutput {
    /// The products of one method and quantity retrieved from one set of returns and field of
    /// view (IPDA: one; DIAL: one per cell, nearest the lidar first).
    pub fn products_of(
        &self,
        method: Method,
        quantity: Quantity,
        source: Source,
        order: Order,
        fov_full_angle_mrad: f64,
    ) -> Vec<&Product> {
        self.products
            .iter()
            .filter(|p| {
                p.method == method
                    && p.quantity == quantity
                    && p.source == source
                    && p.order == order
                    && p.fov_full_angle_mrad == fov_full_angle_mrad
            })
            .collect()
    }
}

/// Why a run failed.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum RunError {
    /// Building the optical atmosphere failed.
    #[error(transparent)]
    Optics(#[from] OpticsError),
    /// The transport failed.
    #[error(transparent)]
    Transport(#[from] TransportError),
    /// A problem with the scene found while running (named by file, line and key).
    #[error(transparent)]
    Input(#[from] InputError),
}

/// Run every stage of `scene`; `transport` says how to run the Monte Carlo (0 photons: the
/// analytic lidar equation only), and [`crate::skip::decide`] whether it runs at all (the
/// scene's `multiple_scattering`). Its `combinations` and `combination_pairs` are set here from
/// the scene's laser.
pub fn run(scene: &Scene, transport: &TransportOptions) -> Result<RunOutput, RunError> {
    run_with(scene, transport, &mut |plan| transport::run_plan(plan))
}

/// [`run`], with the Monte Carlo's batches computed by `monte_carlo` from the validated plan:
/// all on this machine's threads ([`transport::run_plan`]), folded from shard files, or spread
/// over MPI ranks. Everything before and after the transport is the same.
pub fn run_with(
    scene: &Scene,
    transport: &TransportOptions,
    monte_carlo: &mut dyn FnMut(&transport::Plan) -> Result<McResult, TransportError>,
) -> Result<RunOutput, RunError> {
    let atmosphere = OpticalAtmosphere::build(scene)?;
    let analytic = lidar_eq::single_scatter(scene, &atmosphere);
    let analytic_lines = scene.sampling.combine(&analytic);
    let retrieval = match &scene.retrieval {
        Some(_) => Some(retrieval_setup(scene).map_err(|e| retrieval_error(scene, e))?),
        None => None,
    };
    let mut signals = Vec::new();
    let mut products = Vec::new();
    // The analytic returns first: a retrieval that cannot be done fails before the Monte Carlo.
    collect(
        scene,
        retrieval.as_ref(),
        &analytic_lines,
        Order::Exactly(1),
        &mut signals,
        &mut products,
    )?;
    let decision = crate::skip::decide(scene, &atmosphere, transport.photons);
    let (mc, mc_lines) = if decision.run {
        // Refused in milliseconds when the tracing would run for months (README, "Limits").
        let work = monte_carlo_work(scene, &atmosphere, transport.photons);
        work.check()
            .map_err(|m| RunError::Input(scene.input_error("simulation", "photons", m)))?;
        if let Some(note) = work.warning() {
            crate::limits::warn(&scene.input_error("simulation", "photons", note).to_string());
        }
        let opts = plan_options(scene, transport);
        let mc = monte_carlo(&transport::Plan::new(scene, &atmosphere, &opts)?)?;
        let lines = mc.combined.as_ref().map(|c| scene.sampling.split(c));
        (Some(mc), lines)
    } else {
        (None, None)
    };
    if let Some(lines) = &mc_lines {
        for order in [Order::Exactly(1), Order::Total] {
            collect(
                scene,
                retrieval.as_ref(),
                lines,
                order,
                &mut signals,
                &mut products,
            )?;
        }
    }
    let polarised = lidar_eq::single_scatter_polarised(scene, &atmosphere).map(|(co, cross)| {
        let lines = |r: &Returns| scene.sampling.combine(r).mean;
        let n = scene.sampling.lines.len();
        let first: Vec<usize> = (0..n).collect();
        PolarisedLines {
            analytic: (lines(&co), lines(&cross)),
            mc: mc
                .as_ref()
                .and_then(|m| m.polarised.as_ref())
                .and_then(|p| p.combined.as_ref())
                .map(|c| {
                    let b = c.co.bins_per_channel();
                    (
                        c.co.channel_subset(&first),
                        c.cross.channel_subset(&first),
                        c.cov_j2[..n * b].to_vec(),
                    )
                }),
        }
    });
    Ok(RunOutput {
        atmosphere,
        analytic,
        analytic_lines,
        mc,
        monte_carlo: decision,
        mc_lines,
        signals,
        retrieval,
        products,
        polarised,
    })
}

/// The transport options a run of `scene` plans with: `transport` with the scene's line
/// combinations and the pairs whose covariance is folded. The one place they are set, so that a
/// run, a shard ([`crate::shard`]) and a merge of shards build the same plan.
pub fn plan_options(scene: &Scene, transport: &TransportOptions) -> TransportOptions {
    let mut opts = transport.clone();
    opts.combinations = scene.sampling.combinations();
    opts.combination_pairs = scene.sampling.covariance_pairs();
    opts
}

/// Signals of one set of line returns, and the retrievals from them.
fn collect(
    scene: &Scene,
    retrieval: Option<&Retrieval>,
    lines: &LineReturns,
    order: Order,
    signals: &mut Vec<Signals>,
    products: &mut Vec<Product>,
) -> Result<(), RunError> {
    let Some(receiver) = &scene.receiver else {
        return Ok(());
    };
    let telescope = Telescope {
        area_m2: scene.lidar.telescope_area_m2(),
        optical_efficiency: scene.lidar.optical_efficiency,
    };
    let Some(s) = Signals::new(
        lines,
        order,
        &scene.sampling.lines,
        receiver,
        telescope,
        scene.gates.width_m,
    ) else {
        return Ok(());
    };
    if let Some(r) = retrieval {
        for fov in 0..s.fov_full_angle_mrad.len() {
            products.extend(
                r.retrieve(lines, &s, fov)
                    .map_err(|e| retrieval_error(scene, e))?,
            );
        }
    }
    signals.push(s);
    Ok(())
}

/// The retrieval of a scene: its own profile as the reference state and as the truth, on the
/// molecular grid its gas absorption was computed on.
pub fn retrieval_setup(scene: &Scene) -> Result<Retrieval, RetrievalError> {
    let config = scene
        .retrieval
        .clone()
        .ok_or_else(|| RetrievalError::Gas("the scene has no [retrieval]".into()))?;
    let (Some(atm), Some(gas), Some(edges)) =
        (&scene.atmosphere, &scene.gas, scene.molecular_edges())
    else {
        return Err(RetrievalError::Gas(
            "a retrieval needs an atmosphere with gas absorption".into(),
        ));
    };
    let filter = scene
        .receiver
        .as_ref()
        .map(|r| r.filter)
        .unwrap_or(crate::instrument::laser::Filter::none());
    let (lines, options) = config.assumed(&gas.lines, &gas.options);
    let reference = ReferenceState::new(
        &atm.profile,
        &edges,
        &config.gas,
        lines,
        &options,
        AssumedInstrument {
            laser: &scene.laser,
            lines: &scene.sampling.lines,
            filter: &filter,
        },
    )?;
    let truth = LayerColumns::new(&atm.profile, &edges, &config.gas)?;
    let pair = format!(
        "{}/{}",
        scene.sampling.lines[config.on].name, scene.sampling.lines[config.off].name
    );
    let range_m = (0..scene.gates.count)
        .map(|g| scene.gates.centre_m(g))
        .collect();
    Retrieval::new(
        config,
        scene.laser.clone(),
        reference,
        truth,
        scene.lidar.altitude_m,
        scene.lidar.axis().z,
        range_m,
        pair,
        scene.simulation.seed,
    )
}

/// A retrieval problem as an error at the scene key a user should change.
fn retrieval_error(scene: &Scene, e: RetrievalError) -> RunError {
    let (section, key) = e.scene_key();
    RunError::Input(scene.input_error(section, key, e.to_string()))
}

/// The expected cost of a scene's Monte Carlo, estimated from its optics before any photon is
/// traced (README, "Limits"): photons × scattering events per photon × channels (every event
/// updates every channel's weight and scores a local estimate for each).
///
/// Events per photon (scatterings and surface reflections, split copies' included) are
/// estimated as `1.25 · min(τ_path, 5/(−ln ϖ_max)) + 4`:
/// * `τ_path`: the largest scattering optical depth a path can gather before no gate can
///   receive the photon (the transport cuts it there: path + return leg ≤ 2 r_end). A path
///   reaches a layer after at least the distance d from the receiver to the layer's slab and
///   must still be able to come back that far, so it spends at most 2 (r_end − d) in it, and at
///   most 2 (r_end − d_min) in all; the most scattering layers fill that budget first. Without
///   variance reduction a photon's expected number of scatterings is ∫σ_s ds ≤ `τ_path`; the
///   forced collisions, roulette and splitting of the transport change the count, not the
///   weight that reaches each event.
/// * `5/(−ln ϖ_max)`: with absorption every collision multiplies the weights by at most the
///   largest single-scattering albedo ϖ_max (gas absorption included), and Russian roulette
///   ends a photon whose weight has fallen below 1e-2 (ln 100 ≈ 4.6 collisions per e-fold,
///   plus its survivors' tail).
/// * `× 1.25`: the copies that splitting makes share the path left to the photon they come
///   from, and add their own events: up to 6 % more than `τ_path` where photons use their
///   whole path (I3RC case 7, experiment 2: a semi-infinite conservative cloud, 122–127 events
///   per photon against `τ_path` = 120).
/// * `+ 4`: the forced collisions of optically thin flights (each flight that can scatter ends
///   in one, at a weight 1 − e^{−τ}; in layers of optical depth about 1 they add up to 3 events
///   to ∫σ_s ds) and the surface reflections.
///
/// Measured against the counts of the transport on the shipped scenes, the validation scenes
/// (polarisation, I3RC case 7, Platt) and extremes (C.1 × 0.01 to × 10 and with gates to 10 km,
/// isotropic and g = 0.85 to 0.99 layers of optical depth 0.3 to 30, albedos 0.5 to 1, an
/// albedo-1 surface under and above clouds; 57 scenes, 10⁴ photons each): the count lies
/// between 0.03 and 0.83 times the estimate (`tests/validation_inputs.rs` checks ten of them).
/// `max_order` does not enter: orders above it are tallied together, not cut. Not covered: the
/// cost of detector-directed sampling and splitting on phase functions with a strong backward
/// peak (issue 37).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct McWork {
    /// Photon packets.
    pub photons: u64,
    /// Monochromatic channels traced.
    pub channels: usize,
    /// The largest scattering optical depth a photon's path can gather (`τ_path`).
    pub tau_path: f64,
    /// Largest single-scattering albedo of any layer and channel (gas absorption included).
    pub albedo_max: f64,
    /// Scattering events per photon, estimated.
    pub events_per_photon: f64,
}

impl McWork {
    /// photons × events per photon × channels \[channel-events\].
    pub fn work(&self) -> f64 {
        self.photons as f64 * self.events_per_photon * self.channels as f64
    }

    /// The factors of the work, for messages.
    fn factors(&self) -> String {
        format!(
            "{} photons × {:.1} scattering events per photon (estimated from the scattering optical depth {:.3} along the longest path that can still reach the last gate and the largest single-scattering albedo {:.6}) × {} channel{}",
            crate::input::fmt_bound(self.photons as f64),
            self.events_per_photon,
            self.tau_path,
            self.albedo_max,
            self.channels,
            if self.channels == 1 { "" } else { "s" },
        )
    }

    fn describe(&self) -> String {
        format!(
            "{} = {:.2e} channel-events, up to about {} on one core",
            self.factors(),
            self.work(),
            crate::limits::fmt_seconds(self.work() * crate::limits::MC_SECONDS_PER_WORK),
        )
    }

    /// Ok within [`crate::limits::MAX_MC_WORK`], else the message naming the product and the
    /// limit.
    pub fn check(&self) -> Result<(), String> {
        use crate::limits::{MAX_MC_WORK, MC_SECONDS_PER_WORK, fmt_seconds};
        if self.work() <= MAX_MC_WORK {
            return Ok(());
        }
        Err(format!(
            "Monte Carlo work: {}, more than the limit of {:e} (about {}; README, \"Limits\"): fewer photons, or gates that end sooner",
            self.describe(),
            MAX_MC_WORK,
            fmt_seconds(MAX_MC_WORK * MC_SECONDS_PER_WORK)
        ))
    }

    /// A note when the work is allowed but long (above [`crate::limits::MC_WORK_WARN`]).
    pub fn warning(&self) -> Option<String> {
        (self.work() > crate::limits::MC_WORK_WARN)
            .then(|| format!("Monte Carlo work: {}", self.describe()))
    }
}

/// [`McWork`] of `photons` packets of `scene` through `atm`: milliseconds, from the layers'
/// coefficients and the geometry alone.
pub fn monte_carlo_work(scene: &Scene, atm: &OpticalAtmosphere, photons: u64) -> McWork {
    let nch = atm.n_channels;
    let z_rx = scene.lidar.altitude_m;
    let r_end = scene.gates.end_m();
    // Per layer: its largest scattering coefficient over the channels and the longest path a
    // photon can spend in it (type documentation).
    let mut layers: Vec<(f64, f64)> = Vec::new(); // (σ_s, longest path)
    let mut albedo_max: f64 = 0.0;
    for l in 0..atm.n_layers() {
        let (a, b) = (atm.edges_m[l], atm.edges_m[l + 1]);
        let d = (a - z_rx).max(z_rx - b).max(0.0);
        let mut sigma: f64 = 0.0;
        for k in 0..nch {
            let (s, ab) = (
                atm.sigma_s_per_m[l * nch + k],
                atm.sigma_a_per_m[l * nch + k],
            );
            if s > 0.0 {
                sigma = sigma.max(s);
                albedo_max = albedo_max.max(s / (s + ab));
            }
        }
        let reach = 2.0 * (r_end - d);
        if sigma > 0.0 && reach > 0.0 {
            layers.push((sigma, reach));
        }
    }
    let mut budget = layers.iter().map(|l| l.1).fold(0.0f64, f64::max);
    layers.sort_by(|x, y| y.0.total_cmp(&x.0));
    let mut tau_path = 0.0;
    for (sigma, reach) in &layers {
        let take = reach.min(budget);
        tau_path += sigma * take;
        budget -= take;
    }
    // Collisions until absorption alone takes the weights below the roulette's 1e-2, and the
    // tail of its survivors: 5 per e-fold (infinite without absorption).
    let absorbed = if albedo_max < 1.0 {
        5.0 / -albedo_max.ln()
    } else {
        f64::INFINITY
    };
    McWork {
        photons,
        channels: nch,
        tau_path,
        albedo_max,
        events_per_photon: 1.25 * tau_path.min(absorbed) + 4.0,
    }
}

/// The cost of a study that runs a scene's stages for many atmospheric profiles (`lidarsim
/// dial`, `lidarsim bench --study`), estimated before the first profile (README, "Limits").
///
/// Per profile the study computes line by line three truths at every channel and five
/// reference states at every line-shape node (`docs/retrieval.md`): at most 8 × channels ×
/// molecular layers × gas lines line evaluations (each line reaching every channel is the bound;
/// the lines are already cut to the channels' window and wing), and with photons it traces each
/// of the three truths ([`McWork`] of the scene's own profile for each).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StudyWork {
    /// Profile runs: profiles × repetitions.
    pub profile_runs: u64,
    /// Monochromatic channels.
    pub channels: usize,
    /// Molecular layers.
    pub layers: usize,
    /// Gas lines (cut to the channels' window and wing).
    pub gas_lines: usize,
    /// The Monte Carlo of one truth, if the study traces photons.
    pub mc: Option<McWork>,
}

/// Truths and reference states computed line by line per profile, and truths traced.
const STUDY_LBL_STATES: u64 = 8;
const STUDY_TRACED_TRUTHS: u64 = 3;

impl StudyWork {
    /// Line evaluations of the whole study.
    pub fn line_evaluations(&self) -> f64 {
        self.profile_runs as f64
            * (STUDY_LBL_STATES as f64)
            * self.channels as f64
            * self.layers as f64
            * self.gas_lines as f64
    }

    /// Monte Carlo work of the whole study \[channel-events\].
    pub fn mc_work(&self) -> f64 {
        self.mc.map_or(0.0, |m| {
            m.work() * (self.profile_runs * STUDY_TRACED_TRUTHS) as f64
        })
    }

    fn describe_lbl(&self) -> String {
        format!(
            "{} profile runs × {STUDY_LBL_STATES} states (3 truths, 5 reference states) × {} channels × {} molecular layers × {} gas lines = {:.2e} line evaluations, up to about {} on one core",
            self.profile_runs,
            self.channels,
            self.layers,
            self.gas_lines,
            self.line_evaluations(),
            crate::limits::fmt_seconds(
                self.line_evaluations() * crate::limits::STUDY_SECONDS_PER_EVALUATION
            )
        )
    }

    fn describe_mc(&self) -> String {
        format!(
            "{} profile runs × {STUDY_TRACED_TRUTHS} truths traced × {}",
            self.profile_runs,
            self.mc.map_or(String::new(), |m| m.factors())
        )
    }

    /// Ok within the limits of study and Monte Carlo work, else the message naming the
    /// product and the limit.
    pub fn check(&self) -> Result<(), String> {
        use crate::limits::{
            MAX_MC_WORK, MAX_STUDY_WORK, MC_SECONDS_PER_WORK, STUDY_SECONDS_PER_EVALUATION,
            fmt_seconds,
        };
        if self.line_evaluations() > MAX_STUDY_WORK {
            return Err(format!(
                "study work: {}, more than the limit of {MAX_STUDY_WORK:e} (about {}; README, \"Limits\")",
                self.describe_lbl(),
                fmt_seconds(MAX_STUDY_WORK * STUDY_SECONDS_PER_EVALUATION)
            ));
        }
        if self.mc_work() > MAX_MC_WORK {
            return Err(format!(
                "study Monte Carlo work: {} = {:.2e} channel-events, more than the limit of {MAX_MC_WORK:e} (about {}; README, \"Limits\"): fewer profiles or photons",
                self.describe_mc(),
                self.mc_work(),
                fmt_seconds(MAX_MC_WORK * MC_SECONDS_PER_WORK)
            ));
        }
        Ok(())
    }

    /// Notes when the study is allowed but long (above [`crate::limits::STUDY_WORK_WARN`] or
    /// [`crate::limits::MC_WORK_WARN`]).
    pub fn warnings(&self) -> Vec<String> {
        let mut v = Vec::new();
        if self.line_evaluations() > crate::limits::STUDY_WORK_WARN {
            v.push(format!("study work: {}", self.describe_lbl()));
        }
        if self.mc_work() > crate::limits::MC_WORK_WARN {
            v.push(format!(
                "study Monte Carlo work: {} = {:.2e} channel-events, up to about {} on one core",
                self.describe_mc(),
                self.mc_work(),
                crate::limits::fmt_seconds(self.mc_work() * crate::limits::MC_SECONDS_PER_WORK)
            ));
        }
        v
    }
}

/// [`StudyWork`] of `profile_runs` runs of `scene`'s stages, tracing `photons` per truth (0:
/// the analytic equation only). Builds the scene's own optics once (its line-by-line
/// absorption: about one profile's share of the work).
pub fn study_work(
    scene: &Scene,
    profile_runs: u64,
    photons: u64,
) -> Result<StudyWork, OpticsError> {
    let mc = if photons > 0 {
        let atm = OpticalAtmosphere::build(scene)?;
        Some(monte_carlo_work(scene, &atm, photons))
    } else {
        None
    };
    Ok(StudyWork {
        profile_runs,
        channels: scene.channels.len(),
        layers: scene
            .molecular_edges()
            .map_or(0, |e| e.len().saturating_sub(1)),
        gas_lines: scene.gas.as_ref().map_or(0, |g| g.lines.lines.len()),
        mc,
    })
}
