//! A scene from end to end: the stages of docs/design.md §1 in order, the one path every command takes.
//!
//! [`prepare`] (optics → analytic lidar equation → retrieval set-up and the analytic
//! retrievals, so that a retrieval that cannot be done fails before any photon is traced → the
//! skip decision) → trace the batches of [`Prepared::plan`] anywhere (threads, shards, MPI
//! ranks) → [`Prepared::finish`] (line returns → signals → retrievals). [`run`] is the three on
//! this machine; `lidarsim run`, `--shard`, `merge`, MPI runs and the studies all go through
//! them. A study over many profiles calls the pieces it needs per truth: [`trace_lines`],
//! [`signals_of`], [`retrieval_of`].

use std::sync::atomic::AtomicBool;

use thiserror::Error;

use crate::input::InputError;
use crate::instrument::laser::LineReturns;
use crate::instrument::signals::{Signals, Telescope};
use crate::lidar_eq;
use crate::optics::{OpticalAtmosphere, OpticsError};
use crate::retrieval::{
    AssumedInstrument, Geometry, LayerColumns, Method, Product, Quantity, ReferenceState,
    Retrieval, RetrievalConfig, RetrievalError,
};
use crate::returns::{Order, Returns, Source};
use crate::scene::Scene;
use crate::transport::{self, McResult, Progress, TallyLayout, TransportError};

mod compare;
pub mod skip;
mod work;

pub use compare::{Comparison, compare_skip};
pub use work::{McWork, StudyWork, monte_carlo_work, study_work};

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
    pub monte_carlo: skip::Decision,
    /// Monte Carlo line returns.
    pub mc_lines: Option<LineReturns>,
    /// Signals of each set of returns (analytic order 1; Monte Carlo order 1 and all orders),
    /// if the scene has a receiver.
    pub signals: Vec<Signals>,
    /// The retrieval set-up, if the scene asks for one.
    pub retrieval: Option<Retrieval>,
    /// Retrieved products, for every set of signals and field of view.
    pub products: Vec<Product>,
    /// The weighting functions of the Monte Carlo products, single-scatter (order 1) and
    /// aware of multiple scattering (total), when the scene asks for Jacobians.
    pub weighting: Vec<crate::retrieval::Weighting>,
    /// Co- and cross-polarised line returns, when the lidar's light is polarised.
    pub polarised: Option<PolarisedLines>,
    /// The scene's warnings and the run's own (an on-line whose signal-to-noise ratio per shot
    /// is below 1), each `FILE:LINE: key: …` ([`crate::scene::warnings`]); the command line
    /// prints them once and the run's summary records them.
    pub warnings: Vec<String>,
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

/// A scene prepared for its Monte Carlo: everything of a run before the first photon.
///
/// [`prepare`] builds the optics, the analytic returns, the retrieval set-up and the
/// retrievals of the analytic returns (a retrieval that cannot be done fails here, before any
/// photon is traced), and decides whether the Monte Carlo runs ([`crate::skip`]). The caller
/// then traces the batches of [`Prepared::plan`] however it likes — all on this machine's
/// threads ([`transport::run_plan`]), one shard of them ([`crate::shard`]), folded from shard
/// files, or spread over MPI ranks ([`crate::distributed`]) — and hands the folded result to
/// [`Prepared::finish`], which makes the signals, retrievals and products. [`run`] does all
/// three on this machine.
#[derive(Debug)]
pub struct Prepared<'s> {
    scene: &'s Scene,
    layout: TallyLayout,
    atmosphere: OpticalAtmosphere,
    analytic: Returns,
    analytic_lines: LineReturns,
    retrieval: Option<Retrieval>,
    decision: skip::Decision,
    warning: Option<String>,
    /// Signals and products of the analytic returns.
    signals: Vec<Signals>,
    products: Vec<Product>,
}

/// Everything of a run of `scene` before its Monte Carlo ([`Prepared`]); its settings
/// (`scene.simulation`) say how the Monte Carlo would run (0 photons: the analytic lidar
/// equation only).
pub fn prepare(scene: &Scene) -> Result<Prepared<'_>, RunError> {
    let photons = scene.simulation.photons;
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
    let decision = skip::decide_with(
        scene,
        &atmosphere,
        photons,
        Some(skip::Analytic {
            returns: &analytic,
            lines: &analytic_lines,
            retrieval: retrieval.as_ref(),
        }),
    );
    // A Monte Carlo that would run for months is refused here, in milliseconds (README,
    // "Limits").
    let mut warning = None;
    if decision.run {
        let work = monte_carlo_work(scene, &atmosphere, photons);
        work.check()
            .map_err(|m| RunError::Input(scene.input_error("simulation", "photons", m)))?;
        warning = work
            .warning()
            .map(|note| scene.input_error("simulation", "photons", note).to_string());
    }
    Ok(Prepared {
        scene,
        layout: tally_layout(scene),
        atmosphere,
        analytic,
        analytic_lines,
        retrieval,
        decision,
        warning,
        signals,
        products,
    })
}

