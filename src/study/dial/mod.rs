//! A scene's DIAL/IPDA retrievals over an ensemble of profiles, with an error budget.
//!
//! For every profile of a set the scene is run with that profile as the truth
//! ([`Scene::with_profile`]): optics, the analytic lidar equation (or the Monte Carlo, with
//! photons), line returns, signals, and the retrievals of every on/off pair asked for. The
//! retrieval is the reference study's: the slant column from **virtual cross-sections of the
//! ensemble-mean profile of the profile's latitude class**, σ = −ln T_gas/(2N) (docs/design.md §3), and
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

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::Instant;

use rand::RngExt;
use rayon::prelude::*;
use thiserror::Error;

use crate::atmosphere::humidity::{SaturationOver, saturation_vapour_pressure_pa};
use crate::atmosphere::{LatitudeClass, Profile, ProfileSet, SetMember, StateShift, shift_member};
use crate::instrument::laser::{Filter, Laser, LineReturns, SampledChannel};
use crate::instrument::line_shape::LineShape;
use crate::instrument::signals::Signals;
use crate::lidar_eq;
use crate::optics::OpticalAtmosphere;
use crate::pipeline;
use crate::retrieval::{
    AssumedInstrument, LayerColumns, Method, Product, Quantity, ReferenceState, Retrieval,
    RetrievalConfig,
};
use crate::returns::Order;
use crate::rng::{self, Stream};
use crate::scene::Scene;
use crate::spectroscopy::LayerDepthMemo;

mod netcdf;
mod profile;
mod summary;

pub use netcdf::{PROFILES_NC, SUMMARY_NC, profiles_dataset, summary_dataset};
pub use summary::{SourceStats, Summary, summarise};

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

impl BudgetSteps {
    /// Every step finite and inside the range `lidarsim dial`'s options allow (the humidity
    /// and line-width steps as fractions: −50 … 1000 % and above −100 … 1000 %); an error names
    /// the step.
    pub fn check(&self) -> Result<(), String> {
        use crate::input::{Bounds, check_finite_range as check};
        let steps = [
            (
                "temperature_k",
                self.temperature_k,
                Bounds::closed(-100.0, 100.0),
            ),
            (
                "humidity_fraction",
                self.humidity_fraction,
                Bounds::closed(-0.5, 10.0),
            ),
            (
                "surface_pressure_hpa",
                self.surface_pressure_hpa,
                Bounds::closed(-100.0, 100.0),
            ),
            (
                "frequency_offset_mhz",
                self.frequency_offset_mhz,
                Bounds::closed(-1e5, 1e5),
            ),
            (
                "linewidth_fraction",
                self.linewidth_fraction,
                Bounds::above(-1.0, 10.0),
            ),
        ];
        for (name, v, bounds) in steps {
            check(v, bounds).map_err(|m| format!("budget step {name}: {m}"))?;
        }
        Ok(())
    }
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
    /// Of `returns_s`, the Monte Carlo transport (0 without photons; not kept by shards).
    pub transport_s: f64,
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
    /// The study was stopped before its end ([`run_until`]).
    #[error("the study was stopped before its end")]
    Stopped,
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
    transport: AtomicU64,
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
    run_slice(scene, set, options, 0..set.len(), progress, None)
}

/// [`run`], stopping soon after `stop` is set (from another thread: a user's Ctrl-C) with
/// [`StudyError::Stopped`]: the profiles not yet begun are not run (one under way finishes).
pub fn run_until(
    scene: &Scene,
    set: &ProfileSet,
    options: &StudyOptions,
    progress: &(dyn Fn() + Sync),
    stop: &AtomicBool,
) -> Result<StudyResult, StudyError> {
    run_slice(scene, set, options, 0..set.len(), progress, Some(stop))
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
    stop: Option<&AtomicBool>,
) -> Result<StudyResult, StudyError> {
    let stopped = || stop.is_some_and(|s| s.load(Ordering::Relaxed));
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
    // Profiles that cannot be run are found first: they take no part in the class means. Only
    // the verdict is kept (each profile's scene is made again when it runs): a scene per
    // profile held for the whole study was most of its memory (about 45 kB each).
    let checked: Vec<Result<(), String>> = set
        .members
        .par_iter()
        .map(|m| study.usable(m).map(|_| ()))
        .collect();
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
    let one = |((member, seed), ok): ((&SetMember, &u64), &Result<(), String>)| {
        let records = match ok {
            _ if stopped() => Err("stopped".into()),
            Ok(()) => study
                .usable(member)
                .and_then(|scene| study.profile(member, scene, *seed)),
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
    if stopped() {
        return Err(StudyError::Stopped);
    }
    let secs = |c: &AtomicU64| c.load(Ordering::Relaxed) as f64 * 1e-9;
    let timing = Timing {
        mean_references_s,
        truth_optics_s: secs(&study.clock.truth_optics),
        returns_s: secs(&study.clock.returns),
        transport_s: secs(&study.clock.transport),
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

/// The profiles of `set` that cannot be run through `scene` at all (they do not fit it, lack a
/// gas its lines absorb, or are supersaturated), grouped by reason: what [`run`] finds before
/// its first profile and leaves out. Found in a fraction of the study's time, so that a study
/// that must not lose any profile ([`crate::study::FailurePolicy::Strict`]) is refused before
/// its work; profiles whose retrieval fails are found only by running them.
pub fn unusable(scene: &Scene, set: &ProfileSet) -> crate::study::FailureReport {
    let failed: Vec<(String, String)> = set
        .members
        .par_iter()
        .filter_map(|m| {
            profile::usable_in(scene, m)
                .err()
                .map(|e| (m.meta.id.clone(), e))
        })
        .collect();
    crate::study::FailureReport::new(
        set.len(),
        failed.iter().map(|(id, e)| (id.as_str(), e.as_str())),
    )
}

/// Where a study's profiles come from.
#[derive(Debug, Clone, PartialEq)]
pub enum ProfileSource {
    /// A profile set file (lidarsim format), its members of the classes asked for.
    Set(std::path::PathBuf),
    /// `n` members per class generated around the class's AFGL mean with the representative
    /// NWP forecast-error covariance; class i of tropical, mid, high takes seed `seed + i`.
    Ensemble(usize),
    /// A set in memory (the Python package's profiles), its members of the classes asked for.
    Given(ProfileSet),
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
    let of_classes = |set: &ProfileSet| -> Result<ProfileSet, StudyError> {
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
                set.name
            )));
        }
        Ok(out)
    };
    let n = match source {
        ProfileSource::Set(path) => {
            let set = crate::atmosphere::read_profile_set(path)
                .map_err(|e| StudyError::Profiles(e.to_string()))?;
            return of_classes(&set);
        }
        ProfileSource::Given(set) => return of_classes(set),
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

#[cfg(test)]
mod tests;
