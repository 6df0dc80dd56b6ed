//! Scenes: the description of a lidar, its channels, range gates, atmosphere, particle layers,
//! surface and simulation settings, and the resolved [`Scene`] the stages use.
//!
//! **contract** (docs/design.md §4): units in every key name, full angles where a cone is meant, every
//! unknown key rejected with the file, line and key named. The key reference is in README.md;
//! the files in `scenes/` are worked examples.
//!
//! A scene goes through three steps, each in its own file:
//! 1. **parse** ([`SceneDescription::parse`], `description.rs`): serde reads the TOML into the
//!    plain [`SceneDescription`] (types, unknown keys, missing keys; byte spans become line
//!    numbers). A description may as well be built in Rust code.
//! 2. **validate** ([`SceneDescription::validate`], `validate.rs`, `validate_atmosphere.rs`,
//!    `validate_instrument.rs`, `validate_retrieval.rs`): every check that needs only the description's values (ranges,
//!    one-of keys, per-channel lengths, names, layer order, the surface against the lidar and
//!    the gates, the laser, receiver and background, the retrieval's lines, target and cells,
//!    the problem's size), with no file read and no physics. A problem is named at its file, line and key (`source.rs`), or at its field path
//!    (`layer[2].particles`) for a description built in code, with the same message.
//! 3. **resolve** ([`SceneDescription::resolve`], `resolve.rs`, `resolve_gas.rs`,
//!    `resolve_instrument.rs`): the profile sets, phase, matrix and line-shape tables and line
//!    lists read, Mie theory run (and cached), the laser lines sampled; the checks that need
//!    what those give.
//!
//! [`Scene::read`] and [`Scene::from_toml`] do all three; [`Scene::read_with`] reads `-` as
//! standard input and first applies the command line's `--set KEY=VALUE` overrides to the TOML
//! text (`overrides.rs`), so that an override goes through the same three steps, its errors
//! named `--set KEY`. [`SceneDescription::resolve_reusing`]
//! (`reuse.rs`) resolves an edited description keeping what a previous scene resolved from the
//! parts the edit left unchanged; [`Scene::with_profile`] and [`Scene::with_laser`] are such
//! edits.

mod description;
mod overrides;
mod ranges;
mod resolve;
mod resolve_gas;
mod resolve_instrument;
mod resolver;
mod reuse;
mod source;
mod validate;
mod validate_atmosphere;
mod validate_instrument;
mod validate_retrieval;
mod validator;
mod variance;
pub mod warnings;

use std::path::{Path, PathBuf};
use std::sync::Arc;

use crate::atmosphere::{Co2Scaling, Profile};
use crate::input::{InputError, check_count};
use crate::instrument::laser::{Filter, Laser, Line, SampledChannel, SpectralSampling};
use crate::instrument::signals::Receiver;
use crate::particles::matrix::ScatteringMatrix;
use crate::particles::phase::PhaseFunction;
use crate::retrieval::RetrievalConfig;
use crate::spectroscopy::{LblOptions, LineList};

pub use description::{
    AtmosphereDescription, BackgroundDescription, ChannelDescription, GasAbsorptionDescription,
    GasDescription, GatesDescription, LaserDescription, LayerDescription, LidarDescription,
    LineShapeTableDescription, OneOrMany, ParticlesDescription, PerChannel, PhaseDescription,
    ProfileDescription, ReceiverDescription, RetrievalDescription, SceneDescription,
    SimulationDescription, SurfaceDescription,
};
pub use overrides::SceneOverride;
use source::{KeyPath, Source};
pub use variance::{
    ALIGNMENT_SPLITTING, DDIS_EPSILON, RANGE_STRATIFICATION, ROULETTE_ALIGNMENT, VarianceReduction,
};

/// The scene run when `lidarsim run` gets no file.
pub const DEFAULT_SCENE_TOML: &str = include_str!("../../scenes/spaceborne_co2_ipda.toml");
/// Pseudo-path of the embedded default scene in messages.
pub const DEFAULT_SCENE_NAME: &str = "<embedded default scene>";
/// Pseudo-path of a scene read from standard input (`-` as its path) in messages.
pub const STDIN_NAME: &str = "<stdin>";

