//! A validated transport run ([`Plan`]): options checked against the scene, the shared set-up
//! built, and any batch traced from its own random stream.

use super::*;
use std::sync::atomic::{AtomicBool, Ordering};

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
    /// The Jacobian tally of the batch (`super::jacobian`; empty unless the scene asks for
    /// Jacobians), in the same units as `bins`.
    pub jacobian: Vec<f64>,
}

/// Photons a batch traces between two looks at its plan's stop flag: a few milliseconds in
/// the slowest scenes, and an atomic load per thousand photons costs nothing measurable.
pub const STOP_CHECK_PHOTONS: u64 = 1024;

/// A validated transport run, ready to trace any of its batches: the read-only set-up shared by
/// all batches plus what is needed to fold them. [`run`] is `Plan::new`, every batch in parallel,
/// and a [`Fold`] in batch order; sharded and distributed runs use the same three steps.
pub struct Plan<'a> {
    pub(super) setup: Setup<'a>,
    pub(super) fov_order: Vec<usize>,
    pub(super) batches: usize,
    pub(super) per_batch: u64,
    /// The random stream each batch starts from (computed once: batch b's is b jumps on).
    pub(super) streams: Vec<rng::Rng>,
    pub(super) threads: usize,
    /// Energy per photon reaching the detector, per unit weight × geometric factor.
    pub(super) scale: f64,
    pub(super) flux_scale: f64,
    pub(super) combinations: Vec<Combination>,
    pub(super) combination_pairs: Vec<(usize, usize)>,
    pub(super) channels: Vec<String>,
    pub(super) fov_full_angle_mrad: Vec<f64>,
    pub(super) range_m: Vec<f64>,
    /// The user's combinations' names, and the layout of a polarised run's tallies.
    pub(super) combination_names: Vec<String>,
    pub(super) polarised: Option<PolarisedLayout>,
    /// Set from another thread to stop tracing ([`Plan::stop_when`]).
    pub(super) stop: Option<&'a AtomicBool>,
}

impl<'a> Plan<'a> {
    /// Check the options against the scene and build the shared set-up.
    pub fn new(
        scene: &Scene,
        atm: &'a OpticalAtmosphere,
        layout: &TallyLayout,
    ) -> Result<Self, TransportError> {
        check_options(scene, layout)?;
        let sim = &scene.simulation;
        let lidar = &scene.lidar;
        let nch = scene.channels.len();
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
            n_order_bins: sim.max_order as usize + 1,
            n_fov: fov_order.len(),
            n_channels: if polarised_run { 2 * nch } else { nch },
        };
        let setup = Setup::new(scene, atm, layout, fov_cos, shape);
        if let Some(js) = &setup.jac {
            // A batch's tally and the fold's running moments (mean, M2, scale and a batch's
            // values) of the lines (or, without lines, the channels).
            let series = if layout.combinations.is_empty() {
                nch
            } else {
                layout.combinations.len()
            };
            let reported = series * shape.n_fov * shape.n_gates * 3 * js.n_layers * 5;
            let need = 2 * js.len(&shape) + 4 * reported;
            if need > crate::limits::MAX_LIVE_TALLY_VALUES {
                return Err(TransportError::Options(format!(
                    "`jacobians = true`: {} layers × {} gates × {} fields of view × {nch} \
                     channels need {need} tally values, at most {} fit in memory: ask for \
                     fewer gates (`[gates]`), fields of view or layers (a coarser \
                     `[atmosphere] layer_thickness_m`, a lower `top_m`)",
                    js.n_layers,
                    shape.n_gates,
                    shape.n_fov,
                    crate::limits::MAX_LIVE_TALLY_VALUES
                )));
            }
        }

