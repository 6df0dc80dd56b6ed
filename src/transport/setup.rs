//! The read-only set-up every batch shares: geometry, scattering classes, DDIS, cone and
//! crossing regions, and the phase-function and optical-depth queries of the walk.

use super::index::TableIndex;
use super::*;

/// Read-only set-up shared by all batches.
pub(crate) struct Setup<'a> {
    pub(super) atm: &'a OpticalAtmosphere,
    pub(super) receiver: DVec3,
    pub(super) axis: DVec3,
    pub(super) axis_e1: DVec3,
    pub(super) axis_e2: DVec3,
    pub(super) beam_half_angle_rad: f64,
    pub(super) beam_profile: BeamProfile,
    /// cos of FOV half-angles, narrowest first.
    pub(super) fov_cos: Vec<f64>,
    /// Cosine of the widest half-angle.
    pub(super) fov_cos_widest: f64,
    pub(super) has_layers: bool,
    /// Every scatterer has one phase function for all channels (its coefficients may still
    /// differ): a mixture's phase function is then evaluated once per scatterer for all
    /// channels ([`Setup::mixture_phases`]).
    pub(super) phase_shared: bool,
    pub(super) bottom_m: f64,
    pub(super) top_m: f64,
    pub(super) shape: TallyShape,
    pub(super) gate_start_m: f64,
    pub(super) gate_width_m: f64,
    pub(super) r_end_m: f64,
    pub(super) max_order: u32,
    pub(super) surface: Option<Vec<f64>>,
    pub(super) flux_tally: bool,
    /// Cumulative vertical extinction optical depth at the receiver altitude, per channel.
    pub(super) tau_rx: Vec<f64>,
    /// Free-path samplers, one per scattering class (channels whose scatterers, coefficients and
    /// phase functions are the same); class 0 holds channel 0. One class is the common case
    /// (grey scattering: on/off lines); with more, each collision and each scattering angle is
    /// drawn from the mixture of the classes' densities (`photon` module docs).
    pub(super) classes: Vec<ScatterClass>,
    /// The layer edges' index ([`Setup::layer_of`]).
    pub(super) edge_index: TableIndex,
    /// Detector-directed importance sampling: probability ε, the layers whose phase function
    /// has a forward peak worth it, and per layer the cone around the receiver axis where it is
    /// used there (cosine of its half-angle; [`DDIS_MARGIN_MIN_RAD`]).
    pub(super) ddis_epsilon: f64,
    pub(super) forward_peaked: Vec<bool>,
    pub(super) ddis_cos: Vec<f64>,
    /// Per layer, the largest value of the phase function DDIS samples from (`mean_phase`) over
    /// the backward hemisphere, μ ≤ 0: a bound on P(Θ_rx) for a photon travelling away from
    /// the receiver, which spares evaluating it where it cannot matter (`photon`).
    pub(super) backward_max: Vec<f64>,
    /// Alignment splitting's reference phase-function value (0: off).
    pub(super) align_split: f64,
    /// Russian roulette's alignment importance: its reference phase-function value (0: off).
    pub(super) roulette_align: f64,
    /// Probability β of drawing the first collision uniformly in range over the gates.
    pub(super) stratify: f64,
    /// Cone estimate on (for some annulus), the annuli it serves, and the solid angle of each
    /// FOV annulus (narrowest first).
    pub(super) cone: bool,
    pub(super) cone_annuli: Vec<usize>,
    pub(super) annulus_sr: Vec<f64>,
    /// Tangent of the widest cone annulus's half-angle (`Setup::cone_rate`).
    pub(super) cone_tan: f64,
    /// Crossing estimate: the first annulus it serves (it serves the wider ones too; the number
    /// of annuli when off), and tan² of the half-angles of the cones bounding its region (the
    /// inner 0 when it starts at the narrowest).
    pub(super) crossing_from: usize,
    pub(super) crossing_tan2: [f64; 2],
    /// DDIS crossing at every DDIS scattering (`photon::Tracer::score_ddis_crossing`).
    pub(super) ddis_crossing: bool,
    /// Polarised transport: the receiver's analyser (`None`: scalar transport), and the
    /// scattering matrix of each of the atmosphere's phase functions (same index).
    pub(super) analyser: Option<stokes::Analyser>,
    pub(super) matrices: Vec<ScatteringMatrix>,
    /// The aperture seen from close by: where, per layer, the local estimates use the energy
    /// it collects instead of the point-receiver value (`crate::aperture`).
    pub(super) aperture: Aperture,
    /// The Jacobian tally's layers, when the scene asks for Jacobians (`super::jacobian`).
    pub(super) jac: Option<super::jacobian::JacSetup>,
}