/// A resolved scene: what the stages use. Made by [`SceneDescription::resolve`] (or
/// [`Scene::from_toml`] / [`Scene::read`]); editing its public fields skips the checks, editing
/// the description ([`Scene::as_description`]) and resolving again does not.
#[derive(Debug, Clone)]
pub struct Scene {
    /// The file it came from (or [`DEFAULT_SCENE_NAME`]).
    pub path: PathBuf,
    /// Free text.
    pub description: String,
    /// The lidar: platform, pointing, emitter, receiver.
    pub lidar: Lidar,
    /// The laser lines as the scene names them (`[[channel]]`), in file order.
    pub lines: Vec<Channel>,
    /// The monochromatic channels of the transport: the lines themselves, or with a `[laser]`
    /// their line-shape nodes, jitter stencil and impurity ([`SpectralSampling`]). Channel 0 is
    /// the reference channel of the transport. Per-channel values of layers, surface and
    /// atmosphere are those of each channel's line.
    pub channels: Vec<Channel>,
    /// The laser (an ideal monochromatic one when the scene has no `[laser]`).
    pub laser: Laser,
    /// How the channels sample the lines, and the combinations that make line returns.
    pub sampling: SpectralSampling,
    /// The receiver's filter, detector and background (`[receiver]`, `[background]`), if any.
    pub receiver: Option<Receiver>,
    /// What to retrieve (`[retrieval]`), if anything.
    pub retrieval: Option<RetrievalConfig>,
    /// Range gates.
    pub gates: Gates,
    /// Molecular atmosphere, if any.
    pub atmosphere: Option<Atmosphere>,
    /// Particle and absorber layers.
    pub layers: Vec<Layer>,
    /// Lambertian surface, if any.
    pub surface: Option<Surface>,
    /// Line-by-line gas absorption, if any.
    pub gas: Option<GasAbsorption>,
    /// Warnings about the scene's values, each `FILE:LINE: key: …` ([`warnings`]): accepted but
    /// seldom meant (a layer of optical depth above 100), or making the numbers mean less than
    /// they seem (gates the detector does not resolve). Printed once by the command line.
    pub warnings: Vec<String>,
    /// The run settings: everything that says how a scene is run rather than what it is (photons,
    /// seed, batches, threads, orders, when the Monte Carlo runs, its variance reductions). The one
    /// settings type: the transport, the pipeline, shards and MPI read them from here.
    pub simulation: Simulation,
    /// The description it was resolved from.
    spec: Arc<SceneDescription>,
    /// The directory its relative paths are anchored at.
    base_dir: PathBuf,
    /// Where the description came from: names the line (or field path) of a key in errors
    /// found after resolving, and holds the scene text.
    source: Arc<Source>,
}

/// Gas absorption line by line, from the atmosphere's gas profiles.
#[derive(Debug, Clone)]
pub struct GasAbsorption {
    /// The lines (a HITRAN file or the built-in CO2 30012 band model), already cut to the
    /// channels' window plus the wing.
    pub lines: Arc<LineList>,
    /// Line-by-line options (wing cutoff etc.).
    pub options: LblOptions,
    /// Cache of layer optical depths on a wavenumber grid: reused when it matches, else
    /// computed and written.
    pub table: Option<GasTable>,
}

/// Where and on which grid to cache layer optical depths.
#[derive(Debug, Clone, PartialEq)]
pub struct GasTable {
    /// The table file.
    pub path: PathBuf,
    /// Grid for a new table [cm⁻¹].
    pub start_cm1: f64,
    /// End of the grid [cm⁻¹].
    pub end_cm1: f64,
    /// Step [cm⁻¹].
    pub step_cm1: f64,
}

/// Beam divergence profile.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BeamProfile {
    /// Directions uniform in solid angle inside the full divergence angle.
    Uniform,
    /// Gaussian in angle; the full divergence angle is the 1/e² intensity diameter.
    Gaussian,
}

/// The polarisation of the emitted light (`[lidar] polarisation`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Polarisation {
    /// Unpolarised light and scalar transport (the default).
    #[default]
    None,
    /// Linearly polarised along the lidar frame's first axis perpendicular to the pointing.
    Linear,
    /// Circularly polarised (Stokes V = +1 about the direction of emission).
    Circular,
}

impl Polarisation {
    /// The scene-file word.
    pub fn name(self) -> &'static str {
        match self {
            Polarisation::None => "none",
            Polarisation::Linear => "linear",
            Polarisation::Circular => "circular",
        }
    }
}

