//! Scenes: the TOML description of a lidar, its channels, range gates, atmosphere, particle
//! layers, surface and simulation settings, validated into a [`Scene`].
//!
//! **contract** (DESIGN §4): units in every key name, full angles where a cone is meant, every
//! unknown key rejected with the file, line and key named. The key reference is in README.md;
//! the files in `scenes/` are worked examples.
//!
//! Parsing has two steps: serde reads the file into the `*File` structs (types, unknown keys,
//! missing keys; the TOML parser gives byte spans that become line numbers), then
//! [`Scene::from_toml`] checks values and relations (ranges, per-channel list lengths, layer
//! order) and reports each problem at the line of the key it concerns.

mod file;
mod instrument;
mod ranges;

use std::path::{Path, PathBuf};
use std::sync::Arc;

use crate::atmosphere::{Profile, StandardAtmosphere};
use crate::input::{Bounds, InputError, check_count, check_finite_range};
use crate::instrument::laser::{Filter, Laser, Line, SpectralSampling};
use crate::instrument::signals::Receiver;
use crate::particles::matrix::ScatteringMatrix;
use crate::particles::matrix_table::MatrixTable;
use crate::particles::phase::{HenyeyGreenstein, PhaseFunction, RayleighPhase, TabulatedPhase};
use crate::particles::table::PhaseTable;
use crate::particles::{builtin_table, rayleigh};
use crate::retrieval::RetrievalConfig;
use crate::spectroscopy::{LblOptions, LineFilter, LineList, isotopologues};

use file::{KeyPath, PerChannel, PhaseSpecFile, SceneFile};
use ranges::*;

/// The scene run when `lidarsim run` gets no file.
pub const DEFAULT_SCENE_TOML: &str = include_str!("../../scenes/spaceborne_co2_ipda.toml");
/// Pseudo-path of the embedded default scene in messages.
pub const DEFAULT_SCENE_NAME: &str = "<embedded default scene>";

/// A validated scene. Constructed only by [`Scene::from_toml`] / [`Scene::read`].
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
    /// Monte Carlo settings.
    pub simulation: Simulation,
    /// The scene text, to name the line of a key in errors found after parsing.
    text: Arc<str>,
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
    /// The dry-air column average of CO2 the scene asks for \[ppm\] (`co2_ppm`), applied to
    /// its profile and to any profile swapped in ([`Scene::with_profile`]).
    pub co2_ppm: Option<f64>,
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

/// Monte Carlo settings.
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
    /// Directory for cached Mie optics (relative paths are relative to the scene), if any.
    pub cache_dir: Option<PathBuf>,
    /// Whether the Monte Carlo runs (`multiple_scattering`; `--photons N` on the command line
    /// makes it [`MultipleScattering::Always`]).
    pub multiple_scattering: MultipleScattering,
    /// The multiple-scattering share of a return below which `"auto"` skips the Monte Carlo
    /// (`multiple_scattering_tolerance`, default [`MULTIPLE_SCATTERING_TOLERANCE`]).
    pub multiple_scattering_tolerance: f64,
}

/// When the Monte Carlo runs (`[simulation] multiple_scattering`). Single scattering always
/// comes from the analytic lidar equation; the Monte Carlo adds multiple scattering (and an
/// independent check of the single).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum MultipleScattering {
    /// Skip the Monte Carlo when it cannot change the answer: no particle layer scatters and
    /// the bound on molecular multiple scattering (`lidar_eq::molecular_multiple_scattering_bound`)
    /// is below the tolerance in every field of view and channel.
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

impl Scene {
    /// Read and validate a scene file.
    pub fn read(path: &Path) -> Result<Scene, InputError> {
        let text = crate::input::read_to_string(path)?;
        Scene::from_toml(path, &text)
    }

    /// The embedded default scene.
    pub fn default_scene() -> Result<Scene, InputError> {
        Scene::from_toml(Path::new(DEFAULT_SCENE_NAME), DEFAULT_SCENE_TOML)
    }

    /// Parse and validate scene text; `path` names the file in errors and anchors relative
    /// paths (phase-function tables) at its directory.
    pub fn from_toml(path: &Path, text: &str) -> Result<Scene, InputError> {
        let raw: SceneFile = toml::from_str(text).map_err(|e| file::toml_error(path, text, &e))?;
        file::non_finite_value(path, text)?;
        let v = Validator { path, text };
        v.scene(raw)
    }
}

struct Validator<'a> {
    path: &'a Path,
    text: &'a str,
}

