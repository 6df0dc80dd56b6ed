//! What a scene's work will cost, estimated before it starts (README, "Limits"): the Monte
//! Carlo's channel-events ([`McWork`]) and a study's line evaluations ([`StudyWork`]).

use crate::optics::{OpticalAtmosphere, OpticsError};
use crate::scene::Scene;

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
/// peak (bounded on its own: `docs/transport.md`, step 7).
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

/// Truths and reference states computed line by line per profile, and truths traced: with
/// photons every truth is traced, the scene's laser and its four perturbations (offset, no
/// jitter, wider line, pure), as many as the laser has.
const STUDY_LBL_STATES: u64 = 8;
const STUDY_TRACED_TRUTHS: u64 = 5;

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