/// A monostatic, coaxial lidar.
#[derive(Debug, Clone, PartialEq)]
pub struct Lidar {
    /// Altitude of the lidar above the scene's zero \[m\].
    pub altitude_m: f64,
    /// Pointing: angle from the upward vertical \[deg\] (0 looks up, 180 looks down).
    pub zenith_angle_deg: f64,
    /// Pointing azimuth \[deg\] (matters only for the direction of a slant path).
    pub azimuth_deg: f64,
    /// Pulse energy the transport and the lidar equation run with \[J\]: the first laser line's
    /// (the line combinations scale the others by their own energies).
    pub pulse_energy_j: f64,
    /// Full divergence angle of the beam \[mrad\] (0: pencil beam).
    pub beam_divergence_full_angle_mrad: f64,
    /// Shape of the divergence.
    pub beam_profile: BeamProfile,
    /// Telescope diameter \[m\].
    pub telescope_diameter_m: f64,
    /// Receiver optical efficiency (0–1].
    pub optical_efficiency: f64,
    /// Receiver fields of view, full angles \[mrad\], all tallied in one run.
    pub fov_full_angle_mrad: Vec<f64>,
    /// Polarisation of the emitted light; not `None`: Stokes-vector transport and co- and
    /// cross-polarised returns.
    pub polarisation: Polarisation,
}

impl Lidar {
    /// Telescope collecting area \[m²\].
    pub fn telescope_area_m2(&self) -> f64 {
        std::f64::consts::PI * 0.25 * self.telescope_diameter_m * self.telescope_diameter_m
    }

    /// Unit pointing vector (z up; azimuth from +x toward +y).
    pub fn axis(&self) -> glam::DVec3 {
        let (st, ct) = self.zenith_angle_deg.to_radians().sin_cos();
        let (sp, cp) = self.azimuth_deg.to_radians().sin_cos();
        glam::DVec3::new(st * cp, st * sp, ct)
    }
}

/// One monochromatic channel.
#[derive(Debug, Clone, PartialEq)]
pub struct Channel {
    /// Name (`on`, `off`, …).
    pub name: String,
    /// Vacuum wavenumber [cm⁻¹].
    pub wavenumber_cm1: f64,
}

impl Channel {
    /// Vacuum wavelength \[nm\].
    pub fn wavelength_nm(&self) -> f64 {
        1e7 / self.wavenumber_cm1
    }
}

/// Range gates [start, start + count·width).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Gates {
    /// Start of the first gate \[m\].
    pub start_m: f64,
    /// Gate width \[m\].
    pub width_m: f64,
    /// Number of gates.
    pub count: usize,
}

impl Gates {
    /// End of the last gate \[m\].
    pub fn end_m(&self) -> f64 {
        self.start_m + self.width_m * self.count as f64
    }
    /// Centre of gate i \[m\].
    pub fn centre_m(&self, i: usize) -> f64 {
        self.start_m + (i as f64 + 0.5) * self.width_m
    }
}

/// Where molecular scattering comes from.
#[derive(Debug, Clone, PartialEq)]
pub struct Atmosphere {
    /// The profile (altitudes in the scene's frame).
    pub profile: Profile,
    /// Thickness of the optical layers the molecular atmosphere is cut into \[m\].
    pub layer_thickness_m: f64,
    /// Top of the model atmosphere \[m\].
    pub top_m: f64,
    /// Rayleigh scattering on or off.
    pub rayleigh: bool,
    /// Depolarisation factor per channel (Bucholtz 1995 Table 1 unless given).
    pub depolarisation_factor: Vec<f64>,
    /// The CO2 the scene asks for \[ppm\] (`co2_ppm`), applied to its profile and to any
    /// profile swapped in ([`Scene::with_profile`]) as `co2_scaling` says.
    pub co2_ppm: Option<f64>,
    /// How `co2_ppm` is applied (`co2_scaling`; well mixed in dry air unless the scene says
    /// `profile_shape`).
    pub co2_scaling: Co2Scaling,
}