        let batches = sim.batches;
        let per_batch = sim.photons.div_ceil(batches as u64);
        let (polarised, combinations, combination_pairs) = if polarised_run {
            let (layout, c, p) =
                PolarisedLayout::combinations(nch, &layout.combinations, &layout.combination_pairs);
            (Some(layout), c, p)
        } else {
            (
                None,
                layout.combinations.clone(),
                layout.combination_pairs.clone(),
            )
        };
        Ok(Plan {
            setup,
            fov_order,
            batches,
            per_batch,
            streams: rng::streams(sim.seed, Stream::Transport, batches),
            threads: sim.threads,
            scale: lidar.pulse_energy_j * lidar.optical_efficiency * lidar.telescope_area_m2()
                / per_batch as f64,
            flux_scale: 1.0 / per_batch as f64,
            combinations,
            combination_pairs,
            combination_names: layout.combinations.iter().map(|c| c.name.clone()).collect(),
            polarised,
            stop: None,
            channels: scene.channels.iter().map(|c| c.name.clone()).collect(),
            fov_full_angle_mrad: lidar.fov_full_angle_mrad.clone(),
            range_m: (0..scene.gates.count)
                .map(|i| scene.gates.centre_m(i))
                .collect(),
        })
    }

    /// The plan stopping its batches soon after `flag` is set (a user's Ctrl-C, seen by the
    /// thread that waits for the run): [`super::run_plan`] then ends with
    /// [`super::TransportError::Stopped`]. A batch looks at the flag every
    /// [`STOP_CHECK_PHOTONS`] photons; a run never stopped gives the same numbers.
    pub fn stop_when(mut self, flag: &'a AtomicBool) -> Self {
        self.stop = Some(flag);
        self
    }

    /// Whether the plan was asked to stop.
    pub fn stopped(&self) -> bool {
        self.stop.is_some_and(|f| f.load(Ordering::Relaxed))
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

    pub(super) fn trace_batch_with(&self, index: usize, rng: &mut rng::Rng) -> BatchTally {
        // One channel (single-wavelength cloud and aerosol studies): the tracer compiled for
        // it; the same numbers, faster.
        if self.setup.atm.n_channels == 1 {
            self.trace_batch_by::<true>(index, rng)
        } else {
            self.trace_batch_by::<false>(index, rng)
        }
    }

    pub(super) fn trace_batch_by<const ONE_CHANNEL: bool>(
        &self,
        index: usize,
        rng: &mut rng::Rng,
    ) -> BatchTally {
        let mut tracer = photon::Tracer::<ONE_CHANNEL>::new(&self.setup);
        let mut left = self.per_batch;
        while left > 0 && !self.stopped() {
            let n = left.min(STOP_CHECK_PHOTONS);
            for _ in 0..n {
                tracer.trace(rng);
            }
            left -= n;
        }
        BatchTally {
            index,
            bins: tracer.bins,
            flux: tracer.flux,
            stats: tracer.stats,
            jacobian: tracer.jbins,
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
            jac: self.setup.jac.as_ref().map(|js| {
                super::jacobian::JacFold::new(
                    js,
                    self.setup.atm,
                    self.setup.shape,
                    self.fov_order.clone(),
                )
                .with_combinations(&self.combinations)
            }),
            plan: self,
            stats: RunStats::default(),
            next: 0,
        }
    }
}

/// The options checked against the scene: the limits a scene is validated against, the
/// variance reductions' settings, and the combinations of channels and their pairs.
fn check_options(scene: &Scene, layout: &TallyLayout) -> Result<(), TransportError> {
    let opts = &scene.simulation;
    let vr = &opts.variance_reduction;
    if opts.batches < 2 || opts.photons < opts.batches as u64 {
        return Err(TransportError::Options(format!(
            "{} photons in {} batches: need at least 2 batches and one photon per batch",
            opts.photons, opts.batches
        )));
    }
    // The limits a scene is validated against, again for settings changed in code.
    use crate::input::check_count;
    use crate::limits::{MAX_BATCHES, MAX_PHOTONS, MAX_RETURN_BINS, MAX_THREADS, check_product};
    check_count(opts.batches as u64, 2, MAX_BATCHES)
        .and_then(|_| check_count(opts.photons, 1, MAX_PHOTONS))
        .and_then(|_| check_count(opts.threads as u64, 0, MAX_THREADS))
        .and_then(|_| check_count(opts.max_order.into(), 1, 1000))
        .map_err(TransportError::Options)?;
    // The variance reductions' settings (the command line checks its own; these are for
    // settings changed in code): probabilities below 1, reference values finite and ≥ 0.
    for (name, value, below_one) in [
        ("ddis_epsilon", vr.ddis_epsilon, true),
        ("range_stratification", vr.range_stratification, true),
        ("alignment_splitting", vr.alignment_splitting, false),
        ("roulette_alignment", vr.roulette_alignment, false),
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
        * (scene.channels.len() + layout.combinations.len() + layout.combination_pairs.len());
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
    let nch = scene.channels.len();
    if let Some(c) = layout
        .combinations
        .iter()
        .find(|c| c.terms.iter().any(|(k, w)| *k >= nch || !w.is_finite()))
    {
        return Err(TransportError::Options(format!(
            "combination `{}` refers to a channel beyond the {nch} channels or has a non-finite coefficient",
            c.name
        )));
    }
    let n_combos = layout.combinations.len();
    if let Some((a, b)) = layout
        .combination_pairs
        .iter()
        .find(|(a, b)| !(a < b && *b < n_combos))
    {
        return Err(TransportError::Options(format!(
            "combination pair ({a}, {b}) is not two distinct combinations of the {n_combos}"
        )));
    }
    Ok(())
}