impl<'a> Setup<'a> {
    /// The set-up of a run of `scene` (its settings checked), tallying `layout`, its fields of view's cosines
    /// `fov_cos` (narrowest first) and tally `shape`: the geometry, gates and scattering
    /// classes, then the layers where DDIS is used and the regions of the cone and crossing
    /// estimates.
    pub(super) fn new(
        scene: &Scene,
        atm: &'a OpticalAtmosphere,
        layout: &TallyLayout,
        fov_cos: Vec<f64>,
        shape: TallyShape,
    ) -> Self {
        let lidar = &scene.lidar;
        let vr = &scene.simulation.variance_reduction;
        let nch = scene.channels.len();
        let axis = lidar.axis();
        let (axis_e1, axis_e2) = axis.any_orthonormal_pair();
        let receiver = DVec3::new(0.0, 0.0, lidar.altitude_m);

        let n_layers = atm.n_layers();
        let widest = fov_cos.last().copied().unwrap_or(1.0);
        let widest_fov_mrad = lidar
            .fov_full_angle_mrad
            .iter()
            .fold(0.0f64, |m, f| m.max(*f));
        let mut setup = Setup {
            atm,
            fov_cos_widest: widest,
            has_layers: atm.n_layers() > 0,
            phase_shared: atm
                .components
                .iter()
                .flatten()
                .all(|c| c.phase.iter().all(|p| *p == c.phase[0])),
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
            max_order: scene.simulation.max_order,
            surface: scene.surface.as_ref().map(|s| s.albedo.clone()),
            flux_tally: layout.flux,
            tau_rx: (0..nch)
                .map(|k| {
                    let (s, a) = atm.cumulative_tau(receiver.z, k);
                    s + a
                })
                .collect(),
            edge_index: TableIndex::new(&atm.edges_m),
            classes: scatter_classes(atm)
                .into_iter()
                .map(|k| ScatterClass::of_channel(atm, k))
                .collect(),
            ddis_epsilon: vr.ddis_epsilon,
            forward_peaked: vec![false; n_layers],
            ddis_cos: vec![1.0; n_layers],
            backward_max: vec![f64::INFINITY; n_layers],
            align_split: vr.alignment_splitting,
            roulette_align: vr.roulette_alignment,
            stratify: vr.range_stratification,
            cone: false,
            cone_annuli: Vec::new(),
            annulus_sr: Vec::new(),
            cone_tan: 0.0,
            crossing_from: 0,
            crossing_tan2: [0.0; 2],
            ddis_crossing: vr.ddis_crossing,
            analyser: match lidar.polarisation {
                Polarisation::None => None,
                Polarisation::Linear => Some(stokes::Analyser::Linear(axis_e1)),
                Polarisation::Circular => Some(stokes::Analyser::Circular),
            },
            matrices: atm.matrices.iter().map(|m| (**m).clone()).collect(),
            aperture: Aperture::new(lidar.telescope_diameter_m, atm),
            jac: (scene.simulation.jacobians && lidar.polarisation == Polarisation::None)
                .then(|| super::jacobian::JacSetup::new(atm, receiver.z, scene.gates.end_m())),
        };
        setup.place_ddis(widest_fov_mrad);
        setup.place_estimates(vr);
        setup
    }

    /// Which layers get DDIS, the cone around the receiver's axis where it is used in each, and
    /// the layers' backward bounds of the phase function it samples (for alignment).
    fn place_ddis(&mut self, widest_fov_mrad: f64) {
        let setup = self;
        let atm = setup.atm;
        let n_layers = atm.n_layers();
        // Which layers get DDIS: a forward-peaked scatterer mixture (in any class).
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
    }

