//! A validated transport run ([`Plan`]): options checked against the scene, the shared set-up
//! built, and any batch traced from its own random stream.

use super::*;

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
    pub(super) setup: Setup<'a>,
    pub(super) fov_order: Vec<usize>,
    pub(super) batches: usize,
    pub(super) per_batch: u64,
    /// The random stream each batch starts from (computed once: batch b's is b jumps on).
    pub(super) streams: Vec<rng::Rng>,
    pub(super) threads: usize,
    pub(super) progress: bool,
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