/// A horizontal layer of particles and/or extra absorption.
#[derive(Debug, Clone)]
pub struct Layer {
    /// Name for messages.
    pub name: String,
    /// Base altitude \[m\].
    pub base_m: f64,
    /// Top altitude \[m\].
    pub top_m: f64,
    /// Particle extinction coefficient per channel [1/m].
    pub extinction_per_m: Vec<f64>,
    /// Particle single-scattering albedo per channel.
    pub single_scattering_albedo: Vec<f64>,
    /// Particle phase function per channel.
    pub phase: Vec<Arc<PhaseFunction>>,
    /// Particle scattering matrix per channel, whose F11 is `phase` (for polarised transport):
    /// Mie layers and `matrix_table` layers their tabulated matrix, `rayleigh` layers the
    /// molecular matrix, other scalar phase functions a non-depolarising stand-in
    /// ([`ScatteringMatrix::NonDepolarising`]).
    pub matrix: Vec<Arc<ScatteringMatrix>>,
    /// Extra (e.g. gas) absorption coefficient per channel [1/m].
    pub absorption_per_m: Vec<f64>,
}

impl Layer {
    /// True when the layer scatters in some channel through a non-depolarising stand-in for
    /// its matrix (a scalar phase function with no polarisation behind it).
    pub fn uses_stand_in(&self) -> bool {
        (0..self.matrix.len()).any(|k| {
            self.matrix[k].is_stand_in()
                && self.extinction_per_m[k] * self.single_scattering_albedo[k] > 0.0
        })
    }
}

/// A Lambertian surface.
#[derive(Debug, Clone, PartialEq)]
pub struct Surface {
    /// Altitude \[m\].
    pub altitude_m: f64,
    /// Albedo per channel.
    pub albedo: Vec<f64>,
}

/// The run settings: everything that says how a scene is run rather than what it is (photons,
/// seed, batches, threads, orders, when the Monte Carlo runs, its variance reductions). The one
/// settings type: the transport, the pipeline, shards and MPI read them from here.
#[derive(Debug, Clone, PartialEq)]
pub struct Simulation {
    /// Number of photon packets (0: analytic single scattering only, no Monte Carlo).
    pub photons: u64,
    /// Random seed.
    pub seed: u64,
    /// Highest scattering order tallied separately; higher orders go into `N+`.
    pub max_order: u32,
    /// Worker threads (0: all cores).
    pub threads: usize,
    /// Independent batches for the standard errors.
    pub batches: usize,
    /// Directory for cached Mie optics: the scene's `cache_dir` (relative to the scene), else
    /// [`crate::particles::cache::default_cache_dir`]; none when turned off.
    pub cache_dir: Option<PathBuf>,
    /// Whether the Monte Carlo runs (`multiple_scattering`; `--photons N` on the command line
    /// makes it [`MultipleScattering::Always`]).
    pub multiple_scattering: MultipleScattering,
    /// The multiple-scattering share of a return below which `"auto"` skips the Monte Carlo
    /// (`multiple_scattering_tolerance`, default [`MULTIPLE_SCATTERING_TOLERANCE`]).
    pub multiple_scattering_tolerance: f64,
    /// Tally the Monte Carlo returns' derivatives with respect to every layer's absorption,
    /// molecular and particle scattering and particle extinction, from the same photons
    /// (`jacobians`; `docs/transport.md`, "Jacobians").
    pub jacobians: bool,
    /// The Monte Carlo's variance reductions (not in the scene file: defaults, which the
    /// command line and the benchmarks may change).
    pub variance_reduction: VarianceReduction,
}

/// When the Monte Carlo runs (`[simulation] multiple_scattering`). Single scattering always
/// comes from the analytic lidar equation; the Monte Carlo adds multiple scattering (and an
/// independent check of the single).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum MultipleScattering {
    /// Skip the Monte Carlo when it cannot change the answer: the bound on all orders ≥ 2
    /// ([`crate::lidar_eq::multiple_scattering_bound`]) is below the tolerance in every
    /// return, and so is the retrievals' change ([`crate::skip`]).
    #[default]
    Auto,
    /// Always run the Monte Carlo (with `photons` > 0).
    Always,
    /// Never run it: the analytic single-scatter returns alone.
    Never,
}

impl MultipleScattering {
    /// The scene-file spelling.
    pub fn label(self) -> &'static str {
        match self {
            MultipleScattering::Auto => "auto",
            MultipleScattering::Always => "always",
            MultipleScattering::Never => "never",
        }
    }
}

