//! A scene's DIAL/IPDA retrievals over an ensemble of profiles, with an error budget.
//!
//! For every profile of a set the scene is run with that profile as the truth
//! ([`Scene::with_profile`]): optics, the analytic lidar equation (or the Monte Carlo, with
//! photons), line returns, signals, and the retrievals of every on/off pair asked for. The
//! retrieval is the seed paper's: the slant column from **virtual cross-sections of the
//! ensemble-mean profile of the profile's latitude class**, σ = −ln T_gas/(2N) (DESIGN §3), and
//! XCO2 = N / N_dry with the profile's own dry-air column (the meteorology a retrieval takes
//! from NWP and a surface model); for DIAL the cell's density over its dry-air density. The
//! noisy value is one simulated averaged measurement per profile, with the profile's own noise
//! seed.
//!
//! **Error budget.** Each row perturbs one input with the others held, on the same returns
//! and the same noise seed (finite differences), against the retrieval with the profile's own
//! state as reference (the weighting-function IPDA of [`crate::retrieval`]; DIAL cells alike):
//!
//! | row | what differs |
//! |---|---|
//! | random | none: the analytic random error (detector and shot noise, energy monitor, jitter) of the averaged measurement, a standard deviation |
//! | temperature | the retrieval assumes every level colder by `temperature_k` than the truth |
//! | humidity | the truth has `humidity_fraction` more water vapour than the retrieval assumes |
//! | surface pressure | the retrieval assumes a surface pressure higher by `surface_pressure_hpa` |
//! | frequency offset | the true on-lines sit `frequency_offset_mhz` above what the retrieval assumes |
//! | frequency jitter | the scene's laser jitter against none |
//! | line width | the true line width is `linewidth_fraction` wider than assumed |
//! | spectral impurity | the scene's spectral purity against a pure laser |
//! | mean-profile σ | the virtual cross-sections of the class-mean profile against the profile's own |
//! | spectroscopy | the retrieval's lines and line shape (`[retrieval]` `lines`, `line_shape`, `line_mixing`) against the truth's |
//!
//! The state changes are made with [`shift_member`] (levels re-hydrostated), and compared with
//! the unshifted-but-re-levelled state, so only the change itself shows.
//!
//! Profiles are independent work units run in parallel with rayon; each one's noise seed is
//! the profile's index in the set ([`Stream::Study`]), so any thread count gives the same
//! numbers. A profile that cannot be run (it does not cover the scene, is supersaturated, a
//! retrieval fails) is reported with the reason and left out of the statistics.

use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Instant;

use rand::RngExt;
use rayon::prelude::*;
use thiserror::Error;

use crate::atmosphere::humidity::{SaturationOver, saturation_vapour_pressure_pa};
use crate::atmosphere::{LatitudeClass, Profile, ProfileSet, SetMember, StateShift, shift_member};
use crate::instrument::laser::{Filter, Laser, LineReturns};
use crate::instrument::line_shape::LineShape;
use crate::instrument::signals::Signals;
use crate::lidar_eq;
use crate::optics::OpticalAtmosphere;
use crate::pipeline;
use crate::retrieval::{
    AssumedInstrument, LayerColumns, Method, Product, Quantity, ReferenceState, RetrievalConfig,
};
use crate::returns::{Order, Returns};
use crate::rng::{self, Stream};
use crate::scene::Scene;
use crate::transport::TransportOptions;

/// A relative humidity above this (over liquid water) makes a profile unphysical for the study:
/// 100 % plus rounding of the files it came from.
pub const MAX_RELATIVE_HUMIDITY: f64 = 1.001;

/// Sizes of the budget's perturbations (module docs). The defaults are unit steps (1 K, 10 %,
/// 1 hPa, 1 MHz, 10 %), so the budget reads as sensitivities; give a mission's own
/// uncertainties for its budget.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BudgetSteps {
    /// Temperature knowledge error at every level \[K\].
    pub temperature_k: f64,
    /// Relative humidity knowledge error (0.1: the truth has 10 % more water vapour).
    pub humidity_fraction: f64,
    /// Surface pressure knowledge error \[hPa\].
    pub surface_pressure_hpa: f64,
    /// On-line frequency offset \[MHz\].
    pub frequency_offset_mhz: f64,
    /// Relative line-width error.
    pub linewidth_fraction: f64,
}

impl Default for BudgetSteps {
    fn default() -> Self {
        BudgetSteps {
            temperature_k: 1.0,
            humidity_fraction: 0.1,
            surface_pressure_hpa: 1.0,
            frequency_offset_mhz: 1.0,
            linewidth_fraction: 0.1,
        }
    }
}

/// The rows of the error budget.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Source {
    /// Detector and shot noise (a standard deviation).
    Random,
    /// Temperature profile knowledge.
    Temperature,
    /// Humidity knowledge.
    Humidity,
    /// Surface pressure knowledge.
    SurfacePressure,
    /// Laser frequency offset.
    FrequencyOffset,
    /// Laser frequency jitter.
    FrequencyJitter,
    /// Laser line width.
    LineWidth,
    /// Laser spectral impurity.
    SpectralImpurity,
    /// Virtual cross-sections of the class-mean profile instead of the profile's own.
    MeanProfileSigma,
    /// The retrieval's spectroscopy (`[retrieval]` lines, line shape, line mixing) instead of
    /// the truth's.
    Spectroscopy,
}

impl Source {
    /// Every row, in table order.
    pub const ALL: [Source; 10] = [
        Source::Random,
        Source::Temperature,
        Source::Humidity,
        Source::SurfacePressure,
        Source::FrequencyOffset,
        Source::FrequencyJitter,
        Source::LineWidth,
        Source::SpectralImpurity,
        Source::MeanProfileSigma,
        Source::Spectroscopy,
    ];

