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