/// Default `multiple_scattering_tolerance`: 0.1 % of the single-scatter return, below the
/// Monte Carlo's own error on it at the shipped photon counts and an order of magnitude below
/// the 1 % that DIAL/IPDA error budgets give to the lidar equation's assumptions.
pub const MULTIPLE_SCATTERING_TOLERANCE: f64 = 1e-3;

/// Pseudo-path of a description built in code, in messages.
pub const DESCRIPTION_NAME: &str = "<scene description>";

impl SceneDescription {
    /// Parse scene text (step 1): serde's checks of types and keys, and every number finite.
    /// `path` names the file in errors.
    pub fn parse(path: &Path, text: &str) -> Result<SceneDescription, InputError> {
        let d: SceneDescription =
            toml::from_str(text).map_err(|e| source::toml_error(path, text, &e))?;
        source::non_finite_value(path, text)?;
        Ok(d)
    }

    /// The description as TOML text, which [`Self::parse`] reads back to an equal description.
    pub fn to_toml(&self) -> Result<String, InputError> {
        toml::to_string(self)
            .map_err(|e| InputError::file(DESCRIPTION_NAME, format!("cannot write as TOML: {e}")))
    }

    /// Check every value (step 2) without reading a file or doing physics; an error names the
    /// field path (`layer[2].top_m`).
    pub fn validate(&self) -> Result<(), InputError> {
        let source = self.code_source()?;
        validator::Validator { src: &source }
            .check(self)
            .map(|_| ())
    }

    /// Validate, then resolve (step 3): read the files the description names (relative paths
    /// anchored at `base_dir`), run Mie theory, sample the laser lines. Errors name the field
    /// path.
    pub fn resolve(&self, base_dir: &Path) -> Result<Scene, InputError> {
        let source = self.code_source()?;
        Scene::resolve_from(self.clone(), source, base_dir)
    }

    fn code_source(&self) -> Result<Source, InputError> {
        Ok(Source::code(Path::new(DESCRIPTION_NAME), self.to_toml()?))
    }
}

impl Scene {
    /// Read and validate a scene file.
    pub fn read(path: &Path) -> Result<Scene, InputError> {
        let text = crate::input::read_to_string(path)?;
        Scene::from_toml(path, &text)
    }

    /// Read a scene file, or standard input when `path` is `-` (named [`STDIN_NAME`] in errors;
    /// relative paths inside it resolve against the current directory), with `overrides`
    /// (`--set KEY=VALUE`) applied to its text before it is parsed: an override is checked as
    /// the file is, and an error in it names `--set KEY` instead of a line.
    pub fn read_with(path: &Path, overrides: &[SceneOverride]) -> Result<Scene, InputError> {
        if path == Path::new("-") {
            let mut text = String::new();
            std::io::Read::read_to_string(&mut std::io::stdin().lock(), &mut text)
                .map_err(|e| InputError::file(STDIN_NAME, format!("cannot read the scene: {e}")))?;
            let text = crate::input::strip_bom(&text);
            return Scene::from_toml_with(Path::new(STDIN_NAME), text, Path::new("."), overrides);
        }
        let text = crate::input::read_to_string(path)?;
        Scene::from_toml_with(
            path,
            &text,
            path.parent().unwrap_or(Path::new(".")),
            overrides,
        )
    }

    /// The embedded default scene with `overrides` ([`Self::read_with`]).
    pub fn default_with(overrides: &[SceneOverride]) -> Result<Scene, InputError> {
        let path = Path::new(DEFAULT_SCENE_NAME);
        Scene::from_toml_with(path, DEFAULT_SCENE_TOML, Path::new(""), overrides)
    }

    /// [`Self::from_toml`] with `overrides` applied to the text first and relative paths
    /// anchored at `base_dir`.
    pub fn from_toml_with(
        path: &Path,
        text: &str,
        base_dir: &Path,
        overrides: &[SceneOverride],
    ) -> Result<Scene, InputError> {
        if overrides.is_empty() {
            let d = SceneDescription::parse(path, text)?;
            return Scene::resolve_from(d, Source::toml(path, text), base_dir);
        }
        let edited = overrides::apply(text, overrides)?;
        let d = SceneDescription::parse(path, &edited.text)
            .map_err(|e| overrides::remap(e, path, &edited.origins))?;
        Scene::resolve_from(d, Source::edited(path, edited), base_dir)
    }