    /// Column-friendly name.
    pub fn label(self) -> &'static str {
        match self {
            Source::Random => "random",
            Source::Temperature => "temperature",
            Source::Humidity => "humidity",
            Source::SurfacePressure => "surface_pressure",
            Source::FrequencyOffset => "frequency_offset",
            Source::FrequencyJitter => "frequency_jitter",
            Source::LineWidth => "line_width",
            Source::SpectralImpurity => "spectral_impurity",
            Source::MeanProfileSigma => "mean_profile_sigma",
            Source::Spectroscopy => "spectroscopy",
        }
    }

    /// The row's column in `profiles.csv` and variable in `profiles.nc`: the label and `_ppm`.
    pub fn column(self) -> &'static str {
        match self {
            Source::Random => "random_ppm",
            Source::Temperature => "temperature_ppm",
            Source::Humidity => "humidity_ppm",
            Source::SurfacePressure => "surface_pressure_ppm",
            Source::FrequencyOffset => "frequency_offset_ppm",
            Source::FrequencyJitter => "frequency_jitter_ppm",
            Source::LineWidth => "line_width_ppm",
            Source::SpectralImpurity => "spectral_impurity_ppm",
            Source::MeanProfileSigma => "mean_profile_sigma_ppm",
            Source::Spectroscopy => "spectroscopy_ppm",
        }
    }

    /// The `long_name` of [`Source::column`] in `profiles.nc` (the step sizes are in
    /// `budget.csv`).
    pub fn long_name(self) -> &'static str {
        match self {
            Source::Random => "random error of one averaged measurement (1 sigma)",
            Source::Temperature => {
                "error for a retrieval that assumes every level colder than the truth"
            }
            Source::Humidity => "error for a true humidity above the assumed",
            Source::SurfacePressure => "error for an assumed surface pressure above the truth",
            Source::FrequencyOffset => "error for true on-line frequencies above the assumed",
            Source::FrequencyJitter => "error from the laser frequency jitter against none",
            Source::LineWidth => "error for a true laser line width wider than assumed",
            Source::SpectralImpurity => "error from the laser spectral impurity against none",
            Source::MeanProfileSigma => {
                "error from the class-mean virtual cross-sections against the profile's own"
            }
            Source::Spectroscopy => "error from the retrieval's spectroscopy against the truth's",
        }
    }

    /// What the row's perturbation is, for tables and legends.
    pub fn describe(self, steps: &BudgetSteps, laser: &Laser) -> String {
        match self {
            Source::Random => "detector and shot noise (1σ, averaged)".into(),
            Source::Temperature => format!("T assumed {} K too low", steps.temperature_k),
            Source::Humidity => format!("H2O {} % above assumed", 100.0 * steps.humidity_fraction),
            Source::SurfacePressure => {
                format!("p_s assumed {} hPa too high", steps.surface_pressure_hpa)
            }
            Source::FrequencyOffset => {
                format!("on-line {} MHz above assumed", steps.frequency_offset_mhz)
            }
            Source::FrequencyJitter => {
                format!("jitter {} MHz rms vs none", laser.frequency_jitter_rms_mhz)
            }
            Source::LineWidth => format!(
                "line width {} % wider than assumed",
                100.0 * steps.linewidth_fraction
            ),
            Source::SpectralImpurity => {
                format!("spectral purity {} vs 1", laser.spectral_purity)
            }
            Source::MeanProfileSigma => "class-mean virtual σ vs the profile's own".into(),
            Source::Spectroscopy => "the retrieval's spectroscopy vs the truth's".into(),
        }
    }
}

/// Number of budget rows.
pub const N_SOURCES: usize = Source::ALL.len();

/// How to run a study.
#[derive(Debug, Clone, PartialEq)]
pub struct StudyOptions {
    /// Photons per profile (0: the analytic lidar equation, single scattering).
    pub photons: u64,
    /// Seed of the per-profile instrument noise (and of the Monte Carlo).
    pub seed: u64,
    /// (on, off) line indices of the scene's lines to retrieve with.
    pub pairs: Vec<(usize, usize)>,
    /// Budget perturbation sizes.
    pub steps: BudgetSteps,
    /// Field of view (index among the scene's) the retrievals use.
    pub fov: usize,
}

impl StudyOptions {
    /// The scene's own retrieval pair, analytic, the scene's seed, unit budget steps.
    pub fn from_scene(scene: &Scene) -> Option<StudyOptions> {
        let r = scene.retrieval.as_ref()?;
        Some(StudyOptions {
            photons: 0,
            seed: scene.simulation.seed,
            pairs: vec![(r.on, r.off)],
            steps: BudgetSteps::default(),
            fov: 0,
        })
    }
}

/// One retrieved quantity of one profile and line pair: XCO2 of an IPDA column or of a DIAL
/// cell \[ppm\].
#[derive(Debug, Clone, PartialEq)]
pub struct Record {
    /// `on/off`.
    pub pair: String,
    /// [`Method::Ipda`] (column to the hard target) or [`Method::Dial`] (a cell).
    pub method: Method,
    /// Altitude interval \[m\].
    pub altitude_m: (f64, f64),
    /// The profile's own value.
    pub truth_ppm: f64,
    /// Retrieved from the noise-free signals with the class-mean virtual σ (the study's
    /// retrieval). With Monte Carlo returns (`photons` > 0) NaN where it cannot be retrieved
    /// (a window of the photons' signal holds no energy: its logarithm is undefined), as are
    /// then `retrieved_own_ppm` and the budget rows that need it ([`Record::is_defined`]);
    /// from the analytic lidar equation always finite, or the profile fails.
    pub retrieved_ppm: f64,
    /// The same from one noisy averaged measurement; NaN when it cannot be retrieved (the
    /// noisy signal of a window is not positive: its logarithm is undefined), written as an
    /// empty field and left out of the noisy statistics ([`Summary::noisy_profiles`]).
    pub retrieved_noisy_ppm: f64,
    /// Retrieved from the noise-free signals with the profile's own state as reference.
    pub retrieved_own_ppm: f64,
    /// Budget rows in [`Source::ALL`] order \[ppm\]: the random error (a standard deviation)
    /// and the error each perturbation causes (signed).
    pub budget_ppm: [f64; N_SOURCES],
}

impl Record {
    /// Retrieved − truth without noise.
    pub fn error_ppm(&self) -> f64 {
        self.retrieved_ppm - self.truth_ppm
    }
    /// Retrieved − truth with noise.
    pub fn error_noisy_ppm(&self) -> f64 {
        self.retrieved_noisy_ppm - self.truth_ppm
    }
    /// Whether every noise-free value (retrieved, own-reference retrieval, every budget row)
    /// is defined: always from the analytic lidar equation; from Monte Carlo returns not where
    /// a window of the photons' signal holds no energy. Only such records enter the noise-free
    /// statistics ([`Summary::retrieved_profiles`]).
    pub fn is_defined(&self) -> bool {
        self.retrieved_ppm.is_finite()
            && self.retrieved_own_ppm.is_finite()
            && self.budget_ppm.iter().all(|v| v.is_finite())
    }
}

/// What became of one profile.
#[derive(Debug, Clone, PartialEq)]
pub struct ProfileOutcome {
    /// Profile id in its set.
    pub id: String,
    /// Its latitude class.
    pub class: LatitudeClass,
    /// Its records, or why it could not be run.
    pub records: Result<Vec<Record>, String>,
}

/// Thread-summed time spent in each part of a study \[s\].
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Timing {
    /// Class-mean reference states (line by line).
    pub mean_references_s: f64,
    /// Truth optics: line by line at every channel, Rayleigh, particles.
    pub truth_optics_s: f64,
    /// Returns: the lidar equation or the Monte Carlo, and signals.
    pub returns_s: f64,
    /// Reference states of each profile and its perturbations (line by line at the nodes).
    pub references_s: f64,
    /// Retrievals (and one noisy measurement each).
    pub retrievals_s: f64,
    /// Wall-clock time of the whole study.
    pub wall_s: f64,
}

/// A finished study.
#[derive(Debug, Clone)]
pub struct StudyResult {
    /// Every profile, in set order.
    pub outcomes: Vec<ProfileOutcome>,
    /// The class-mean profiles whose virtual σ was used (after the scene's CO2 rescale).
    pub mean_profiles: Vec<(LatitudeClass, Profile)>,
    /// Where the time went.
    pub timing: Timing,
}