    /// The FOV annuli's solid angles, and which annuli the cone estimate and the crossing
    /// estimate serve.
    fn place_estimates(&mut self, vr: &VarianceReduction) {
        let setup = self;
        let atm = setup.atm;
        let n_layers = atm.n_layers();
        let (receiver, axis) = (setup.receiver, setup.axis);
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
        if vr.cone_estimate {
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
        setup.crossing_from = if vr.crossing_estimate && setup.has_layers {
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
    }
}

/// The free-path density of one scattering class: its cumulative vertical scattering optical
/// depth at the layer edges and its σ_s per layer (those of its first channel).
pub(crate) struct ScatterClass {
    pub(super) channel: usize,
    pub(super) cum: Vec<f64>,
    pub(super) sigma: Vec<f64>,
    /// 1/σ per layer (0 where σ = 0): the inverse optical depth without a division.
    pub(super) inv_sigma: Vec<f64>,
    /// The index of `cum` ([`Setup::altitude_at_tau`]).
    pub(super) cum_index: TableIndex,
}

impl ScatterClass {
    pub(super) fn of_channel(atm: &OpticalAtmosphere, k: usize) -> Self {
        let nch = atm.n_channels;
        let sigma: Vec<f64> = (0..atm.n_layers())
            .map(|l| atm.sigma_s_per_m[l * nch + k])
            .collect();
        let cum: Vec<f64> = (0..atm.edges_m.len())
            .map(|e| atm.cum_tau_s[e * nch + k])
            .collect();
        ScatterClass {
            channel: k,
            cum_index: TableIndex::new(&cum),
            cum,
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
pub(super) fn scatter_classes(atm: &OpticalAtmosphere) -> Vec<usize> {
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

/// Layers [`Setup::altitude_at_tau`] checks from its hint along the flight before it searches
/// the whole table.
const HINT_LAYERS: usize = 4;

/// The half-width of a phase function's forward peak: the scattering angle [rad] at which it
/// first falls to half its forward value P(0°), π if it never does. A scan in steps of
/// [`HALF_WIDTH_STEP_RAD`] finds the first step below half, bisection the angle within it.
pub(super) fn forward_half_width(phase: impl Fn(f64) -> f64) -> f64 {
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
pub(super) fn backward_max(phase: impl Fn(f64) -> f64) -> f64 {
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
pub(super) fn similar_phase(
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
    pub(super) fn order_bin(&self, order: u32) -> usize {
        (order.min(self.max_order + 1) - 1) as usize
    }

    /// The molecular share of a scattering in `layer` through the angle of cosine μ, channel
    /// k: σ_mol P_mol(μ)/Σ_j σ_j P_j(μ) (`super::jacobian`); 0 without molecules.
    pub(super) fn molecular_share(&self, layer: usize, k: usize, mu: f64) -> f64 {
        let comps = &self.atm.components[layer];
        let (mut mol, mut all) = (0.0, 0.0);
        for c in comps {
            let v = c.sigma_s_per_m[k] * self.atm.phases[c.phase[k] as usize].eval(mu);
            all += v;
            if c.molecular {
                mol += v;
            }
        }
        if all > 0.0 { mol / all } else { 0.0 }
    }

    /// Phase function of the scatterer mixture of `layer` for channel k at μ.
    #[inline]
    pub(super) fn mixture_phase(&self, layer: usize, k: usize, mu: f64) -> f64 {
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

    /// [`Self::mixture_phase`] of every channel at once, into `out` (one value per channel):
    /// where the scatterers share their phase functions across channels
    /// ([`Setup::phase_shared`]), each is evaluated once and weighted per channel in one
    /// contiguous pass, with the same arithmetic as the one-channel function.
    #[inline]
    pub(super) fn mixture_phases(&self, layer: usize, mu: f64, out: &mut [f64]) {
        let atm = self.atm;
        let comps = &atm.components[layer];
        if !self.phase_shared {
            for (k, o) in out.iter_mut().enumerate() {
                *o = self.mixture_phase(layer, k, mu);
            }
            return;
        }
        if let [c] = &comps[..] {
            out.fill(atm.phases[c.phase[0] as usize].eval(mu));
            return;
        }
        shared_mixture(atm, layer, mu, out);
    }

    /// [`Self::receiver_phase`] of every channel at once, into `out`.
    #[inline]
    pub(super) fn receiver_phases(
        &self,
        layer: usize,
        mu: f64,
        band: Option<(f64, f64)>,
        out: &mut [f64],
    ) {
        match band {
            None => self.mixture_phases(layer, mu, out),
            Some(b) => {
                for (k, o) in out.iter_mut().enumerate() {
                    *o = self.mixture_band(layer, k, b);
                }
            }
        }
    }

    /// The phase function a local estimate toward the receiver uses: its value at μ, or
    /// close to the receiver its mean over the aperture's band (`crate::aperture`).
    #[inline]
    pub(super) fn receiver_phase(
        &self,
        layer: usize,
        k: usize,
        mu: f64,
        band: Option<(f64, f64)>,
    ) -> f64 {
        match band {
            None => self.mixture_phase(layer, k, mu),
            Some(b) => self.mixture_band(layer, k, b),
        }
    }

    /// Polarised estimates close to the receiver: the factor that turns the scattering
    /// matrix's F₁₁ at μ into its mean over the aperture's band (the other elements scaled
    /// alike); 0 where F₁₁(μ) is 0.
    pub(super) fn band_over_point(
        &self,
        layer: usize,
        k: usize,
        mu: f64,
        band: Option<(f64, f64)>,
    ) -> f64 {
        let Some(b) = band else { return 1.0 };
        let point = self.mixture_phase(layer, k, mu);
        if point > 0.0 {
            self.mixture_band(layer, k, b) / point
        } else {
            0.0
        }
    }

    /// [`Self::mixture_phase`] averaged over a band of scattering angles (`crate::aperture`).
    pub(super) fn mixture_band(&self, layer: usize, k: usize, band: (f64, f64)) -> f64 {
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
    pub(super) fn mean_phase(&self, layer: usize, mu: f64) -> f64 {
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
    pub(super) fn mixture_matrix(&self, layer: usize, k: usize, mu: f64) -> MatrixElements {
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
    pub(super) fn tau_to_receiver(
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

    /// [`Self::tau_to_receiver`] of every channel at once, from the cumulative optical depths
    /// `ts`, `ta` at z, into `out`.
    #[allow(clippy::too_many_arguments)]
    #[inline]
    pub(super) fn taus_to_receiver(
        &self,
        z: f64,
        omega_z: f64,
        d: f64,
        layer: usize,
        ts: &[f64],
        ta: &[f64],
        out: &mut [f64],
    ) {
        let n = out.len();
        let (ts, ta) = (&ts[..n], &ta[..n]);
        if omega_z.abs() < 1e-12 {
            for k in 0..n {
                out[k] = self.tau_to_receiver(z, omega_z, d, layer, k, ts[k] + ta[k]);
            }
            return;
        }
        super::lanes::to_receiver(out, ts, ta, &self.tau_rx, omega_z.abs());
    }

    /// The layer at altitude z, as [`OpticalAtmosphere::layer_of`] (the last one at or above
    /// the top), through the edges' index.
    #[inline]
    pub(super) fn layer_of(&self, z: f64) -> usize {
        let n = self.atm.n_layers();
        if z >= self.top_m {
            return n.saturating_sub(1);
        }
        self.edge_index
            .find(&self.atm.edges_m, z, |e| e <= z)
            .min(n.saturating_sub(1))
    }

    /// [`OpticalAtmosphere::layer_near`], its search through the edges' index.
    #[inline]
    pub(super) fn layer_near(&self, z: f64, hint: usize) -> usize {
        self.atm.layer_near_or(z, hint, |z| self.layer_of(z))
    }

    /// Cumulative vertical scattering optical depth of class `c` at altitude z.
    #[inline]
    pub(super) fn class_tau_at(&self, c: usize, z: f64) -> f64 {
        if !self.has_layers {
            return 0.0;
        }
        let cls = &self.classes[c];
        // Outside the layers (a flight cut above them): the ends of the table, without a
        // search (the same numbers: the last entry is the last layer's value at its top).
        if z >= self.top_m {
            return cls.cum[cls.cum.len() - 1];
        } else if z <= self.bottom_m {
            return cls.cum[0];
        }
        let z = z.clamp(self.bottom_m, self.top_m);
        let e = &self.atm.edges_m;
        let l = self
            .edge_index
            .find(e, z, |x| x <= z)
            .min(cls.sigma.len() - 1);
        cls.cum[l] + (z - e[l]) * cls.sigma[l]
    }

    /// [`Self::class_tau_at`] at an altitude z usually in or next to layer `hint`
    /// ([`OpticalAtmosphere::layer_near`]).
    #[inline]
    pub(super) fn class_tau_near(&self, c: usize, z: f64, hint: usize) -> f64 {
        if !self.has_layers {
            return 0.0;
        }
        let z = z.clamp(self.bottom_m, self.top_m);
        self.class_tau_in(c, self.layer_near(z, hint), z)
    }

    /// [`Self::class_tau_at`] at an altitude z known to lie in layer l: no search.
    #[inline]
    pub(super) fn class_tau_in(&self, c: usize, l: usize, z: f64) -> f64 {
        if !self.has_layers {
            return 0.0;
        }
        let cls = &self.classes[c];
        let e = &self.atm.edges_m;
        let z = z.clamp(e[l], e[l + 1]);
        cls.cum[l] + (z - e[l]) * cls.sigma[l]
    }

    /// [`Self::class_tau_at`] at the end `z_end` of a flight that ends `end`: at the top or
    /// bottom without a search.
    #[inline]
    pub(super) fn class_tau_at_end(&self, c: usize, end: photon::End, z_end: f64) -> f64 {
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
    pub(super) fn altitude_at_tau(
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
        let holds =
            |l: usize| (l == 0 || below(cls.cum[l])) && (l == n - 1 || !below(cls.cum[l + 1]));
        // The layer holding the target is unique (the cumulative table is monotone): look a few
        // layers from the hint along the flight before searching the whole table.
        // The hint itself first (a collision in the layer its flight starts in: always in a
        // single cloud), then a few more along the flight.
        let mut l = usize::MAX;
        if hint < n && holds(hint) {
            l = hint;
        } else {
            let mut next = hint;
            for _ in 1..HINT_LAYERS {
                next = match (mu > 0.0, next.checked_sub(1)) {
                    (true, _) => next + 1,
                    (false, Some(below)) => below,
                    (false, None) => break,
                };
                if next >= n {
                    break;
                }
                if holds(next) {
                    l = next;
                    break;
                }
            }
        }
        if l == usize::MAX {
            l = cls.cum_index.find(&cls.cum, target, below);
        }
        let e = &self.atm.edges_m;
        let z = if cls.sigma[l] > 0.0 {
            e[l] + (target - cls.cum[l]) * cls.inv_sigma[l]
        } else {
            e[l]
        };
        (z.clamp(e[l], e[l + 1]), l)
    }
}

crate::simd::wide_fn! {
    /// [`Setup::mixture_phases`] of a layer of several scatterers sharing their phase
    /// functions across channels: each evaluated once, weighted per channel in one contiguous
    /// pass (the AVX2 copy at many channels: this function, its divisions mostly, was 7 % of a
    /// 16-channel default scene's run before).
    fn shared_mixture<'a>(atm: &'a OpticalAtmosphere, layer: usize, mu: f64, out: &'a mut [f64])
    where
        wide(out.len() >= crate::simd::WIDE_FROM)
    {
        let nch = out.len();
        out.fill(0.0);
        for c in &atm.components[layer] {
            let p = atm.phases[c.phase[0] as usize].eval(mu);
            for (o, sigma) in out.iter_mut().zip(&c.sigma_s_per_m[..nch]) {
                *o += sigma * p;
            }
        }
        let total = &atm.sigma_s_per_m[layer * atm.n_channels..][..nch];
        for (o, t) in out.iter_mut().zip(total) {
            *o = if *t <= 0.0 { 0.0 } else { *o / t };
        }
    }
}