    /// The embedded default scene.
    pub fn default_scene() -> Result<Scene, InputError> {
        Scene::from_toml(Path::new(DEFAULT_SCENE_NAME), DEFAULT_SCENE_TOML)
    }

    /// Parse and validate scene text without reading any file it names or doing any physics:
    /// errors name the file, line and key.
    pub fn check_toml(path: &Path, text: &str) -> Result<SceneDescription, InputError> {
        let d = SceneDescription::parse(path, text)?;
        validator::Validator {
            src: &Source::toml(path, text),
        }
        .check(&d)?;
        Ok(d)
    }

    /// Parse, validate and resolve scene text; `path` names the file in errors and anchors
    /// relative paths (phase-function tables) at its directory.
    pub fn from_toml(path: &Path, text: &str) -> Result<Scene, InputError> {
        let d = SceneDescription::parse(path, text)?;
        let base_dir = path.parent().unwrap_or(Path::new("."));
        Scene::resolve_from(d, Source::toml(path, text), base_dir)
    }

    /// Validate and resolve a description whose values came from `source`.
    fn resolve_from(
        d: SceneDescription,
        source: Source,
        base_dir: &Path,
    ) -> Result<Scene, InputError> {
        let checked = validator::Validator { src: &source }.check(&d)?;
        resolver::Resolver {
            src: &source,
            base_dir,
        }
        .scene_reusing(d, checked, None)
    }

    /// The description this scene was resolved from.
    pub fn as_description(&self) -> &SceneDescription {
        &self.spec
    }

    /// The directory its relative paths are anchored at (the scene file's; the one
    /// [`SceneDescription::resolve`] was given).
    pub fn base_dir(&self) -> &Path {
        &self.base_dir
    }
}

impl Scene {
    /// Replace every per-line value (layer optics, albedo, depolarisation) by one value per
    /// channel, each channel taking its line's: particle optics do not change over the few GHz
    /// a line's channels span (an impurity channel far from its line is approximated so too).
    fn expand_per_channel_values(&mut self) {
        let parent: Vec<usize> = self.sampling.channels.iter().map(|c| c.line).collect();
        if parent.iter().enumerate().all(|(i, p)| i == *p) && parent.len() == self.lines.len() {
            return;
        }
        self.remap_per_channel_values(&parent);
    }

    /// Every per-channel value of layers, surface and atmosphere replaced by
    /// `v[index[0]], v[index[1]], …`: from lines to channels and back.
    fn remap_per_channel_values(&mut self, index: &[usize]) {
        fn remap<T: Clone>(v: &mut Vec<T>, index: &[usize]) {
            *v = index.iter().map(|i| v[*i].clone()).collect();
        }
        if let Some(a) = &mut self.atmosphere {
            remap(&mut a.depolarisation_factor, index);
        }
        for l in &mut self.layers {
            remap(&mut l.extinction_per_m, index);
            remap(&mut l.single_scattering_albedo, index);
            remap(&mut l.phase, index);
            remap(&mut l.matrix, index);
            remap(&mut l.absorption_per_m, index);
        }
        if let Some(s) = &mut self.surface {
            remap(&mut s.albedo, index);
        }
    }

    /// This scene with the channels `extra` appended, each sampling one of its lines (and
    /// carrying that line's per-channel values: optics, albedo, depolarisation). For the
    /// analytic returns of the channels of several lasers on the same lines at once: the
    /// optical atmosphere and the lidar equation of a channel depend on its wavenumber and its
    /// line alone. The laser and the line combinations stay this scene's (they use none of
    /// `extra`); `None` if a channel of `extra` names a line the scene does not have.
    pub fn with_extra_channels(&self, extra: &[SampledChannel]) -> Option<Scene> {
        let mut index: Vec<usize> = (0..self.channels.len()).collect();
        for c in extra {
            index.push(
                self.sampling
                    .channels
                    .iter()
                    .position(|b| b.line == c.line)?,
            );
        }
        let mut out = self.clone();
        out.remap_per_channel_values(&index);
        out.channels.extend(extra.iter().map(|c| Channel {
            name: c.name.clone(),
            wavenumber_cm1: c.wavenumber_cm1,
        }));
        out.sampling.channels.extend(extra.iter().cloned());
        Some(out)
    }