/// Why a study could not start.
#[derive(Debug, Error)]
pub enum StudyError {
    /// The scene cannot be studied (no retrieval, no receiver, no gas).
    #[error("{0}")]
    Scene(String),
    /// The profile set could not be read or generated.
    #[error("{0}")]
    Profiles(String),
    /// The ensemble-mean profile of a class failed.
    #[error("the mean profile of class {class}: {message}")]
    MeanProfile {
        /// The class.
        class: LatitudeClass,
        /// Why.
        message: String,
    },
}

/// Nanosecond counters behind [`Timing`], shared by the worker threads.
#[derive(Default)]
struct Clock {
    truth_optics: AtomicU64,
    returns: AtomicU64,
    references: AtomicU64,
    retrievals: AtomicU64,
}

impl Clock {
    fn time<T>(counter: &AtomicU64, f: impl FnOnce() -> T) -> T {
        let t = Instant::now();
        let out = f();
        counter.fetch_add(t.elapsed().as_nanos() as u64, Ordering::Relaxed);
        out
    }
}

/// A study set up for one scene and profile set.
struct Study<'a> {
    scene: &'a Scene,
    config: &'a RetrievalConfig,
    options: &'a StudyOptions,
    filter: Filter,
    /// Class-mean reference states.
    means: Vec<(LatitudeClass, ReferenceState)>,
    clock: Clock,
}

/// Run `scene`'s retrievals for every profile of `set` (module docs). `progress` is called
/// once per finished profile.
pub fn run(
    scene: &Scene,
    set: &ProfileSet,
    options: &StudyOptions,
    progress: &(dyn Fn() + Sync),
) -> Result<StudyResult, StudyError> {
    run_slice(scene, set, options, 0..set.len(), progress)
}

/// [`run`] for the profiles `slice` of `set` only (a shard of the study,
/// [`crate::study::shard`]): the class means are still those of the whole set and each
/// profile keeps its noise seed, so the outcomes are those of the same profiles in [`run`],
/// bit for bit. `outcomes` holds the slice's profiles only.
pub fn run_slice(
    scene: &Scene,
    set: &ProfileSet,
    options: &StudyOptions,
    slice: std::ops::Range<usize>,
    progress: &(dyn Fn() + Sync),
) -> Result<StudyResult, StudyError> {
    if slice.start > slice.end || slice.end > set.len() {
        return Err(StudyError::Scene(format!(
            "profiles {}..{} of a set of {}",
            slice.start,
            slice.end,
            set.len()
        )));
    }
    let started = Instant::now();
    let config = scene
        .retrieval
        .as_ref()
        .ok_or_else(|| StudyError::Scene("the scene has no [retrieval]".into()))?;
    if scene.receiver.is_none() {
        return Err(StudyError::Scene(
            "the scene has no [receiver]: a study needs the instrument's noise".into(),
        ));
    }
    if scene.gas.is_none() {
        return Err(StudyError::Scene(
            "the scene has no [gas_absorption]: nothing to retrieve".into(),
        ));
    }
    let n_lines = scene.lines.len();
    if options.pairs.is_empty() {
        return Err(StudyError::Scene("no on/off line pair to retrieve".into()));
    }
    for &(on, off) in &options.pairs {
        if on >= n_lines || off >= n_lines || on == off {
            return Err(StudyError::Scene(format!(
                "line pair ({on}, {off}) is not two different lines of the scene's {n_lines}"
            )));
        }
    }
    if options.fov >= scene.lidar.fov_full_angle_mrad.len() {
        return Err(StudyError::Scene(format!(
            "field of view {} of {}",
            options.fov,
            scene.lidar.fov_full_angle_mrad.len()
        )));
    }
    let filter = scene
        .receiver
        .as_ref()
        .map(|r| r.filter)
        .unwrap_or(Filter::none());
    let mut study = Study {
        scene,
        config,
        options,
        filter,
        means: Vec::new(),
        clock: Clock::default(),
    };
    // Profiles that cannot be run are found first: they take no part in the class means.
    let checked: Vec<Result<Scene, String>> =
        set.members.par_iter().map(|m| study.usable(m)).collect();
    // The class-mean profiles and their reference states.
    let t_means = Instant::now();
    let mut mean_profiles = Vec::new();
    for class in LatitudeClass::ALL {
        let members = ProfileSet {
            name: format!("{} [{class}]", set.name),
            members: set
                .members
                .iter()
                .zip(&checked)
                .filter(|(m, ok)| m.meta.class() == class && ok.is_ok())
                .map(|(m, _)| m.clone())
                .collect(),
            notes: Vec::new(),
        };
        if members.is_empty() {
            continue;
        }
        let err = |message: String| StudyError::MeanProfile { class, message };
        let mean = members.mean_member().map_err(|e| err(e.to_string()))?;
        let mean_scene = scene
            .with_profile(mean.profile)
            .map_err(|e| err(e.to_string()))?;
        let profile = mean_scene
            .atmosphere
            .as_ref()
            .map(|a| a.profile.clone())
            .ok_or_else(|| err("no atmosphere".into()))?;
        let edges = mean_scene
            .molecular_edges()
            .ok_or_else(|| err("no molecular grid".into()))?;
        let reference = study.reference(&profile, &edges).map_err(err)?;
        study.means.push((class, reference));
        mean_profiles.push((class, profile));
    }
    let mean_references_s = t_means.elapsed().as_secs_f64();
    // One noise seed per profile, from its index: independent of threads and of other profiles.
    let seeds: Vec<u64> = rng::streams(options.seed, Stream::Study, set.len())
        .into_iter()
        .map(|mut r| r.random::<u64>())
        .collect();
    let one = |((member, seed), ok): ((&SetMember, &u64), &Result<Scene, String>)| {
        let records = match ok {
            Ok(scene) => study.profile(member, scene, *seed),
            Err(e) => Err(e.clone()),
        };
        progress();
        ProfileOutcome {
            id: member.meta.id.clone(),
            class: member.meta.class(),
            records,
        }
    };
    // With photons the transport parallelises each profile itself.
    let (members, seeds, checked) = (
        &set.members[slice.clone()],
        &seeds[slice.clone()],
        &checked[slice],
    );
    let outcomes: Vec<ProfileOutcome> = if options.photons > 0 {
        members.iter().zip(seeds).zip(checked).map(one).collect()
    } else {
        members
            .par_iter()
            .zip(seeds)
            .zip(checked)
            .map(one)
            .collect()
    };
    let secs = |c: &AtomicU64| c.load(Ordering::Relaxed) as f64 * 1e-9;
    let timing = Timing {
        mean_references_s,
        truth_optics_s: secs(&study.clock.truth_optics),
        returns_s: secs(&study.clock.returns),
        references_s: secs(&study.clock.references),
        retrievals_s: secs(&study.clock.retrievals),
        wall_s: started.elapsed().as_secs_f64(),
    };
    Ok(StudyResult {
        outcomes,
        mean_profiles,
        timing,
    })
}

/// Where a study's profiles come from.
#[derive(Debug, Clone, PartialEq)]
pub enum ProfileSource {
    /// A profile set file (lidarsim format), its members of the classes asked for.
    Set(std::path::PathBuf),
    /// `n` members per class generated around the class's AFGL mean with the representative
    /// NWP forecast-error covariance; class i of tropical, mid, high takes seed `seed + i`.
    Ensemble(usize),
}