impl<'s> Prepared<'s> {
    /// The scene.
    pub fn scene(&self) -> &'s Scene {
        self.scene
    }

    /// The optical atmosphere.
    pub fn atmosphere(&self) -> &OpticalAtmosphere {
        &self.atmosphere
    }

    /// Whether the Monte Carlo runs, and why.
    pub fn decision(&self) -> &skip::Decision {
        &self.decision
    }

    /// The layout of the Monte Carlo's tallies ([`tally_layout`]).
    pub fn layout(&self) -> &TallyLayout {
        &self.layout
    }

    /// A note for the user when the Monte Carlo is allowed but long (README, "Limits"), named
    /// at the scene's `simulation.photons`; the caller prints it ([`crate::limits::warn`]).
    pub fn warning(&self) -> Option<String> {
        self.warning.clone()
    }

    /// The Monte Carlo's validated plan, or `None` when the scene runs no Monte Carlo (0
    /// photons, or [`crate::skip`] decided it cannot change the answer).
    pub fn plan(&self) -> Result<Option<transport::Plan<'_>>, RunError> {
        if !self.decision.run {
            return Ok(None);
        }
        Ok(Some(transport::Plan::new(
            self.scene,
            &self.atmosphere,
            &self.layout,
        )?))
    }

    /// The Monte Carlo traced on this machine, on `scene.simulation.threads` threads
    /// ([`transport::run_plan`]), reporting the batches folded to `progress`; `None` when the
    /// scene runs none.
    pub fn trace(&self, progress: Progress) -> Result<Option<McResult>, RunError> {
        match self.plan()? {
            Some(plan) => Ok(Some(transport::run_plan(&plan, progress)?)),
            None => Ok(None),
        }
    }

    /// [`Self::trace`], stopping soon after `stop` is set (from another thread: a user's
    /// Ctrl-C) with [`transport::TransportError::Stopped`].
    pub fn trace_until(
        &self,
        progress: Progress,
        stop: &AtomicBool,
    ) -> Result<Option<McResult>, RunError> {
        match self.plan()? {
            Some(plan) => Ok(Some(transport::run_plan(&plan.stop_when(stop), progress)?)),
            None => Ok(None),
        }
    }

    /// The run's outputs from the folded Monte Carlo of [`Self::plan`]'s batches (`None`
    /// exactly when the plan was `None`): the line returns, signals, retrievals and products.
    pub fn finish(self, mc: Option<McResult>) -> Result<RunOutput, RunError> {
        let scene = self.scene;
        if mc.is_some() != self.decision.run {
            return Err(RunError::Input(scene.input_error(
                "simulation",
                "photons",
                if self.decision.run {
                    "the run needs its Monte Carlo, and none was given to finish it"
                } else {
                    "a Monte Carlo was given to a run that traces none"
                },
            )));
        }
        let Prepared {
            atmosphere,
            analytic,
            analytic_lines,
            retrieval,
            decision,
            mut signals,
            mut products,
            ..
        } = self;
        let mc_lines = mc
            .as_ref()
            .and_then(|m| m.combined.as_ref())
            .map(|c| scene.sampling.split(c));
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
        let polarised = polarised_lines(scene, &atmosphere, mc.as_ref());
        let mut weighting = Vec::new();
        if let (Some(r), Some(lines), Some(jac)) = (
            retrieval.as_ref(),
            &mc_lines,
            mc.as_ref().and_then(|m| m.jacobians_combined.as_ref()),
        ) {
            for order in [Order::Exactly(1), Order::Total] {
                for fov in 0..lines.mean.fov_full_angle_mrad.len() {
                    weighting.extend(r.weighting(lines, jac, order, fov));
                }
            }
        }
        let mut warnings = scene.warnings.clone();
        if let Some(r) = &retrieval {
            warnings.extend(crate::scene::warnings::on_line_snr_warnings(
                scene, r, &signals,
            ));
        }
        Ok(RunOutput {
            warnings,
            weighting,
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
}

/// Run every stage of `scene` on this machine, quietly: [`prepare`], [`Prepared::trace`],
/// [`Prepared::finish`]; a note on long work goes to standard error ([`crate::limits::warn`]).
pub fn run(scene: &Scene) -> Result<RunOutput, RunError> {
    run_reporting(scene, &transport::quiet)
}

/// [`run`], reporting the Monte Carlo's batches folded to `progress`.
pub fn run_reporting(scene: &Scene, progress: Progress) -> Result<RunOutput, RunError> {
    let prepared = prepare(scene)?;
    if let Some(note) = prepared.warning() {
        crate::limits::warn(&note);
    }
    let mc = prepared.trace(progress)?;
    prepared.finish(mc)
}

/// The co- and cross-polarised line returns of a run, when the lidar's light is polarised.
fn polarised_lines(
    scene: &Scene,
    atmosphere: &OpticalAtmosphere,
    mc: Option<&McResult>,
) -> Option<PolarisedLines> {
    lidar_eq::single_scatter_polarised(scene, atmosphere).map(|(co, cross)| {
        let lines = |r: &Returns| scene.sampling.combine(r).mean;
        let n = scene.sampling.lines.len();
        let first: Vec<usize> = (0..n).collect();
        PolarisedLines {
            analytic: (lines(&co), lines(&cross)),
            mc: mc
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
    })
}

/// The Monte Carlo of `scene` through `atmosphere` (its settings: `scene.simulation`), and its
/// line returns: what a study traces for each truth ([`crate::study::dial`]), with the tally
/// layout a run would use ([`tally_layout`]).
pub fn trace_lines(
    scene: &Scene,
    atmosphere: &OpticalAtmosphere,
) -> Result<(McResult, Option<LineReturns>), TransportError> {
    let mc = transport::run(scene, atmosphere, &tally_layout(scene))?;
    let lines = mc.combined.as_ref().map(|c| scene.sampling.split(c));
    Ok((mc, lines))
}

/// The layout of a run's tallies: the scene's line combinations and the pairs whose covariance
/// is folded. The one place they are set, so that a run, a shard ([`crate::shard`]), a merge
/// of shards and a study build the same plan.
pub fn tally_layout(scene: &Scene) -> TallyLayout {
    TallyLayout {
        flux: false,
        combinations: scene.sampling.combinations(),
        combination_pairs: scene.sampling.covariance_pairs(),
    }
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
    let Some(s) = signals_of(scene, lines, order) else {
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

/// The signals of a set of line returns of `scene` through its receiver, if it has one (and the
/// returns give signals: [`Signals::new`]).
pub fn signals_of(scene: &Scene, lines: &LineReturns, order: Order) -> Option<Signals> {
    let receiver = scene.receiver.as_ref()?;
    let telescope = Telescope {
        area_m2: scene.lidar.telescope_area_m2(),
        optical_efficiency: scene.lidar.optical_efficiency,
    };
    Signals::new(
        lines,
        order,
        &scene.sampling.lines,
        receiver,
        telescope,
        scene.gates.width_m,
    )
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
    retrieval_of(scene, config, reference, truth, scene.simulation.seed)
}

/// A [`Retrieval`] of `scene`'s geometry (lidar altitude, beam direction, gate centres) and
/// laser, for `config`'s line pair, against `reference` and `truth`; `seed` seeds its noise.
/// The one place a retrieval is set up, for a run and for each profile of a study.
pub fn retrieval_of(
    scene: &Scene,
    config: RetrievalConfig,
    reference: ReferenceState,
    truth: LayerColumns,
    seed: u64,
) -> Result<Retrieval, RetrievalError> {
    let pair = pair_name(scene, config.on, config.off);
    let range_m = (0..scene.gates.count)
        .map(|g| scene.gates.centre_m(g))
        .collect();
    let geometry = Geometry {
        lidar_altitude_m: scene.lidar.altitude_m,
        mu: scene.lidar.axis().z,
        range_m,
    };
    Retrieval::new(
        config,
        scene.laser.clone(),
        (reference, truth),
        geometry,
        pair,
        seed,
    )
}

/// The name of a line pair, `on/off` (the scene's line names).
pub fn pair_name(scene: &Scene, on: usize, off: usize) -> String {
    format!(
        "{}/{}",
        scene.sampling.lines[on].name, scene.sampling.lines[off].name
    )
}

/// A retrieval problem as an error at the scene key a user should change.
fn retrieval_error(scene: &Scene, e: RetrievalError) -> RunError {
    let (section, key) = e.scene_key();
    RunError::Input(scene.input_error(section, key, e.to_string()))
}