impl Validator<'_> {
    fn err(&self, at: &KeyPath, message: impl Into<String>) -> InputError {
        InputError {
            path: self.path.to_path_buf(),
            line: Some(at.line(self.text)),
            field: Some(at.dotted()),
            message: message.into(),
        }
    }

    /// `v` if it is finite and inside `bounds` (in the unit of the key's name), else an error
    /// at the key: the one check of every number in a scene.
    fn range(&self, at: &KeyPath, v: f64, bounds: Bounds) -> Result<f64, InputError> {
        check_finite_range(v, bounds).map_err(|m| self.err(at, m))
    }

    /// Every value of a per-channel list inside `bounds`.
    fn range_all(&self, at: &KeyPath, v: &[f64], bounds: Bounds) -> Result<(), InputError> {
        for x in v {
            self.range(at, *x, bounds)?;
        }
        Ok(())
    }

    /// Exactly one of two alternative keys, each checked against its own bounds in its own
    /// unit, then scaled to a common unit.
    fn one_of(
        &self,
        section: &KeyPath,
        a: (&str, Option<f64>, f64, Bounds),
        b: (&str, Option<f64>, f64, Bounds),
    ) -> Result<(KeyPath, f64), InputError> {
        let pick = |(name, v, scale, bounds): (&str, f64, f64, Bounds)| {
            let at = section.key(name);
            let v = self.range(&at, v, bounds)?;
            Ok((at, v * scale))
        };
        match (a.1, b.1) {
            (Some(x), None) => pick((a.0, x, a.2, a.3)),
            (None, Some(x)) => pick((b.0, x, b.2, b.3)),
            (Some(_), Some(_)) => Err(self.err(
                &section.key(b.0),
                format!("give `{}` or `{}`, not both", a.0, b.0),
            )),
            (None, None) => Err(self.err(section, format!("needs `{}` or `{}`", a.0, b.0))),
        }
    }

    fn per_channel(
        &self,
        at: &KeyPath,
        v: &PerChannel,
        n_channels: usize,
    ) -> Result<Vec<f64>, InputError> {
        match v {
            PerChannel::One(x) => Ok(vec![*x; n_channels]),
            PerChannel::Many(xs) if xs.len() == n_channels => Ok(xs.clone()),
            PerChannel::Many(xs) => Err(self.err(
                at,
                format!(
                    "has {} values; give one value or one per channel ({n_channels})",
                    xs.len()
                ),
            )),
        }
    }

    fn cache_dir(&self, raw: &SceneFile) -> Option<PathBuf> {
        let d = raw.simulation.as_ref()?.cache_dir.as_ref()?;
        Some(self.path.parent().unwrap_or(Path::new(".")).join(d))
    }

    fn scene(&self, raw: SceneFile) -> Result<Scene, InputError> {
        let (mut lidar, lidar_pulse_energy_j) = self.lidar(&raw)?;
        // Until the channels are expanded at the end, every per-channel value is per line.
        let channels = self.channels(&raw)?;
        let nch = channels.len();
        let laser = self.laser(&raw, &channels, lidar_pulse_energy_j)?;
        // The transport runs with the first line's energy; combinations scale the others.
        lidar.pulse_energy_j = laser.pulse_energy_j[0];
        let gates = self.gates(&raw)?;
        let simulation = self.simulation(&raw)?;
        // A first look at the size with what is known (each line is at least one channel and
        // one line sum), so that a huge problem is refused before Mie theory and line-by-line
        // work on each of its channels.
        self.problem_size(
            &raw,
            &lidar,
            &gates,
            &simulation,
            2 * channels.len() as u64,
            channels.len() as u64,
            None,
            0,
        )?;
        let atmosphere = match &raw.atmosphere {
            Some(a) => Some(self.atmosphere(a, &channels)?),
            None => None,
        };
        let mut layers = Vec::new();
        let cache_dir = self.cache_dir(&raw);
        for (i, l) in raw.layer.iter().enumerate() {
            layers.push(self.layer(i, l, &channels, cache_dir.as_deref(), lidar.polarisation)?);
        }
        let surface = match &raw.surface {
            Some(s) => {
                let sec = KeyPath::table("surface");
                let altitude_m = self.range(&sec.key("altitude_m"), s.altitude_m, ALTITUDE_M)?;
                let albedo = self.per_channel(&sec.key("albedo"), &s.albedo, nch)?;
                self.range_all(&sec.key("albedo"), &albedo, FRACTION)?;
                Some(Surface { altitude_m, albedo })
            }
            None => None,
        };
        if let Some(s) = &surface {
            let at = KeyPath::table("surface").key("altitude_m");
            if lidar.altitude_m < s.altitude_m {
                return Err(self.err(&at, "the lidar is below the surface"));
            }
            if let Some(a) = &atmosphere
                && (s.altitude_m < a.profile.altitude_m[0] || s.altitude_m >= a.top_m)
            {
                return Err(self.err(
                    &at,
                    format!(
                        "{} m is outside the atmosphere profile ({} to {} m)",
                        s.altitude_m, a.profile.altitude_m[0], a.top_m
                    ),
                ));
            }
            for (i, l) in layers.iter().enumerate() {
                if l.base_m < s.altitude_m {
                    return Err(self.err(
                        &KeyPath::array("layer", i).key("base_m"),
                        format!("layer `{}` reaches below the surface", l.name),
                    ));
                }
            }
            // A beam that meets the surface ends there: gates that all start beyond it can
            // receive nothing.
            let mu = lidar.axis().z;
            if mu < 0.0 {
                let surface_range_m = (lidar.altitude_m - s.altitude_m) / -mu;
                if gates.start_m > surface_range_m {
                    return Err(self.err(
                        &KeyPath::table("gates").key("start_m"),
                        format!(
                            "every gate lies beyond the surface, which the beam meets at {surface_range_m:.1} m range"
                        ),
                    ));
                }
            }
        }
        let receiver = self.receiver(&raw, &channels, surface.as_ref().map(|s| s.albedo[0]))?;
        let (sampling, sampled) = sample_lines(&laser, &channels, receiver.as_ref());
        if let Some(c) = sampled.iter().find(|c| !(c.wavenumber_cm1 > 0.0)) {
            return Err(self.err(
                &KeyPath::table("laser").key("frequency_offset_mhz"),
                format!("channel `{}` falls at {} cm⁻¹", c.name, c.wavenumber_cm1),
            ));
        }
        let gas = match &raw.gas_absorption {
            Some(g) => Some(self.gas(g, &sampled, atmosphere.as_ref())?),
            None => None,
        };
        let n_lines = channels.len() as u64;
        self.problem_size(
            &raw,
            &lidar,
            &gates,
            &simulation,
            (sampled.len() + sampling.combinations().len()) as u64,
            n_lines,
            atmosphere.as_ref(),
            layers.len(),
        )?;
        let retrieval = self.retrieval(
            &raw,
            &channels,
            &lidar,
            &laser,
            &gates,
            surface.as_ref(),
            &layers,
            atmosphere.as_ref(),
            gas.as_ref(),
            receiver.is_some(),
        )?;
        let mut scene = Scene {
            path: self.path.to_path_buf(),
            description: raw.description.clone().unwrap_or_default(),
            lidar,
            lines: channels,
            channels: sampled,
            laser,
            sampling,
            receiver,
            retrieval,
            gates,
            atmosphere,
            layers,
            surface,
            gas,
            simulation,
            text: Arc::from(self.text),
        };
        scene.expand_per_channel_values();
        Ok(scene)
    }

    /// The whole problem against the limits of memory and time ([`crate::limits`]), before
    /// anything large is allocated; an error names the key of the largest factor.
    #[allow(clippy::too_many_arguments)]
    fn problem_size(
        &self,
        raw: &SceneFile,
        lidar: &Lidar,
        gates: &Gates,
        simulation: &Simulation,
        channels_and_sums: u64,
        n_lines: u64,
        atmosphere: Option<&Atmosphere>,
        n_particle_layers: usize,
    ) -> Result<(), InputError> {
        use crate::limits::{MAX_OPTICAL_CELLS, MAX_RETURN_BINS, check_product};
        // Every channel, every line sum (and its derivatives) and every pair of lines whose
        // covariance is kept has its own returns.
        let series = channels_and_sums + n_lines * n_lines.saturating_sub(1) / 2;
        let n_channels = channels_and_sums.saturating_sub(n_lines);
        let gates_n = gates.count as u64;
        let fovs = lidar.fov_full_angle_mrad.len() as u64;
        let order_bins = u64::from(simulation.max_order) + 2;
        let blame = [
            (gates_n, KeyPath::table("gates").key("width_m")),
            (fovs, KeyPath::table("lidar").key("fov_full_angle_mrad")),
            (order_bins, KeyPath::table("simulation").key("max_order")),
            (
                series,
                if raw.laser.is_some() && n_channels > n_lines {
                    KeyPath::table("laser").key("line_shape_nodes")
                } else {
                    KeyPath::array("channel", raw.channel.len().saturating_sub(1))
                },
            ),
        ];
        check_product(
            "the returns",
            &[
                ("gates", gates_n),
                ("fields of view", fovs),
                ("order bins", order_bins),
                ("channels, line sums and line pairs", series),
            ],
            MAX_RETURN_BINS,
        )
        .map_err(|m| {
            let at = &blame
                .iter()
                .max_by_key(|(n, _)| *n)
                .expect("four factors")
                .1;
            self.err(at, m)
        })?;
        if let Some(a) = atmosphere {
            // Molecular layers, split again at every particle-layer boundary.
            let layers = molecular_layer_count(a) + 2 * n_particle_layers as u64 + 2;
            check_product(
                "the optical atmosphere",
                &[("layers", layers), ("channels", n_channels)],
                MAX_OPTICAL_CELLS,
            )
            .map_err(|m| self.err(&KeyPath::table("atmosphere").key("layer_thickness_m"), m))?;
        }
        Ok(())
    }

    /// The cache table of a `[gas_absorption]` section, if one is asked for.
    fn gas_table(
        &self,
        sec: &KeyPath,
        g: &file::GasAbsorptionFile,
        atm: &Atmosphere,
        lo: f64,
        hi: f64,
    ) -> Result<Option<GasTable>, InputError> {
        Ok(match &g.table {
            Some(f) => {
                let start = match g.table_start_cm1 {
                    Some(v) => self.range(&sec.key("table_start_cm1"), v, WAVENUMBER_CM1)?,
                    None => lo - 1.0,
                };
                let end = match g.table_end_cm1 {
                    Some(v) => self.range(&sec.key("table_end_cm1"), v, WAVENUMBER_CM1)?,
                    None => hi + 1.0,
                };
                let step = self.range(
                    &sec.key("table_step_cm1"),
                    g.table_step_cm1.unwrap_or(5e-4),
                    TABLE_STEP_CM1,
                )?;
                // The table interpolates with 6 points: 3 grid steps of room beyond each channel.
                if !(start <= lo - 3.0 * step && end >= hi + 3.0 * step) {
                    return Err(self.err(
                        &sec.key("table_start_cm1"),
                        format!("the table grid {start}–{end} cm⁻¹ must contain every channel ({lo}–{hi} cm⁻¹) with 3 steps of room to interpolate"),
                    ));
                }
                // The table holds every grid point of every molecular layer.
                let points = ((end - start) / step).ceil() as u64 + 1;
                let layers = molecular_layer_count(atm);
                crate::limits::check_product(
                    "the gas optical-depth table",
                    &[("grid points", points), ("molecular layers", layers)],
                    crate::limits::MAX_GAS_TABLE_VALUES,
                )
                .map_err(|m| self.err(&sec.key("table_step_cm1"), m))?;
                Some(GasTable {
                    path: self.path.parent().unwrap_or(Path::new(".")).join(f),
                    start_cm1: start,
                    end_cm1: end,
                    step_cm1: step,
                })
            }
            None => {
                for k in ["table_start_cm1", "table_end_cm1", "table_step_cm1"] {
                    let given = match k {
                        "table_start_cm1" => g.table_start_cm1.is_some(),
                        "table_end_cm1" => g.table_end_cm1.is_some(),
                        _ => g.table_step_cm1.is_some(),
                    };
                    if given {
                        return Err(self.err(&sec.key(k), "goes with `table`"));
                    }
                }
                None
            }
        })
    }

    fn gas(
        &self,
        g: &file::GasAbsorptionFile,
        channels: &[Channel],
        atmosphere: Option<&Atmosphere>,
    ) -> Result<GasAbsorption, InputError> {
        let sec = KeyPath::table("gas_absorption");
        let atm = atmosphere.ok_or_else(|| {
            self.err(
                &sec,
                "needs an [atmosphere] with gas profiles (`standard` or `profile_file`)",
            )
        })?;
        let mut options = LblOptions::default();
        if let Some(w) = g.wing_cm1 {
            options.wing_cm1 = self.range(&sec.key("wing_cm1"), w, WING_CM1)?;
        }
        if let Some(shape) = &g.line_shape {
            options.line_shape = shape
                .parse()
                .map_err(|m: String| self.err(&sec.key("line_shape"), m))?;
        }
        options.line_mixing = g.line_mixing.unwrap_or(false);
        let lo = channels
            .iter()
            .map(|c| c.wavenumber_cm1)
            .fold(f64::INFINITY, f64::min);
        let hi = channels
            .iter()
            .map(|c| c.wavenumber_cm1)
            .fold(f64::NEG_INFINITY, f64::max);
        let molecules = match &g.molecules {
            Some(names) => {
                let at = sec.key("molecules");
                let mut ids = Vec::new();
                for n in names {
                    ids.push(isotopologues::molecule_id(n).ok_or_else(|| {
                        self.err(
                            &at,
                            format!("`{n}` is not a HITRAN molecule lidarsim knows"),
                        )
                    })?);
                    if atm.profile.gas(n).is_none() {
                        return Err(self.err(&at, format!("the atmosphere has no `{n}` profile")));
                    }
                }
                Some(ids)
            }
            None => None,
        };
        let table = self.gas_table(&sec, g, atm, lo, hi)?;
        // Every line that reaches a channel, or any point of a table's grid (a later run may
        // take channels anywhere inside it).
        let (w_lo, w_hi) = match &table {
            Some(t) => (lo.min(t.start_cm1), hi.max(t.end_cm1)),
            None => (lo, hi),
        };
        let filter = LineFilter {
            molecules,
            isotopologues: None,
            min_cm1: Some(w_lo - options.wing_cm1),
            max_cm1: Some(w_hi + options.wing_cm1),
        };
        let lines = match &g.lines {
            Some(f) => {
                let path = self.path.parent().unwrap_or(Path::new(".")).join(f);
                LineList::read(&path, &filter)
                    .map_err(|e| self.err(&sec.key("lines"), format!("line file: {e}")))?
            }
            // The built-in approximate CO2 band (docs/spectroscopy.md), cut like a file.
            None => LineList::co2_30012_band_model().filtered(&filter),
        };
        // Absorption asked for but no line to give it is a mistake (a file of another
        // molecule, or of another band), not a transparent atmosphere.
        let window = format!(
            "{:.4}–{:.4} cm⁻¹ (the channels ± the {} cm⁻¹ wing)",
            w_lo - options.wing_cm1,
            w_hi + options.wing_cm1,
            options.wing_cm1
        );
        let source = match &g.lines {
            Some(f) => format!("the line file `{f}`"),
            None => "the built-in CO2 band model".to_string(),
        };
        match &g.molecules {
            Some(names) => {
                let present = lines.molecules();
                for n in names {
                    let id = isotopologues::molecule_id(n).unwrap_or(0);
                    if !present.contains(&id) {
                        return Err(self.err(
                            &sec.key("molecules"),
                            format!("{source} has no {n} line in {window}"),
                        ));
                    }
                }
            }
            None if lines.is_empty() => {
                return Err(self.err(
                    &sec.key(if g.lines.is_some() {
                        "lines"
                    } else {
                        "molecules"
                    }),
                    format!("{source} has no line in {window}"),
                ));
            }
            None => {}
        }
        options.check_lines(&lines).map_err(|e| {
            let key = if g.line_shape.is_some() {
                "line_shape"
            } else {
                "line_mixing"
            };
            self.err(&sec.key(key), e.to_string())
        })?;
        for id in lines.molecules() {
            let name = isotopologues::molecule_name(id).unwrap_or("?");
            if atm.profile.gas(name).is_none() {
                return Err(self.err(
                    &sec.key("lines"),
                    format!("the lines include {name}, which the atmosphere profile does not carry (restrict `molecules`)"),
                ));
            }
        }
        Ok(GasAbsorption {
            lines: Arc::new(lines),
            options,
            table,
        })
    }

    /// The lidar, and the pulse energy if `[lidar]` gives one (it may come from `[laser]`).
    fn lidar(&self, raw: &SceneFile) -> Result<(Lidar, Option<f64>), InputError> {
        let l = &raw.lidar;
        let sec = KeyPath::table("lidar");
        let (_, altitude_m) = self.one_of(
            &sec,
            ("altitude_m", l.altitude_m, 1.0, ALTITUDE_M),
            ("altitude_km", l.altitude_km, 1e3, ALTITUDE_KM),
        )?;
        let zenith_angle_deg =
            self.range(&sec.key("zenith_angle_deg"), l.zenith_angle_deg, ZENITH_DEG)?;
        let azimuth_deg = match l.azimuth_deg {
            Some(a) => self.range(&sec.key("azimuth_deg"), a, AZIMUTH_DEG)?,
            None => 0.0,
        };
        let pulse_energy_j = match l.pulse_energy_j {
            Some(e) => Some(self.range(&sec.key("pulse_energy_j"), e, PULSE_ENERGY_J)?),
            None => None,
        };
        let div = self.range(
            &sec.key("beam_divergence_full_angle_mrad"),
            l.beam_divergence_full_angle_mrad,
            DIVERGENCE_MRAD,
        )?;
        let beam_profile = match l.beam_profile.as_deref() {
            None | Some("uniform") => BeamProfile::Uniform,
            Some("gaussian") => BeamProfile::Gaussian,
            Some(other) => {
                return Err(self.err(
                    &sec.key("beam_profile"),
                    format!("`{other}` is not a beam profile (uniform, gaussian)"),
                ));
            }
        };
        let polarisation = match l.polarisation.as_deref() {
            None | Some("none") => Polarisation::None,
            Some("linear") => Polarisation::Linear,
            Some("circular") => Polarisation::Circular,
            Some(other) => {
                return Err(self.err(
                    &sec.key("polarisation"),
                    format!("`{other}` is not a polarisation (none, linear, circular)"),
                ));
            }
        };
        let telescope_diameter_m = self.range(
            &sec.key("telescope_diameter_m"),
            l.telescope_diameter_m,
            TELESCOPE_DIAMETER_M,
        )?;
        let optical_efficiency = self.range(
            &sec.key("optical_efficiency"),
            l.optical_efficiency,
            EFFICIENCY,
        )?;
        let fov_at = sec.key("fov_full_angle_mrad");
        let fov_full_angle_mrad = match &l.fov_full_angle_mrad {
            PerChannel::One(x) => vec![*x],
            PerChannel::Many(xs) => xs.clone(),
        };
        if fov_full_angle_mrad.is_empty() {
            return Err(self.err(&fov_at, "needs at least one field of view"));
        }
        self.range_all(&fov_at, &fov_full_angle_mrad, FOV_MRAD)?;
        // Sorted, so that a list of any length is checked in n log n.
        let mut sorted = fov_full_angle_mrad.clone();
        sorted.sort_by(f64::total_cmp);
        if let Some(w) = sorted.windows(2).find(|w| w[0] == w[1]) {
            return Err(self.err(&fov_at, format!("{} mrad is given twice", w[0])));
        }
        Ok((
            Lidar {
                altitude_m,
                zenith_angle_deg,
                azimuth_deg,
                // Set from the laser once it is known.
                pulse_energy_j: f64::NAN,
                beam_divergence_full_angle_mrad: div,
                beam_profile,
                telescope_diameter_m,
                optical_efficiency,
                fov_full_angle_mrad,
                polarisation,
            },
            pulse_energy_j,
        ))
    }

    fn channels(&self, raw: &SceneFile) -> Result<Vec<Channel>, InputError> {
        if raw.channel.is_empty() {
            return Err(self.err(&KeyPath::root(), "needs at least one [[channel]]"));
        }
        let mut out: Vec<Channel> = Vec::new();
        let mut names = std::collections::HashSet::new();
        for (i, c) in raw.channel.iter().enumerate() {
            let sec = KeyPath::array("channel", i);
            let wavenumber_cm1 = match (c.wavelength_nm, c.wavenumber_cm1) {
                (Some(w), None) => 1e7 / self.range(&sec.key("wavelength_nm"), w, WAVELENGTH_NM)?,
                (None, Some(k)) => self.range(&sec.key("wavenumber_cm1"), k, WAVENUMBER_CM1)?,
                (Some(_), Some(_)) => {
                    return Err(self.err(
                        &sec.key("wavenumber_cm1"),
                        "give `wavelength_nm` or `wavenumber_cm1`, not both",
                    ));
                }
                (None, None) => {
                    return Err(self.err(&sec, "needs `wavelength_nm` or `wavenumber_cm1`"));
                }
            };
            if !names.insert(c.name.as_str()) {
                return Err(self.err(
                    &sec.key("name"),
                    format!("channel `{}` is given twice", c.name),
                ));
            }
            // Any other text is a name: CSV files quote it (`crate::output::csv_field`).
            if c.name.is_empty() {
                return Err(self.err(&sec.key("name"), "must not be empty"));
            }
            out.push(Channel {
                name: c.name.clone(),
                wavenumber_cm1,
            });
        }
        Ok(out)
    }

    fn gates(&self, raw: &SceneFile) -> Result<Gates, InputError> {
        let g = &raw.gates;
        let sec = KeyPath::table("gates");
        // r = 0 is excluded: the single-scatter return diverges as 1/r² at the lidar.
        let start_m = self.range(&sec.key("start_m"), g.start_m, RANGE_M)?;
        let width_m = self.range(&sec.key("width_m"), g.width_m, GATE_WIDTH_M)?;
        let end_m = self.range(&sec.key("end_m"), g.end_m, RANGE_M)?;
        if !(end_m > start_m) {
            return Err(self.err(&sec.key("end_m"), "must be greater than `start_m`"));
        }
        let n = (end_m - start_m) / width_m;
        let count = n.round();
        if (n - count).abs() > 1e-6 * n.max(1.0) {
            return Err(self.err(
                &sec.key("end_m"),
                format!(
                    "end_m − start_m = {} m is not a whole number of {width_m} m gates",
                    end_m - start_m
                ),
            ));
        }
        // The gates alone must fit in the returns; with channels, fields of view and orders
        // they are checked again once all are known.
        crate::limits::check_product(
            "the range gates",
            &[("gates", count as u64)],
            crate::limits::MAX_RETURN_BINS,
        )
        .map_err(|m| self.err(&sec.key("width_m"), m))?;
        Ok(Gates {
            start_m,
            width_m,
            count: count as usize,
        })
    }

    fn atmosphere(
        &self,
        a: &file::AtmosphereFile,
        channels: &[Channel],
    ) -> Result<Atmosphere, InputError> {
        let sec = KeyPath::table("atmosphere");
        let explicit = a.altitude_m.is_some() || a.air_number_density_per_m3.is_some();
        let sources = [a.standard.is_some(), a.profile_file.is_some(), explicit];
        if sources.iter().filter(|x| **x).count() != 1 {
            return Err(self.err(
                &sec,
                "needs exactly one of `standard` (an AFGL atmosphere), `profile_file` (a profile \
                 set, with `profile_id`), or `altitude_m` with `air_number_density_per_m3`",
            ));
        }
        let mut profile = if let Some(name) = &a.standard {
            name.parse::<StandardAtmosphere>()
                .map_err(|m| self.err(&sec.key("standard"), m))?
                .profile()
        } else if let Some(file) = &a.profile_file {
            self.set_profile(&sec, file, a.profile_id.as_deref())?
        } else {
            match (&a.altitude_m, &a.air_number_density_per_m3) {
                (Some(z), Some(n)) => self.density_profile(&sec, z, n)?,
                _ => {
                    return Err(self.err(
                        &sec,
                        "`altitude_m` and `air_number_density_per_m3` go together",
                    ));
                }
            }
        };
        if a.profile_id.is_some() && a.profile_file.is_none() {
            return Err(self.err(&sec.key("profile_id"), "goes with `profile_file`"));
        }
        if let Some(ppm) = a.co2_ppm {
            let at = sec.key("co2_ppm");
            self.range(&at, ppm, CO2_PPM)?;
            profile
                .rescale_gas("CO2", ppm * 1e-6)
                .map_err(|e| self.err(&at, e.to_string()))?;
        }
        let z_top = *profile.altitude_m.last().unwrap_or(&0.0);
        let top_m = match a.top_m {
            Some(t) => {
                let at = sec.key("top_m");
                let t = self.range(&at, t, ALTITUDE_M)?;
                if t > z_top || t <= profile.altitude_m[0] {
                    return Err(self.err(
                        &at,
                        format!(
                            "{t} m is outside the profile ({} to {z_top} m)",
                            profile.altitude_m[0]
                        ),
                    ));
                }
                t
            }
            None => z_top,
        };
        let layer_thickness_m = self.range(
            &sec.key("layer_thickness_m"),
            a.layer_thickness_m.unwrap_or(100.0),
            LAYER_THICKNESS_M,
        )?;
        let layers = ((top_m - profile.altitude_m[0]) / layer_thickness_m).ceil() as u64;
        crate::limits::check_product(
            "the molecular grid",
            &[("layers", layers)],
            crate::limits::MAX_PATH_LAYERS,
        )
        .map_err(|m| self.err(&sec.key("layer_thickness_m"), m))?;
        let rayleigh_on = a.rayleigh.unwrap_or(true);
        // Bucholtz's depolarisation and cross-section are needed only with Rayleigh scattering
        // on; a channel outside their range is an error then, and only then.
        let depolarisation_factor = match &a.depolarization_factor {
            Some(v) => {
                let at = sec.key("depolarization_factor");
                let d = self.per_channel(&at, v, channels.len())?;
                self.range_all(&at, &d, DEPOLARISATION)?;
                d
            }
            None if rayleigh_on => channels
                .iter()
                .map(|c| rayleigh::depolarisation_factor(c.wavelength_nm()))
                .collect::<Result<_, _>>()
                .map_err(|e| self.err(&sec.key("rayleigh"), e.to_string()))?,
            None => vec![0.0; channels.len()],
        };
        if rayleigh_on {
            for (i, c) in channels.iter().enumerate() {
                rayleigh::cross_section_m2(c.wavelength_nm())
                    .map_err(|e| self.err(&KeyPath::array("channel", i), e.to_string()))?;
            }
        }
        Ok(Atmosphere {
            profile,
            layer_thickness_m,
            top_m,
            rayleigh: rayleigh_on,
            depolarisation_factor,
            co2_ppm: a.co2_ppm,
        })
    }

    /// One profile of a profile-set file (lidarsim's set format, `docs/atmosphere.md`), the file
    /// relative to the scene.
    fn set_profile(
        &self,
        sec: &KeyPath,
        file: &str,
        id: Option<&str>,
    ) -> Result<Profile, InputError> {
        let at = sec.key("profile_file");
        let path = self.path.parent().unwrap_or(Path::new(".")).join(file);
        let set = crate::atmosphere::read_profile_set(&path)
            .map_err(|e| self.err(&at, format!("profile set: {e}")))?;
        let member = match id {
            Some(id) => set.member(id).ok_or_else(|| {
                let ids: Vec<&str> = set
                    .members
                    .iter()
                    .take(10)
                    .map(|m| m.meta.id.as_str())
                    .collect();
                self.err(
                    &sec.key("profile_id"),
                    format!(
                        "no profile `{id}` in {} (ids: {}{})",
                        path.display(),
                        ids.join(", "),
                        if set.len() > 10 { ", …" } else { "" }
                    ),
                )
            })?,
            None if set.len() == 1 => &set.members[0],
            None => {
                return Err(self.err(
                    &at,
                    format!(
                        "{} holds {} profiles: say which with `profile_id`",
                        path.display(),
                        set.len()
                    ),
                ));
            }
        };
        Ok(member.profile.clone())
    }

    fn density_profile(&self, sec: &KeyPath, z: &[f64], n: &[f64]) -> Result<Profile, InputError> {
        let at_z = sec.key("altitude_m");
        let at_n = sec.key("air_number_density_per_m3");
        if z.len() != n.len() || z.len() < 2 {
            return Err(self.err(&at_n, "needs as many values as `altitude_m`, at least two"));
        }
        self.range_all(&at_z, z, ALTITUDE_M)?;
        self.range_all(&at_n, n, AIR_NUMBER_DENSITY_PER_M3)?;
        if z.windows(2).any(|w| w[1] <= w[0]) {
            return Err(self.err(&at_z, "must strictly increase"));
        }
        // Only the number density matters for Rayleigh scattering: carry it as p = n k T at a
        // nominal 273.15 K.
        let t = 273.15;
        Ok(Profile {
            name: "scene air-density profile".into(),
            altitude_m: z.to_vec(),
            pressure_pa: n
                .iter()
                .map(|v| v * crate::constants::BOLTZMANN_J_PER_K * t)
                .collect(),
            temperature_k: vec![t; z.len()],
            gases: Vec::new(),
        })
    }

    fn layer(
        &self,
        i: usize,
        l: &file::LayerFile,
        channels: &[Channel],
        cache_dir: Option<&Path>,
        polarisation: Polarisation,
    ) -> Result<Layer, InputError> {
        let nch = channels.len();
        let sec = KeyPath::array("layer", i);
        let name = l.name.clone().unwrap_or_else(|| format!("layer {}", i + 1));
        self.range(&sec.key("base_m"), l.base_m, ALTITUDE_M)?;
        self.range(&sec.key("top_m"), l.top_m, ALTITUDE_M)?;
        if !(l.top_m > l.base_m) {
            return Err(self.err(&sec.key("top_m"), "must be above `base_m`"));
        }
        if let Some(p) = &l.particles {
            return self.mie_layer(&sec, name, l, p, channels, cache_dir);
        }
        if l.number_density_per_cm3.is_some() {
            return Err(self.err(&sec.key("number_density_per_cm3"), "goes with `particles`"));
        }
        let ext = match (&l.extinction_per_m, &l.extinction_per_km) {
            (Some(v), None) => Some((sec.key("extinction_per_m"), v, 1.0, COEFFICIENT_PER_M)),
            (None, Some(v)) => Some((sec.key("extinction_per_km"), v, 1e-3, COEFFICIENT_PER_KM)),
            (Some(_), Some(_)) => {
                return Err(self.err(
                    &sec.key("extinction_per_km"),
                    "give `extinction_per_m` or `extinction_per_km`, not both",
                ));
            }
            (None, None) => None,
        };
        let has_particles = ext.is_some();
        let (extinction_per_m, single_scattering_albedo, phase, matrix) = match ext {
            Some((at, v, scale, bounds)) => {
                let mut e = self.per_channel(&at, v, nch)?;
                for x in e.iter_mut() {
                    *x = self.range(&at, *x, bounds)? * scale;
                }
                let ssa_at = sec.key("single_scattering_albedo");
                let ssa_raw = l.single_scattering_albedo.as_ref().ok_or_else(|| {
                    self.err(
                        &sec,
                        "a layer with extinction needs `single_scattering_albedo`",
                    )
                })?;
                let ssa = self.per_channel(&ssa_at, ssa_raw, nch)?;
                self.range_all(&ssa_at, &ssa, FRACTION)?;
                let phase_at = sec.key("phase");
                let specs = l
                    .phase
                    .as_ref()
                    .ok_or_else(|| self.err(&sec, "a layer with extinction needs `phase`"))?;
                let specs: Vec<&PhaseSpecFile> = match specs {
                    file::OneOrMany::One(s) => vec![s; nch],
                    file::OneOrMany::Many(v) if v.len() == nch => v.iter().collect(),
                    file::OneOrMany::Many(v) => {
                        return Err(self.err(
                            &phase_at,
                            format!(
                                "has {} entries; give one or one per channel ({nch})",
                                v.len()
                            ),
                        ));
                    }
                };
                let mut phase: Vec<Arc<PhaseFunction>> = Vec::new();
                let mut matrix: Vec<Arc<ScatteringMatrix>> = Vec::new();
                for (k, s) in specs.iter().enumerate() {
                    // Identical specs share one phase function (tables are large).
                    if let Some(j) = (0..k).find(|&j| specs[j] == *s) {
                        phase.push(phase[j].clone());
                        matrix.push(matrix[j].clone());
                    } else {
                        let (p, m) = self.phase(&phase_at, s, &channels[k])?;
                        if let (Polarisation::Circular, Some(ScatteringMatrix::Tabulated(t))) =
                            (polarisation, &m)
                            && !t.circular
                        {
                            let file = match s {
                                PhaseSpecFile::MatrixTable { file } => file.as_str(),
                                _ => "",
                            };
                            return Err(self.err(
                                &phase_at,
                                format!(
                                    "`{file}` is a linear-only scattering-matrix table (no F44, F34): a circularly polarised lidar needs all six elements"
                                ),
                            ));
                        }
                        let p = Arc::new(p);
                        let m = m.unwrap_or_else(|| ScatteringMatrix::NonDepolarising(p.clone()));
                        phase.push(p);
                        matrix.push(Arc::new(m));
                    }
                }
                (e, ssa, phase, matrix)
            }
            None => {
                if l.single_scattering_albedo.is_some() || l.phase.is_some() {
                    return Err(self.err(
                        &sec,
                        "`single_scattering_albedo` and `phase` need `extinction_per_m` or `extinction_per_km`",
                    ));
                }
                // Nothing scatters: isotropic placeholders.
                let p = Arc::new(PhaseFunction::Isotropic);
                let m = Arc::new(ScatteringMatrix::NonDepolarising(p.clone()));
                (vec![0.0; nch], vec![1.0; nch], vec![p; nch], vec![m; nch])
            }
        };
        let absorption_per_m = self.absorption(&sec, l, nch)?;
        if !has_particles && l.absorption_per_m.is_none() {
            return Err(self.err(
                &sec,
                "a layer needs particles (`extinction_per_m`/`_per_km`) or `absorption_per_m`",
            ));
        }
        Ok(Layer {
            name,
            base_m: l.base_m,
            top_m: l.top_m,
            extinction_per_m,
            single_scattering_albedo,
            phase,
            matrix,
            absorption_per_m,
        })
    }

    /// Extra (non-particle) absorption per channel of a layer, zero if not given.
    fn absorption(
        &self,
        sec: &KeyPath,
        l: &file::LayerFile,
        nch: usize,
    ) -> Result<Vec<f64>, InputError> {
        let Some(v) = &l.absorption_per_m else {
            return Ok(vec![0.0; nch]);
        };
        let at = sec.key("absorption_per_m");
        let a = self.per_channel(&at, v, nch)?;
        self.range_all(&at, &a, COEFFICIENT_PER_M)?;
        Ok(a)
    }

    /// A layer of particles given by a size distribution and refractive index: extinction,
    /// single-scattering albedo and phase function per channel by Mie theory (cached).
    fn mie_layer(
        &self,
        sec: &KeyPath,
        name: String,
        l: &file::LayerFile,
        p: &file::ParticlesFile,
        channels: &[Channel],
        cache_dir: Option<&Path>,
    ) -> Result<Layer, InputError> {
        use crate::particles::cache::layer_optics;
        use crate::particles::distribution::{BulkOptions, Component, SizeDistribution};
        let nch = channels.len();
        let at = sec.key("particles");
        if l.single_scattering_albedo.is_some() || l.phase.is_some() {
            return Err(self.err(
                &at,
                "a layer of `particles` gets its single-scattering albedo and phase function from Mie theory: remove `single_scattering_albedo` and `phase`",
            ));
        }
        let need = |v: Option<f64>, key: &str, bounds: Bounds| {
            let v =
                v.ok_or_else(|| self.err(&at, format!("`{}` needs `{key}`", p.distribution)))?;
            check_finite_range(v, bounds).map_err(|m| self.err(&at, format!("`{key}`: {m}")))
        };
        // The amount's own range first: Mie theory below is the slow part.
        if let Some(n) = l.number_density_per_cm3 {
            self.range(
                &sec.key("number_density_per_cm3"),
                n,
                PARTICLE_DENSITY_PER_CM3,
            )?;
        }
        for (key, v, b) in [
            ("extinction_per_m", &l.extinction_per_m, COEFFICIENT_PER_M),
            (
                "extinction_per_km",
                &l.extinction_per_km,
                COEFFICIENT_PER_KM,
            ),
        ] {
            if let Some(PerChannel::One(e)) = v {
                self.range(&sec.key(key), *e, Bounds::positive(b.hi))?;
            }
        }
        for (key, v) in [("r_min_um", p.r_min_um), ("r_max_um", p.r_max_um)] {
            if let Some(r) = v {
                check_finite_range(r, Bounds::closed(0.0, RADIUS_UM.hi))
                    .map_err(|m| self.err(&at, format!("`{key}`: {m}")))?;
            }
        }
        let mie_err = |e: String| self.err(&at, e);
        // Per channel, the components of the population (one, or an OPAC mixture).
        let components: Vec<Vec<Component>> = if p.distribution == "opac" {
            use crate::particles::opac::OpacType;
            if p.refractive_index.is_some() {
                return Err(self.err(&at, "OPAC aerosol types carry their own refractive indices: remove `refractive_index`"));
            }
            let name = p
                .aerosol_type
                .as_deref()
                .ok_or_else(|| self.err(&at, "`opac` needs `aerosol_type`"))?;
            let t = OpacType::from_name(name).ok_or_else(|| {
                let known: Vec<&str> = OpacType::ALL.iter().map(|t| t.name()).collect();
                self.err(
                    &at,
                    format!(
                        "unknown OPAC aerosol type `{name}` (known: {})",
                        known.join(", ")
                    ),
                )
            })?;
            channels
                .iter()
                .map(|c| {
                    t.components(c.wavelength_nm() * 1e-9)
                        .map_err(|e| mie_err(e.to_string()))
                })
                .collect::<Result<_, _>>()?
        } else {
            if p.aerosol_type.is_some() {
                return Err(self.err(&at, "`aerosol_type` goes with distribution = \"opac\""));
            }
            let mut dist = match p.distribution.as_str() {
                "lognormal" => SizeDistribution::lognormal(
                    1.0,
                    need(p.median_radius_um, "median_radius_um", RADIUS_UM)?,
                    need(p.sigma_g, "sigma_g", SIGMA_G)?,
                ),
                "modified_gamma" => SizeDistribution::modified_gamma(
                    1.0,
                    need(p.alpha, "alpha", GAMMA_SHAPE)?,
                    need(p.b, "b", GAMMA_SHAPE)?,
                    need(p.gamma, "gamma", GAMMA_SHAPE)?,
                ),
                other => {
                    return Err(self.err(
                        &at,
                        format!(
                            "distribution `{other}` is not one of: lognormal, modified_gamma, opac"
                        ),
                    ));
                }
            }
            .map_err(|e| mie_err(e.to_string()))?;
            match (p.r_min_um, p.r_max_um) {
                (Some(a), Some(b)) => {
                    dist = dist.truncated(a, b).map_err(|e| mie_err(e.to_string()))?
                }
                (None, None) => {}
                _ => return Err(self.err(&at, "`r_min_um` and `r_max_um` go together")),
            }
            let m_text: Vec<&String> = match &p.refractive_index {
                None => {
                    return Err(self.err(
                        &at,
                        format!("`{}` needs `refractive_index`", p.distribution),
                    ));
                }
                Some(file::OneOrMany::One(m)) => vec![m; nch],
                Some(file::OneOrMany::Many(v)) if v.len() == nch => v.iter().collect(),
                Some(file::OneOrMany::Many(v)) => {
                    return Err(self.err(
                        &at,
                        format!(
                            "refractive_index has {} entries; give one or one per channel ({nch})",
                            v.len()
                        ),
                    ));
                }
            };
            m_text
                .iter()
                .map(|m| {
                    let m = crate::particles::mie::parse_refractive_index(m)
                        .map_err(|e| self.err(&at, format!("refractive_index: {e}")))?;
                    Ok(vec![Component {
                        name: name.clone(),
                        distribution: dist.clone(),
                        refractive_index: m,
                    }])
                })
                .collect::<Result<_, InputError>>()?
        };
        // Mie theory is the slow part: its cost over every channel, bounded before any of it
        // is done (README, "Limits").
        let work = crate::particles::distribution::mie_work_of(
            channels
                .iter()
                .zip(&components)
                .map(|(c, comps)| (comps.as_slice(), c.wavelength_nm() * 1e-9)),
            &BulkOptions::default(),
        )
        .map_err(|e| mie_err(e.to_string()))?;
        work.check().map_err(mie_err)?;
        if let Some(note) = work.warning() {
            crate::limits::warn(&mie_err(note).to_string());
        }
        let mut optics = Vec::with_capacity(nch);
        for (c, comps) in channels.iter().zip(&components) {
            let (o, _) = layer_optics(
                comps,
                c.wavelength_nm() * 1e-9,
                &BulkOptions::default(),
                cache_dir,
            )
            .map_err(mie_err)?;
            optics.push(o);
        }
        // The amount: a number density, or an extinction at the first channel.
        let ext0 = match (&l.extinction_per_m, &l.extinction_per_km) {
            (Some(PerChannel::One(e)), None) => Some((sec.key("extinction_per_m"), *e)),
            (None, Some(PerChannel::One(e))) => Some((sec.key("extinction_per_km"), e * 1e-3)),
            (None, None) => None,
            _ => {
                return Err(self.err(
                    &at,
                    "give one extinction (at the first channel), `extinction_per_m` or `_per_km`; Mie theory gives the others",
                ));
            }
        };
        let number_density_per_m3 = match (l.number_density_per_cm3, ext0) {
            (Some(n), None) => n * 1e6,
            (None, Some((_, e))) => e / optics[0].extinction_cross_section_m2,
            _ => {
                return Err(self.err(
                    &at,
                    "give the amount as `number_density_per_cm3` or as an extinction at the first channel (one of them)",
                ));
            }
        };
        let mut phase: Vec<Arc<PhaseFunction>> = Vec::with_capacity(nch);
        let mut matrix: Vec<Arc<ScatteringMatrix>> = Vec::with_capacity(nch);
        for (k, o) in optics.iter().enumerate() {
            if let Some(j) = (0..k).find(|&j| Arc::ptr_eq(&optics[j], o)) {
                phase.push(phase[j].clone());
                matrix.push(matrix[j].clone());
            } else {
                // Both from the matrix table, whose F11 column is the Mie phase table number
                // for number: the phase function is the one that table gives.
                let (p, m) = o
                    .matrix
                    .phase_and_matrix()
                    .map_err(|e| mie_err(e.to_string()))?;
                phase.push(Arc::new(p));
                matrix.push(Arc::new(m));
            }
        }
        let absorption_per_m = self.absorption(sec, l, nch)?;
        Ok(Layer {
            name,
            base_m: l.base_m,
            top_m: l.top_m,
            extinction_per_m: optics
                .iter()
                .map(|o| number_density_per_m3 * o.extinction_cross_section_m2)
                .collect(),
            single_scattering_albedo: optics.iter().map(|o| o.single_scattering_albedo).collect(),
            phase,
            matrix,
            absorption_per_m,
        })
    }

    /// The phase function of a layer's `phase` spec at one channel, and its scattering matrix
    /// where the spec gives one (`None`: a scalar phase function, for which the caller makes a
    /// non-depolarising stand-in).
    fn phase(
        &self,
        at: &KeyPath,
        spec: &PhaseSpecFile,
        channel: &Channel,
    ) -> Result<(PhaseFunction, Option<ScatteringMatrix>), InputError> {
        let bad = |m: String| self.err(at, m);
        let scalar = |p: PhaseFunction| (p, None);
        Ok(match spec {
            PhaseSpecFile::Isotropic {} => scalar(PhaseFunction::Isotropic),
            PhaseSpecFile::Rayleigh {
                depolarization_factor,
            } => {
                let rho = match depolarization_factor {
                    Some(r) => *r,
                    None => rayleigh::depolarisation_factor(channel.wavelength_nm())
                        .map_err(|e| bad(e.to_string()))?,
                };
                // Molecule-like scatterers: the molecular matrix with the same ρ, whose F11 is
                // this phase function.
                (
                    PhaseFunction::Rayleigh(
                        RayleighPhase::from_depolarisation(rho).map_err(|e| bad(e.to_string()))?,
                    ),
                    Some(ScatteringMatrix::rayleigh(rho)),
                )
            }
            PhaseSpecFile::HenyeyGreenstein { g } => scalar(PhaseFunction::HenyeyGreenstein(
                HenyeyGreenstein::new(*g).map_err(|e| bad(e.to_string()))?,
            )),
            PhaseSpecFile::DoubleHenyeyGreenstein { f, g1, g2 } => {
                scalar(PhaseFunction::double_hg(*f, *g1, *g2).map_err(|e| bad(e.to_string()))?)
            }
            PhaseSpecFile::Table { file, builtin } => {
                let table = match (file, builtin) {
                    (Some(f), None) => {
                        let p = self.path.parent().unwrap_or(Path::new(".")).join(f);
                        PhaseTable::read(&p)
                            .map_err(|e| bad(format!("phase-function table: {e}")))?
                    }
                    (None, Some(name)) => builtin_table(name).map_err(bad)?,
                    _ => {
                        return Err(bad(
                            "a table phase function needs `file` (relative to the scene) or `builtin`, not both".into(),
                        ));
                    }
                };
                scalar(PhaseFunction::Tabulated(Box::new(
                    TabulatedPhase::from_table(&table).map_err(|e| bad(e.to_string()))?,
                )))
            }
            PhaseSpecFile::MatrixTable { file } => {
                let p = self.path.parent().unwrap_or(Path::new(".")).join(file);
                let table = MatrixTable::read(&p)
                    .map_err(|e| bad(format!("scattering-matrix table: {e}")))?;
                let (phase, matrix) = table
                    .phase_and_matrix()
                    .map_err(|e| bad(format!("scattering-matrix table {}: {e}", p.display())))?;
                (phase, Some(matrix))
            }
        })
    }

    fn simulation(&self, raw: &SceneFile) -> Result<Simulation, InputError> {
        let s = raw.simulation.clone().unwrap_or_default();
        let sec = KeyPath::table("simulation");
        let sim = Simulation {
            photons: s.photons.unwrap_or(1_000_000),
            seed: s.seed.unwrap_or(1),
            max_order: s.max_order.unwrap_or(5),
            threads: s.threads.unwrap_or(0),
            batches: s.batches.unwrap_or(100),
            cache_dir: self.cache_dir(raw),
            multiple_scattering: match s.multiple_scattering.as_deref() {
                None | Some("auto") => MultipleScattering::Auto,
                Some("always") => MultipleScattering::Always,
                Some("never") => MultipleScattering::Never,
                Some(other) => {
                    return Err(self.err(
                        &sec.key("multiple_scattering"),
                        format!("`{other}` is not a choice (auto, always, never)"),
                    ));
                }
            },
            multiple_scattering_tolerance: match s.multiple_scattering_tolerance {
                None => MULTIPLE_SCATTERING_TOLERANCE,
                Some(v) => {
                    self.range(&sec.key("multiple_scattering_tolerance"), v, MS_TOLERANCE)?
                }
            },
        };
        check_count(sim.max_order.into(), 1, 1000)
            .map_err(|m| self.err(&sec.key("max_order"), m))?;
        check_count(sim.batches as u64, 2, crate::limits::MAX_BATCHES).map_err(|m| {
            self.err(
                &sec.key("batches"),
                format!("{m} (at least 2 for error bars)"),
            )
        })?;
        check_count(sim.photons, 0, crate::limits::MAX_PHOTONS)
            .map_err(|m| self.err(&sec.key("photons"), m))?;
        check_count(sim.threads as u64, 0, crate::limits::MAX_THREADS)
            .map_err(|m| self.err(&sec.key("threads"), format!("{m} (0: all cores)")))?;
        if sim.multiple_scattering == MultipleScattering::Always && sim.photons == 0 {
            return Err(self.err(
                &sec.key("multiple_scattering"),
                "\"always\" needs photons > 0 (`photons = 0` runs the analytic lidar equation only)",
            ));
        }
        // 0 photons: the analytic lidar equation only.
        if sim.photons != 0 && sim.photons < sim.batches as u64 {
            return Err(self.err(
                &sec.key("photons"),
                "must be 0 (analytic only) or at least the number of batches",
            ));
        }
        Ok(sim)
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

    /// The scene with another atmospheric profile (an ensemble member, say), checked as the
    /// scene file's own is: the scene's `co2_ppm` rescales its CO2 column, and it must cover
    /// the scene's surface and top of the atmosphere. Errors name the scene key that the
    /// profile does not fit.
    pub fn with_profile(&self, mut profile: Profile) -> Result<Scene, InputError> {
        let Some(a) = &self.atmosphere else {
            return Err(self.input_error(
                "atmosphere",
                "",
                "the scene has no atmosphere to swap a profile into",
            ));
        };
        profile
            .validate()
            .map_err(|e| self.input_error("atmosphere", "", e.to_string()))?;
        if let Some(ppm) = a.co2_ppm {
            profile
                .rescale_gas("CO2", ppm * 1e-6)
                .map_err(|e| self.input_error("atmosphere", "co2_ppm", e.to_string()))?;
        }
        let (bottom, top) = (profile.altitude_m[0], profile.altitude_m[profile.len() - 1]);
        if top < a.top_m {
            return Err(self.input_error(
                "atmosphere",
                "top_m",
                format!(
                    "profile `{}` ends at {top:.0} m, below the scene's top of the atmosphere ({:.0} m)",
                    profile.name, a.top_m
                ),
            ));
        }
        if let Some(s) = &self.surface
            && s.altitude_m < bottom
        {
            return Err(self.input_error(
                "surface",
                "altitude_m",
                format!(
                    "profile `{}` starts at {bottom:.0} m, above the scene's surface ({:.0} m)",
                    profile.name, s.altitude_m
                ),
            ));
        }
        if let Some(g) = &self.gas {
            for id in g.lines.molecules() {
                let name = isotopologues::molecule_name(id).unwrap_or("?");
                if profile.gas(name).is_none() {
                    return Err(self.input_error(
                        "gas_absorption",
                        "",
                        format!(
                            "profile `{}` has no {name}, which the lines absorb",
                            profile.name
                        ),
                    ));
                }
            }
        }
        let mut scene = self.clone();
        if let Some(a) = &mut scene.atmosphere {
            a.profile = profile;
        }
        Ok(scene)
    }

    /// The scene with another laser on the same lines (another frequency offset, jitter, line
    /// width or purity): its channels are sampled anew and per-channel values follow the lines.
    /// The laser must have one entry per line in its per-line vectors.
    pub fn with_laser(&self, laser: Laser) -> Result<Scene, InputError> {
        let n = self.lines.len();
        if laser.pulse_energy_j.len() != n
            || laser.frequency_offset_mhz.len() != n
            || laser.impurity_wavenumber_cm1.len() != n
        {
            return Err(self.input_error(
                "laser",
                "",
                format!("a laser for {n} lines needs {n} values per line"),
            ));
        }
        let mut scene = self.clone();
        scene.collapse_per_channel_values();
        let (sampling, channels) = sample_lines(&laser, &scene.lines, scene.receiver.as_ref());
        scene.sampling = sampling;
        scene.channels = channels;
        if let Some(c) = scene.channels.iter().find(|c| !(c.wavenumber_cm1 > 0.0)) {
            return Err(self.input_error(
                "laser",
                "frequency_offset_mhz",
                format!("channel `{}` falls at {} cm⁻¹", c.name, c.wavenumber_cm1),
            ));
        }
        scene.lidar.pulse_energy_j = laser.pulse_energy_j[0];
        scene.laser = laser;
        scene.expand_per_channel_values();
        Ok(scene)
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
        InputError {
            path: self.path.clone(),
            line: Some(at.line(&self.text)),
            field: Some(at.dotted()),
            message: message.into(),
        }
    }

    /// The scene text as it was parsed (the embedded default scene's for it).
    pub fn text(&self) -> &str {
        &self.text
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
fn molecular_layer_count(a: &Atmosphere) -> u64 {
    ((a.top_m - a.profile.altitude_m[0]) / a.layer_thickness_m)
        .ceil()
        .max(1.0) as u64
}

/// The channels that sample `laser`'s `lines` through the receiver's filter (none without a
/// receiver), as the transport's monochromatic channels.
fn sample_lines(
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

#[cfg(test)]
mod tests;