/// The latitude classes `class` names: `tropical`, `mid`, `high` or `all`.
pub fn classes(class: &str) -> Result<Vec<LatitudeClass>, StudyError> {
    match class {
        "all" => Ok(LatitudeClass::ALL.to_vec()),
        c => Ok(vec![
            c.parse::<LatitudeClass>().map_err(StudyError::Profiles)?,
        ]),
    }
}

/// The profiles of a study: `source`'s members of the classes `class` names ([`classes`]),
/// generated ensembles from `seed`.
pub fn profile_set(
    source: &ProfileSource,
    class: &str,
    seed: u64,
) -> Result<ProfileSet, StudyError> {
    let classes = classes(class)?;
    let n = match source {
        ProfileSource::Set(path) => {
            let set = crate::atmosphere::read_profile_set(path)
                .map_err(|e| StudyError::Profiles(e.to_string()))?;
            let mut out = ProfileSet {
                name: set.name.clone(),
                members: Vec::new(),
                notes: set.notes.clone(),
            };
            for c in &classes {
                out.members.extend(set.class(*c).members);
            }
            if out.is_empty() {
                return Err(StudyError::Profiles(format!(
                    "{}: no profile of class {class}",
                    path.display()
                )));
            }
            return Ok(out);
        }
        ProfileSource::Ensemble(n) => *n,
    };
    let mut set = ProfileSet {
        name: format!("{n} members per class, seed {seed}"),
        members: Vec::new(),
        notes: Vec::new(),
    };
    for c in &classes {
        let i = LatitudeClass::ALL.iter().position(|x| x == c).unwrap_or(0) as u64;
        let (s, report) = crate::atmosphere::class_ensemble(*c, n, seed.wrapping_add(i))
            .map_err(|e| StudyError::Profiles(e.to_string()))?;
        if report.capped_values > 0 {
            set.notes.push(format!(
                "class {c}: water vapour capped at 100 % relative humidity in {} of {} values",
                report.capped_values, report.total_values
            ));
        }
        set.members.extend(s.members);
    }
    Ok(set)
}

/// Line returns and signals of one truth.
struct Measured {
    scene: Scene,
    /// The channels' returns (analytic only), for truths whose channels are a subset.
    channels: Option<Returns>,
    lines: LineReturns,
    signals: Signals,
}