    /// The inverse of [`Self::expand_per_channel_values`]: one value per line again, each
    /// line's from its first channel (all of a line's channels carry the line's value).
    fn collapse_per_channel_values(&mut self) {
        let first: Vec<usize> = (0..self.lines.len())
            .map(|l| {
                self.sampling
                    .channels
                    .iter()
                    .position(|c| c.line == l)
                    .unwrap_or(l)
            })
            .collect();
        if first.len() == self.channels.len() && first.iter().enumerate().all(|(i, f)| i == *f) {
            return;
        }
        self.remap_per_channel_values(&first);
    }

    /// The molecular grid: layer edges from the profile bottom (or the surface) to the top of
    /// the atmosphere in steps of its layer thickness (the last layer may be thinner). Gas
    /// optical depths are computed on it (Curtis-Godson layers), for the truth and for a
    /// retrieval's reference state alike. `None` without an atmosphere.
    pub fn molecular_edges(&self) -> Option<Vec<f64>> {
        let a = self.atmosphere.as_ref()?;
        let mut bottom = a.profile.altitude_m[0];
        if let Some(s) = &self.surface {
            bottom = bottom.max(s.altitude_m);
        }
        let n = ((a.top_m - bottom) / a.layer_thickness_m).ceil().max(1.0) as usize;
        let mut edges: Vec<f64> = (0..n)
            .map(|i| bottom + i as f64 * a.layer_thickness_m)
            .collect();
        edges.push(a.top_m);
        Some(edges)
    }

    /// An error at a key of this scene, with the key's line (for problems found after parsing,
    /// such as a retrieval that cannot be done). `section` is `retrieval`, `laser`, …; `key`
    /// may be empty to name the section.
    pub fn input_error(&self, section: &str, key: &str, message: impl Into<String>) -> InputError {
        let sec = KeyPath::table(section);
        let at = if key.is_empty() { sec } else { sec.key(key) };
        self.source.err(&at, message)
    }

    /// The scene text as it was parsed (the embedded default scene's for it; a description
    /// built in code as [`SceneDescription::to_toml`] writes it).
    pub fn text(&self) -> &str {
        &self.source.text
    }

    /// Override the Monte Carlo settings from the command line (validated like the file).
    pub fn override_simulation(
        &mut self,
        photons: Option<u64>,
        seed: Option<u64>,
        threads: Option<usize>,
    ) -> Result<(), String> {
        if let Some(p) = photons {
            check_count(p, 0, crate::limits::MAX_PHOTONS).map_err(|m| format!("--photons {m}"))?;
            if p != 0 && p < self.simulation.batches as u64 {
                return Err(format!(
                    "--photons {p} is fewer than the {} batches (0 runs the analytic equation only)",
                    self.simulation.batches
                ));
            }
            self.simulation.photons = p;
            // Photons asked for on the command line are traced whatever the scene says.
            if p > 0 {
                self.simulation.multiple_scattering = MultipleScattering::Always;
            }
        }
        if let Some(s) = seed {
            self.simulation.seed = s;
        }
        if let Some(t) = threads {
            check_count(t as u64, 0, crate::limits::MAX_THREADS)
                .map_err(|m| format!("--threads {m} (0: all cores)"))?;
            self.simulation.threads = t;
        }
        Ok(())
    }
}

/// Layers of the molecular grid of `a` from the profile's bottom (at most one more than from a
/// surface above it).
pub(super) fn molecular_layer_count(a: &Atmosphere) -> u64 {
    ((a.top_m - a.profile.altitude_m[0]) / a.layer_thickness_m)
        .ceil()
        .max(1.0) as u64
}

/// The channels that sample `laser`'s `lines` through the receiver's filter (none without a
/// receiver), as the transport's monochromatic channels.
pub(super) fn sample_lines(
    laser: &Laser,
    lines: &[Channel],
    receiver: Option<&Receiver>,
) -> (SpectralSampling, Vec<Channel>) {
    let lines: Vec<Line> = lines
        .iter()
        .map(|c| Line {
            name: c.name.clone(),
            wavenumber_cm1: c.wavenumber_cm1,
        })
        .collect();
    let filter = receiver.map(|r| r.filter).unwrap_or(Filter::none());
    let sampling = SpectralSampling::new(laser, &lines, &filter);
    let channels = sampling
        .channels
        .iter()
        .map(|c| Channel {
            name: c.name.clone(),
            wavenumber_cm1: c.wavenumber_cm1,
        })
        .collect();
    (sampling, channels)
}