impl Study<'_> {
    /// The reference state of `profile` on `edges` (cut to the profile's top), as the
    /// retrieval assumes the scene's instrument.
    fn reference(&self, profile: &Profile, edges: &[f64]) -> Result<ReferenceState, String> {
        self.reference_as(profile, edges, true)
    }

    /// The reference state with the retrieval's own spectroscopy (`assumed`) or the truth's.
    fn reference_as(
        &self,
        profile: &Profile,
        edges: &[f64],
        assumed: bool,
    ) -> Result<ReferenceState, String> {
        let gas = self.scene.gas.as_ref().ok_or("no gas absorption")?;
        let (lines, options) = if assumed {
            self.config.assumed(&gas.lines, &gas.options)
        } else {
            (&*gas.lines, gas.options)
        };
        ReferenceState::new(
            profile,
            &fit_edges(edges, profile),
            &self.config.gas,
            lines,
            &options,
            AssumedInstrument {
                laser: &self.scene.laser,
                lines: &self.scene.sampling.lines,
                filter: &self.filter,
            },
        )
        .map_err(|e| e.to_string())
    }

    /// The expected returns and signals of `scene` (a truth); with photons, traced from the
    /// profile's `seed` (every truth of one profile on the same photons).
    fn measure(&self, scene: Scene, seed: u64) -> Result<Measured, String> {
        let optics = Clock::time(&self.clock.truth_optics, || {
            OpticalAtmosphere::build(&scene).map_err(|e| e.to_string())
        })?;
        Clock::time(&self.clock.returns, || {
            let (channels, lines, order) = if self.options.photons > 0 {
                let mut opts = TransportOptions::from_scene(&scene);
                opts.photons = self.options.photons;
                opts.seed = seed;
                let (_, lines) =
                    pipeline::trace_lines(&scene, &optics, &opts).map_err(|e| e.to_string())?;
                (None, lines.ok_or("no combined returns")?, Order::Total)
            } else {
                let analytic = lidar_eq::single_scatter(&scene, &optics);
                let lines = scene.sampling.combine(&analytic);
                (Some(analytic), lines, Order::Exactly(1))
            };
            with_signals(scene, channels, lines, order)
        })
    }

    /// The truth `scene` (another laser on `base`'s profile): from `base`'s channel returns
    /// when it samples only wavenumbers `base` has (a laser without jitter or impurity: the
    /// analytic return of a channel depends on its wavenumber and its line alone), else anew.
    fn measure_like(&self, base: &Measured, scene: Scene, seed: u64) -> Result<Measured, String> {
        let subset = base.channels.as_ref().and_then(|r| {
            let index: Option<Vec<usize>> = scene
                .sampling
                .channels
                .iter()
                .map(|c| {
                    base.scene.sampling.channels.iter().position(|b| {
                        b.line == c.line && b.wavenumber_cm1.to_bits() == c.wavenumber_cm1.to_bits()
                    })
                })
                .collect();
            index.map(|i| r.channel_subset(&i))
        });
        match subset {
            Some(channels) => Clock::time(&self.clock.returns, || {
                let lines = scene.sampling.combine(&channels);
                with_signals(scene, Some(channels), lines, Order::Exactly(1))
            }),
            None => self.measure(scene, seed),
        }
    }

    /// The products of every pair retrieved from `m` with `reference` (one retrieval set-up,
    /// its paths shared by the pairs: [`Retrieval::set_pair`](crate::retrieval::Retrieval::set_pair)).
    fn retrieve(
        &self,
        m: &Measured,
        reference: &ReferenceState,
        truth: &LayerColumns,
        seed: u64,
    ) -> Result<Vec<Vec<Product>>, String> {
        Clock::time(&self.clock.retrievals, || {
            let mut config = self.config.clone();
            config.realisations = 1;
            (config.on, config.off) = self.options.pairs[0];
            let mut r =
                pipeline::retrieval_of(&m.scene, config, reference.clone(), truth.clone(), seed)
                    .map_err(|e| e.to_string())?;
            let name = |(on, off): (usize, usize)| pipeline::pair_name(&m.scene, on, off);
            let mut out = Vec::with_capacity(self.options.pairs.len());
            for &(on, off) in &self.options.pairs {
                r.set_pair(on, off, name((on, off)))
                    .map_err(|e| e.to_string())?;
                out.push(
                    r.retrieve(&m.lines, &m.signals, self.options.fov)
                        .map_err(|e| e.to_string())?,
                );
            }
            Ok(out)
        })
    }

    /// The scene with `member` as its truth, or why it cannot be run: it does not fit the scene
    /// ([`Scene::with_profile`]) or is supersaturated.
    fn usable(&self, member: &SetMember) -> Result<Scene, String> {
        let scene = self
            .scene
            .with_profile(member.profile.clone())
            .map_err(|e| e.to_string())?;
        match &scene.atmosphere {
            Some(a) => check_saturation(&a.profile)?,
            None => return Err("no atmosphere".into()),
        }
        Ok(scene)
    }

    /// Every record of one profile, `scene` its truth ([`Self::usable`]).
    fn profile(&self, member: &SetMember, scene: &Scene, seed: u64) -> Result<Vec<Record>, String> {
        let scene = scene.clone();
        let profile = scene
            .atmosphere
            .as_ref()
            .map(|a| a.profile.clone())
            .ok_or("no atmosphere")?;
        let mean = self
            .means
            .iter()
            .find(|(c, _)| *c == member.meta.class())
            .map(|(_, r)| r)
            .ok_or("no mean profile of its class")?;
        let edges = scene.molecular_edges().ok_or("no molecular grid")?;
        let truth =
            LayerColumns::new(&profile, &edges, &self.config.gas).map_err(|e| e.to_string())?;
        let truth_member = SetMember {
            meta: member.meta.clone(),
            profile,
        };
        let steps = &self.options.steps;
        // References: the truth's own, re-levelled, and one per knowledge error.
        let (own, exact, knowledge) = Clock::time(&self.clock.references, || {
            let own = self.reference(&truth_member.profile, &edges)?;
            // The truth's spectroscopy, where the retrieval assumes another.
            let exact = match &self.config.spectroscopy {
                Some(_) => Some(self.reference_as(&truth_member.profile, &edges, false)?),
                None => None,
            };
            let shifted = |s: StateShift| -> Result<ReferenceState, String> {
                let p = shift_member(&truth_member, &s).map_err(|e| e.to_string())?;
                check_dry_air(&p.profile, s.h2o_factor)?;
                self.reference(&p.profile, &edges)
            };
            let none = StateShift::NONE;
            let knowledge = [
                shifted(none)?,
                shifted(StateShift {
                    temperature_k: -steps.temperature_k,
                    ..none
                })?,
                shifted(StateShift {
                    h2o_factor: 1.0 / (1.0 + steps.humidity_fraction),
                    ..none
                })?,
                shifted(StateShift {
                    surface_pressure_hpa: steps.surface_pressure_hpa,
                    ..none
                })?,
            ];
            Ok::<_, String>((own, exact, knowledge))
        })?;
        // Truths: the scene's laser, and one per laser perturbation (None: the row is 0).
        let laser = &scene.laser;
        let mut offset = laser.clone();
        for &(on, _) in &self.options.pairs {
            offset.frequency_offset_mhz[on] += steps.frequency_offset_mhz;
        }
        let no_jitter = (laser.frequency_jitter_rms_mhz > 0.0).then(|| Laser {
            frequency_jitter_rms_mhz: 0.0,
            ..laser.clone()
        });
        let wider = widened(&laser.line_shape, 1.0 + steps.linewidth_fraction).map(|s| Laser {
            line_shape: s,
            ..laser.clone()
        });
        let pure = (laser.spectral_purity < 1.0).then(|| Laser {
            spectral_purity: 1.0,
            ..laser.clone()
        });
        let base = self.measure(scene, seed)?;
        let variant = |l: Option<Laser>| -> Result<Option<Measured>, String> {
            match l {
                None => Ok(None),
                Some(l) => {
                    let s = base.scene.with_laser(l).map_err(|e| e.to_string())?;
                    self.measure_like(&base, s, seed).map(Some)
                }
            }
        };
        let lasers = [
            variant(Some(offset))?,
            variant(no_jitter)?,
            variant(wider)?,
            variant(pure)?,
        ];
        let paper = self.retrieve(&base, mean, &truth, seed)?;
        let own_p = self.retrieve(&base, &own, &truth, seed)?;
        let exact_p = exact
            .as_ref()
            .map(|r| self.retrieve(&base, r, &truth, seed))
            .transpose()?;
        let know: Vec<Vec<Vec<Product>>> = knowledge
            .iter()
            .map(|r| self.retrieve(&base, r, &truth, seed))
            .collect::<Result<_, _>>()?;
        let las: Vec<Option<Vec<Vec<Product>>>> = lasers
            .iter()
            .map(|m| {
                m.as_ref()
                    .map(|m| self.retrieve(m, &own, &truth, seed))
                    .transpose()
            })
            .collect::<Result<_, _>>()?;
        let mut records: Vec<Record> = Vec::new();
        for p in 0..self.options.pairs.len() {
            let know_p: Vec<Vec<Product>> = know.iter().map(|k| k[p].clone()).collect();
            let las_p: Vec<Option<Vec<Product>>> = las
                .iter()
                .map(|l| l.as_ref().map(|l| l[p].clone()))
                .collect();
            let exact = exact_p.as_ref().map(|e| e[p].as_slice());
            records.extend(pair_records(&paper[p], &own_p[p], exact, &know_p, &las_p));
        }
        check_records(&mut records, self.options.photons > 0)?;
        Ok(records)
    }
}

/// Refuse a water-vapour factor that leaves a level of `p` (a state shifted by it) without dry
/// air: the dry-air column, and with it the mixing ratio, would be 0 or negative.
fn check_dry_air(p: &Profile, factor: f64) -> Result<(), String> {
    let Some(h2o) = p.gas("H2O") else {
        return Ok(());
    };
    match h2o.iter().enumerate().find(|(_, x)| !(**x < 1.0)) {
        Some((k, x)) => Err(format!(
            "the humidity budget's assumed state (water vapour × {factor:.4}) has an H2O mole fraction of {x:.3} at {:.0} m, leaving no dry air (give a smaller --budget-humidity-percent below 0)",
            p.altitude_m[k]
        )),
        None => Ok(()),
    }
}

/// Which values of a profile's records must be defined, and what an undefined one is written
/// as: the truth always (it is the profile's own column); the noise-free retrievals and the
/// budget rows when the returns are analytic (`monte_carlo` false: a noise-free lidar
/// equation has energy in every window, so a value that is not finite is a failure, and the
/// profile fails with it named). From Monte Carlo returns, as from one noisy measurement, a
/// window may hold no energy (a few photons, a far cell behind a cloud): the retrieval has no
/// logarithm there, and the value is honestly undefined, set to NaN (an infinity too: a ratio
/// over no energy), written as an empty field and left out of the statistics with its count
/// ([`Summary::retrieved_profiles`], [`Summary::noisy_profiles`]).
fn check_records(records: &mut [Record], monte_carlo: bool) -> Result<(), String> {
    let undefined = |v: &mut f64| {
        if !v.is_finite() {
            *v = f64::NAN;
        }
    };
    for r in records.iter_mut() {
        undefined(&mut r.retrieved_noisy_ppm);
        if monte_carlo {
            undefined(&mut r.retrieved_ppm);
            undefined(&mut r.retrieved_own_ppm);
            r.budget_ppm.iter_mut().for_each(undefined);
        }
        let values = [
            ("truth_ppm", r.truth_ppm),
            ("retrieved_ppm", r.retrieved_ppm),
            ("retrieved_own_profile_ppm", r.retrieved_own_ppm),
        ];
        let budget = Source::ALL
            .iter()
            .zip(&r.budget_ppm)
            .map(|(s, v)| (s.column(), *v));
        let must = |name: &str| !monte_carlo || name == "truth_ppm";
        if let Some((name, v)) = values
            .into_iter()
            .chain(budget)
            .find(|(name, v)| must(name) && !v.is_finite())
        {
            return Err(format!(
                "{name} of {} {} {:.0}–{:.0} m is {v}: it cannot be computed",
                r.pair,
                r.method.label(),
                r.altitude_m.0,
                r.altitude_m.1
            ));
        }
    }
    Ok(())
}

/// Signals of a truth's line returns through its receiver.
fn with_signals(
    scene: Scene,
    channels: Option<Returns>,
    lines: LineReturns,
    order: Order,
) -> Result<Measured, String> {
    if scene.receiver.is_none() {
        return Err("no receiver".into());
    }
    let signals = pipeline::signals_of(&scene, &lines, order).ok_or("no signals of the returns")?;
    Ok(Measured {
        scene,
        channels,
        lines,
        signals,
    })
}

/// The records of one pair from its products (in [`Retrieval`](crate::retrieval::Retrieval)'s target order: IPDA mixing
/// ratio and slant column, then per DIAL cell density and mixing ratio).
///
/// `exact` holds the products with the own reference in the truth's spectroscopy, where the
/// retrieval assumes another; `know` holds the products with the re-levelled own reference and with each knowledge error
/// (temperature, humidity, surface pressure); `las` those with each laser perturbation
/// (offset, no jitter, wider, pure), None where the perturbation does not apply.
fn pair_records(
    paper: &[Product],
    own: &[Product],
    exact: Option<&[Product]>,
    know: &[Vec<Product>],
    las: &[Option<Vec<Product>>],
) -> Vec<Record> {
    let mut out = Vec::new();
    let mut i = 0;
    while i + 1 < paper.len() {
        // (the column or density product, the mixing-ratio product) of this target.
        let (col, mr) = match paper[i].method {
            Method::Ipda => (i + 1, i),
            _ => (i, i + 1),
        };
        debug_assert_eq!(paper[mr].quantity, Quantity::MixingRatio);
        let truth = paper[mr].truth;
        // Dry-air amount of the truth in the column product's unit: N_dry = N / x.
        let dry = paper[col].truth / (truth * 1e-6);
        let ppm = |v: f64| v / dry * 1e6;
        let d = |a: &[Product], b: &[Product]| a[mr].retrieved - b[mr].retrieved;
        let mut budget = [0.0; N_SOURCES];
        budget[0] = ppm(paper[col].random_error_averaged);
        budget[1] = d(&know[1], &know[0]);
        budget[2] = d(&know[2], &know[0]);
        budget[3] = d(&know[3], &know[0]);
        let laser_row = |k: usize, sign: f64| {
            las[k]
                .as_ref()
                .map_or(0.0, |p| sign * (p[mr].retrieved - own[mr].retrieved))
        };
        budget[4] = laser_row(0, 1.0);
        budget[5] = laser_row(1, -1.0);
        budget[6] = laser_row(2, 1.0);
        budget[7] = laser_row(3, -1.0);
        let retrieved = ppm(paper[col].retrieved);
        budget[8] = retrieved - ppm(own[col].retrieved);
        budget[9] = exact.map_or(0.0, |e| own[mr].retrieved - e[mr].retrieved);
        out.push(Record {
            pair: paper[mr].channel_pair.clone(),
            method: paper[mr].method,
            altitude_m: paper[mr].altitude_m,
            truth_ppm: truth,
            retrieved_ppm: retrieved,
            retrieved_noisy_ppm: ppm(paper[col].simulated_first_averaged),
            retrieved_own_ppm: own[mr].retrieved,
            budget_ppm: budget,
        });
        i += 2;
    }
    out
}

/// `edges` cut to the top of `profile` (a profile re-levelled colder ends a little lower).
fn fit_edges(edges: &[f64], profile: &Profile) -> Vec<f64> {
    let top = profile.altitude_m[profile.len() - 1].min(edges[edges.len() - 1]);
    let mut out: Vec<f64> = edges.iter().copied().filter(|z| *z < top).collect();
    out.push(top);
    out
}

/// The line shape `factor` times wider, if it has a width to scale.
fn widened(shape: &LineShape, factor: f64) -> Option<LineShape> {
    match shape {
        LineShape::Gaussian { fwhm_mhz } => Some(LineShape::Gaussian {
            fwhm_mhz: fwhm_mhz * factor,
        }),
        LineShape::Lorentzian { fwhm_mhz } => Some(LineShape::Lorentzian {
            fwhm_mhz: fwhm_mhz * factor,
        }),
        LineShape::Monochromatic | LineShape::Table(_) => None,
    }
}

/// A profile supersaturated over liquid water (beyond [`MAX_RELATIVE_HUMIDITY`]) is refused.
fn check_saturation(p: &Profile) -> Result<(), String> {
    let Some(h2o) = p.gas("H2O") else {
        return Ok(());
    };
    for k in 0..p.len() {
        let e = h2o[k] * p.pressure_pa[k];
        let e_s = saturation_vapour_pressure_pa(p.temperature_k[k], SaturationOver::Water);
        if e > MAX_RELATIVE_HUMIDITY * e_s {
            return Err(format!(
                "supersaturated: relative humidity {:.1} % at {:.0} m ({:.1} hPa, {:.1} K)",
                100.0 * e / e_s,
                p.altitude_m[k],
                p.pressure_pa[k] / 100.0,
                p.temperature_k[k]
            ));
        }
    }
    Ok(())
}

/// Bias and spread of one budget row over a group of profiles \[ppm\].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SourceStats {
    /// Mean error (0 for the random row).
    pub bias_ppm: f64,
    /// Standard deviation over the profiles (the random row: the rms of each profile's 1σ).
    pub sd_ppm: f64,
    /// √(bias² + sd²).
    pub rms_ppm: f64,
    /// rms² over the sum of every row's rms²: the row's share of the total error variance.
    pub share: f64,
}

/// Statistics of one retrieved quantity over a group of profiles.
#[derive(Debug, Clone, PartialEq)]
pub struct Summary {
    /// A latitude class, or `all`.
    pub class: String,
    /// `on/off`.
    pub pair: String,
    /// IPDA or DIAL.
    pub method: Method,
    /// Altitude interval \[m\].
    pub altitude_m: (f64, f64),
    /// Profiles in the group (failed ones excluded).
    pub profiles: usize,
    /// Of those, the profiles whose noise-free values could all be computed
    /// ([`Record::is_defined`]): the members of `bias_ppm`, `sd_ppm`, the budget rows and
    /// `total_ppm`. `profiles` from the analytic lidar equation; from Monte Carlo returns the
    /// profiles with energy in the quantity's windows.
    pub retrieved_profiles: usize,
    /// Of those, the profiles whose noisy measurement could be retrieved too: the members of
    /// `noisy_bias_ppm`, `noisy_sd_ppm` and `noise_ratio`.
    pub noisy_profiles: usize,
    /// Mean truth \[ppm\].
    pub truth_mean_ppm: f64,
    /// Mean and standard deviation of retrieved − truth, noise-free, over the
    /// `retrieved_profiles` \[ppm\] (NaN, an empty field, for none; the standard deviation
    /// also for one).
    pub bias_ppm: f64,
    /// See `bias_ppm`.
    pub sd_ppm: f64,
    /// The same with one noisy measurement per profile, over the `noisy_profiles` whose
    /// measurement could be retrieved \[ppm\] (NaN, an empty field, for none; the standard
    /// deviation also for one).
    pub noisy_bias_ppm: f64,
    /// See `noisy_bias_ppm`.
    pub noisy_sd_ppm: f64,
    /// Standard deviation of noisy − noise-free over the `noisy_profiles`, divided by the rms
    /// analytic random error over the same profiles: 1 within sampling error (√(1/(2n))
    /// relative) if the analytic error is right (NaN, an empty field, for fewer than 2).
    pub noise_ratio: f64,
    /// The budget rows in [`Source::ALL`] order.
    pub sources: [SourceStats; N_SOURCES],
    /// √ of the sum of every row's rms² \[ppm\].
    pub total_ppm: f64,
}

/// Root mean square (NaN for none).
fn rms(v: &[f64]) -> f64 {
    (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt()
}

/// Mean and sample standard deviation; NaN where undefined (no value; one, for the standard
/// deviation), which the writers make empty fields and `_FillValue`.
fn mean_sd(v: &[f64]) -> (f64, f64) {
    let n = v.len() as f64;
    if v.is_empty() {
        return (f64::NAN, f64::NAN);
    }
    let m = v.iter().sum::<f64>() / n;
    let var = if v.len() > 1 {
        v.iter().map(|x| (x - m) * (x - m)).sum::<f64>() / (n - 1.0)
    } else {
        f64::NAN
    };
    (m, var.sqrt())
}

/// Statistics per class (and over all classes when there are several), pair, method and
/// altitude interval, in class, pair and record order. Failed profiles are left out.
pub fn summarise(outcomes: &[ProfileOutcome]) -> Vec<Summary> {
    let mut groups: Vec<(String, Vec<&ProfileOutcome>)> = LatitudeClass::ALL
        .iter()
        .map(|c| {
            let members: Vec<&ProfileOutcome> = outcomes.iter().filter(|o| o.class == *c).collect();
            (c.name().to_string(), members)
        })
        .filter(|(_, m)| !m.is_empty())
        .collect();
    if groups.len() > 1 {
        groups.push(("all".into(), outcomes.iter().collect()));
    }
    let mut out = Vec::new();
    for (class, members) in groups {
        let ok: Vec<&Vec<Record>> = members
            .iter()
            .filter_map(|o| o.records.as_ref().ok())
            .collect();
        let Some(first) = ok.first() else {
            continue;
        };
        // Records of every profile come in the same order (same scene, same pairs).
        for (k, r0) in first.iter().enumerate() {
            let recs: Vec<&Record> = ok.iter().filter_map(|rs| rs.get(k)).collect();
            let col =
                |f: &dyn Fn(&Record) -> f64| -> Vec<f64> { recs.iter().map(|r| f(r)).collect() };
            let (truth_mean_ppm, _) = mean_sd(&col(&|r| r.truth_ppm));
            // The noise-free statistics over the profiles whose noise-free values are all
            // defined (always from the analytic lidar equation; from a Monte Carlo with few
            // photons a window may hold none), so that every budget row and the total are
            // over the same profiles.
            let defined: Vec<&Record> = recs.iter().copied().filter(|r| r.is_defined()).collect();
            let col =
                |f: &dyn Fn(&Record) -> f64| -> Vec<f64> { defined.iter().map(|r| f(r)).collect() };
            let (bias_ppm, sd_ppm) = mean_sd(&col(&|r| r.error_ppm()));
            // The noisy statistics over those whose noisy measurement was retrieved too (a
            // far DIAL cell from space often has no positive noisy signal).
            let noisy: Vec<&Record> = defined
                .iter()
                .copied()
                .filter(|r| r.retrieved_noisy_ppm.is_finite())
                .collect();
            let noisy_col =
                |f: &dyn Fn(&Record) -> f64| -> Vec<f64> { noisy.iter().map(|r| f(r)).collect() };
            let (noisy_bias_ppm, noisy_sd_ppm) = mean_sd(&noisy_col(&|r| r.error_noisy_ppm()));
            let (_, noise_sd) = mean_sd(&noisy_col(&|r| r.retrieved_noisy_ppm - r.retrieved_ppm));
            let noisy_random = rms(&noisy_col(&|r| r.budget_ppm[0]));
            let mut sources = [SourceStats {
                bias_ppm: 0.0,
                sd_ppm: 0.0,
                rms_ppm: 0.0,
                share: 0.0,
            }; N_SOURCES];
            for (j, s) in sources.iter_mut().enumerate() {
                let v = col(&|r| r.budget_ppm[j]);
                if j == 0 {
                    let rms = rms(&v);
                    *s = SourceStats {
                        bias_ppm: if v.is_empty() { f64::NAN } else { 0.0 },
                        sd_ppm: rms,
                        rms_ppm: rms,
                        share: 0.0,
                    };
                } else {
                    let (m, sd) = mean_sd(&v);
                    // One profile: no spread (none: nothing, NaN, empty fields).
                    let sd = if v.len() == 1 { 0.0 } else { sd };
                    *s = SourceStats {
                        bias_ppm: m,
                        sd_ppm: sd,
                        rms_ppm: (m * m + sd * sd).sqrt(),
                        share: 0.0,
                    };
                }
            }
            let total2: f64 = sources.iter().map(|s| s.rms_ppm * s.rms_ppm).sum();
            for s in &mut sources {
                s.share = if total2 > 0.0 {
                    s.rms_ppm * s.rms_ppm / total2
                } else if defined.is_empty() {
                    f64::NAN
                } else {
                    0.0
                };
            }
            out.push(Summary {
                class: class.clone(),
                pair: r0.pair.clone(),
                method: r0.method,
                altitude_m: r0.altitude_m,
                profiles: recs.len(),
                retrieved_profiles: defined.len(),
                noisy_profiles: noisy.len(),
                truth_mean_ppm,
                bias_ppm,
                sd_ppm,
                noisy_bias_ppm,
                noisy_sd_ppm,
                noise_ratio: noise_sd / noisy_random,
                sources,
                total_ppm: total2.sqrt(),
            });
        }
    }
    out
}

/// `profiles.nc` beside `profiles.csv`.
pub const PROFILES_NC: &str = "profiles.nc";
/// `summary.nc` beside `summary.csv`.
pub const SUMMARY_NC: &str = "summary.nc";

/// The records of the profiles that ran as a CF NetCDF file (`profiles.nc`): the columns of
/// `profiles.csv` at full precision over the dimension `row`, one row per profile, line pair
/// and retrieved quantity, in the CSV's order ([`crate::netcdf::table_file`]). Mixing ratios
/// in ppm have the units `1e-6` (UDUNITS, CF-1.8 §3.1). An error when no profile has records.
pub fn profiles_netcdf(
    outcomes: &[ProfileOutcome],
    title: &str,
    history: &str,
) -> Result<Vec<u8>, crate::netcdf::NetcdfError> {
    use crate::netcdf::{Column, ColumnValues::Number, ColumnValues::Text, table_file};
    let rows: Vec<(&ProfileOutcome, &Record)> = outcomes
        .iter()
        .filter_map(|o| o.records.as_ref().ok().map(|r| (o, r)))
        .flat_map(|(o, records)| records.iter().map(move |r| (o, r)))
        .collect();
    let text = |name, long_name, f: &dyn Fn(&ProfileOutcome, &Record) -> String| Column {
        name,
        long_name,
        units: None,
        values: Text(rows.iter().map(|(o, r)| f(o, r)).collect()),
    };
    let num = |name, long_name, units, f: &dyn Fn(&Record) -> f64| Column {
        name,
        long_name,
        units: Some(units),
        values: Number(rows.iter().map(|(_, r)| f(r)).collect()),
    };
    let mut columns = vec![
        text("profile_id", "profile id in its set", &|o, _| o.id.clone()),
        text("class", "latitude class", &|o, _| o.class.to_string()),
        text("pair", "on-line/off-line pair", &|_, r| r.pair.clone()),
        text(
            "method",
            "retrieved quantity: ipda (column to the hard target) or dial (a cell)",
            &|_, r| r.method.label().to_string(),
        ),
        num(
            "altitude_bottom_m",
            "bottom of the altitude interval",
            "m",
            &|r| r.altitude_m.0,
        ),
        num(
            "altitude_top_m",
            "top of the altitude interval",
            "m",
            &|r| r.altitude_m.1,
        ),
        num(
            "truth_ppm",
            "true CO2 dry-air mole fraction of the profile",
            "1e-6",
            &|r| r.truth_ppm,
        ),
        num(
            "retrieved_ppm",
            "CO2 dry-air mole fraction retrieved from noise-free signals with class-mean virtual cross-sections",
            "1e-6",
            &|r| r.retrieved_ppm,
        ),
        num(
            "error_ppm",
            "retrieved_ppm - truth_ppm",
            "1e-6",
            &Record::error_ppm,
        ),
        num(
            "retrieved_noisy_ppm",
            "CO2 dry-air mole fraction retrieved from one noisy averaged measurement",
            "1e-6",
            &|r| r.retrieved_noisy_ppm,
        ),
        num(
            "error_noisy_ppm",
            "retrieved_noisy_ppm - truth_ppm",
            "1e-6",
            &Record::error_noisy_ppm,
        ),
        num(
            "retrieved_own_profile_ppm",
            "CO2 dry-air mole fraction retrieved from noise-free signals with the profile's own state as reference",
            "1e-6",
            &|r| r.retrieved_own_ppm,
        ),
    ];
    for (j, src) in Source::ALL.iter().enumerate() {
        columns.push(num(src.column(), src.long_name(), "1e-6", &|r| {
            r.budget_ppm[j]
        }));
    }
    table_file("row", &columns, title, history)
}

/// The statistics as a CF NetCDF file (`summary.nc`): the columns of `summary.csv` at full
/// precision over the dimension `row`, one row per class (and `all`), line pair and retrieved
/// quantity ([`crate::netcdf::table_file`]). An error when there are no rows.
pub fn summary_netcdf(
    summaries: &[Summary],
    title: &str,
    history: &str,
) -> Result<Vec<u8>, crate::netcdf::NetcdfError> {
    use crate::netcdf::{Column, ColumnValues::Number, ColumnValues::Text, table_file};
    let text = |name, long_name, f: fn(&Summary) -> String| Column {
        name,
        long_name,
        units: None,
        values: Text(summaries.iter().map(f).collect()),
    };
    let num = |name, long_name, units, f: fn(&Summary) -> f64| Column {
        name,
        long_name,
        units: Some(units),
        values: Number(summaries.iter().map(f).collect()),
    };
    let columns = [
        text("class", "latitude class, or all", |m| m.class.clone()),
        text("pair", "on-line/off-line pair", |m| m.pair.clone()),
        text(
            "method",
            "retrieved quantity: ipda (column to the hard target) or dial (a cell)",
            |m| m.method.label().to_string(),
        ),
        num(
            "altitude_bottom_m",
            "bottom of the altitude interval",
            "m",
            |m| m.altitude_m.0,
        ),
        num("altitude_top_m", "top of the altitude interval", "m", |m| {
            m.altitude_m.1
        }),
        num(
            "profiles",
            "profiles in the group (failed ones excluded)",
            "1",
            |m| m.profiles as f64,
        ),
        num(
            "retrieved_profiles",
            "profiles whose noise-free values could all be computed (the members of bias_ppm, sd_ppm and the budget; fewer than profiles only from Monte Carlo returns with windows that hold no energy)",
            "1",
            |m| m.retrieved_profiles as f64,
        ),
        num(
            "noisy_profiles",
            "of the retrieved_profiles, those whose noisy measurement could be retrieved (the members of noisy_bias_ppm, noisy_sd_ppm and noise_ratio)",
            "1",
            |m| m.noisy_profiles as f64,
        ),
        num(
            "truth_mean_ppm",
            "mean true CO2 dry-air mole fraction",
            "1e-6",
            |m| m.truth_mean_ppm,
        ),
        num(
            "bias_ppm",
            "mean of retrieved - truth, noise-free",
            "1e-6",
            |m| m.bias_ppm,
        ),
        num(
            "sd_ppm",
            "standard deviation of retrieved - truth, noise-free",
            "1e-6",
            |m| m.sd_ppm,
        ),
        num(
            "noisy_bias_ppm",
            "mean of retrieved - truth, one noisy measurement per profile",
            "1e-6",
            |m| m.noisy_bias_ppm,
        ),
        num(
            "noisy_sd_ppm",
            "standard deviation of retrieved - truth, one noisy measurement per profile",
            "1e-6",
            |m| m.noisy_sd_ppm,
        ),
        num(
            "random_error_rms_ppm",
            "rms of the analytic random error of one averaged measurement",
            "1e-6",
            |m| m.sources[0].rms_ppm,
        ),
        num(
            "noise_ratio",
            "standard deviation of noisy - noise-free over the rms analytic random error",
            "1",
            |m| m.noise_ratio,
        ),
        num(
            "total_budget_ppm",
            "root-sum-square of every budget row's rms",
            "1e-6",
            |m| m.total_ppm,
        ),
    ];
    table_file("row", &columns, title, history)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// profiles.csv's budget columns (and profiles.nc's variables) are the labels with `_ppm`,
    /// each named once.
    #[test]
    fn budget_columns_are_the_labels_in_ppm() {
        for s in Source::ALL {
            assert_eq!(s.column(), format!("{}_ppm", s.label()));
            assert!(!s.long_name().is_empty());
        }
        let mut names: Vec<&str> = Source::ALL.iter().map(|s| s.long_name()).collect();
        names.sort();
        names.dedup();
        assert_eq!(names.len(), N_SOURCES);
    }

    /// No rows, no file: the callers skip it.
    #[test]
    fn empty_tables_are_refused() {
        assert!(profiles_netcdf(&[], "t", "h").is_err());
        assert!(summary_netcdf(&[], "t", "h").is_err());
    }
}
