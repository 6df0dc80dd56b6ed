//! The scene description: what a scene file says, as plain public data, nothing computed.
//!
//! [`SceneDescription`] is the TOML scene file read by serde (and written back by it): one
//! struct per section, one field per key, units in the names, paths as written (relative ones
//! are anchored at the directory [`SceneDescription::resolve`] is given). A description built in
//! Rust code goes through exactly the checks of a file ([`SceneDescription::validate`]); its
//! errors name the field path (`layer[2].particles`) where a file's name the line and key.
//! The meaning and range of every key is in README.md ("Scene keys"); the files in `scenes/`
//! are worked examples.

use serde::de::{self, Deserializer, SeqAccess, Visitor};
use serde::ser::Serializer;
use serde::{Deserialize, Serialize};

/// A whole scene as its file says it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SceneDescription {
    /// Free text.
    pub description: Option<String>,
    /// `[lidar]`: platform, pointing, beam and telescope.
    pub lidar: LidarDescription,
    /// `[[channel]]`: the laser lines, in order.
    #[serde(default)]
    pub channel: Vec<ChannelDescription>,
    /// `[gates]`: the range gates.
    pub gates: GatesDescription,
    /// `[atmosphere]`: the molecular atmosphere, if any.
    pub atmosphere: Option<AtmosphereDescription>,
    /// `[[layer]]`: particle and absorber layers.
    #[serde(default)]
    pub layer: Vec<LayerDescription>,
    /// `[surface]`: a Lambertian surface, if any.
    pub surface: Option<SurfaceDescription>,
    /// `[gas_absorption]`: line-by-line gas absorption, if any.
    pub gas_absorption: Option<GasAbsorptionDescription>,
    /// `[simulation]`: Monte Carlo settings (defaults where absent).
    pub simulation: Option<SimulationDescription>,
    /// `[laser]`: the emitter's lines and spectrum (an ideal monochromatic laser if absent).
    pub laser: Option<LaserDescription>,
    /// `[receiver]`: filter and detector, if any.
    pub receiver: Option<ReceiverDescription>,
    /// `[background]`: background light on the receiver, if any.
    pub background: Option<BackgroundDescription>,
    /// `[retrieval]`: what to retrieve, if anything.
    pub retrieval: Option<RetrievalDescription>,
}

/// `[laser]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LaserDescription {
    /// Pulse energy per line \[J\].
    pub pulse_energy_j: PerChannel,
    /// Pulse repetition rate \[Hz\].
    pub repetition_rate_hz: f64,
    /// `monochromatic` (default), `gaussian`, `lorentzian` or `table`.
    pub line_shape: Option<String>,
    /// Full width at half maximum of a gaussian or lorentzian line \[MHz\].
    pub linewidth_fwhm_mhz: Option<f64>,
    /// The line-shape table of `line_shape = "table"` (relative to the scene), or
    /// `line_shape_table`.
    pub line_shape_file: Option<String>,
    /// The line-shape table of `line_shape = "table"` given by values, or `line_shape_file`.
    pub line_shape_table: Option<LineShapeTableDescription>,
    /// Quadrature nodes over the line shape.
    #[serde(default, deserialize_with = "crate::input::serde_count::option")]
    pub line_shape_nodes: Option<usize>,
    /// Offset of each line from its channel's wavenumber \[MHz\].
    pub frequency_offset_mhz: Option<PerChannel>,
    /// Shot-to-shot frequency jitter, RMS \[MHz\].
    pub frequency_jitter_rms_mhz: Option<f64>,
    /// Fraction of the energy in the line (the rest at `impurity_wavenumber_cm1`).
    pub spectral_purity: Option<f64>,
    /// Where the impure part of each line's energy goes \[cm⁻¹\].
    pub impurity_wavenumber_cm1: Option<PerChannel>,
    /// Shot-to-shot pulse-energy jitter, as a fraction.
    pub pulse_energy_jitter_fraction: Option<f64>,
    /// Error of the energy monitor, as a fraction.
    pub energy_monitor_error_fraction: Option<f64>,
}

/// `[receiver]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ReceiverDescription {
    /// Optical filter width \[nm\] (or `filter_bandwidth_ghz`).
    pub filter_bandwidth_nm: Option<f64>,
    /// Optical filter width \[GHz\] (or `filter_bandwidth_nm`).
    pub filter_bandwidth_ghz: Option<f64>,
    /// Filter transmission (default 1).
    pub filter_transmission: Option<f64>,
    /// Detector quantum efficiency.
    pub quantum_efficiency: f64,
    /// Detector gain (default 1).
    pub gain: Option<f64>,
    /// Excess noise factor (or `ionization_ratio`).
    pub excess_noise_factor: Option<f64>,
    /// APD ionisation ratio, from which the excess noise factor follows.
    pub ionization_ratio: Option<f64>,
    /// Dark current \[A\].
    pub dark_current_a: Option<f64>,
    /// Noise-equivalent power \[W/√Hz\].
    pub nep_w_per_sqrt_hz: Option<f64>,
    /// Amplifier current noise \[A/√Hz\].
    pub amplifier_noise_a_per_sqrt_hz: Option<f64>,
    /// Read-out noise \[electrons\].
    pub readout_noise_electrons: Option<f64>,
    /// Electrical bandwidth \[MHz\].
    pub bandwidth_mhz: Option<f64>,
}

/// `[background]`: a radiance, or sunlight reflected by the scene.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BackgroundDescription {
    /// Background radiance \[W/(m² sr µm)\].
    pub radiance_w_per_m2_sr_um: Option<f64>,
    /// Solar spectral irradiance \[W/(m² µm)\].
    pub solar_irradiance_w_per_m2_um: Option<f64>,
    /// Solar zenith angle \[deg\].
    pub solar_zenith_angle_deg: Option<f64>,
    /// Reflectance of the scene (default: the surface albedo).
    pub reflectance: Option<f64>,
}

/// `[retrieval]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RetrievalDescription {
    /// The gas retrieved (default CO2).
    pub gas: Option<String>,
    /// The on-line channel's name (default `on`).
    pub on: Option<String>,
    /// The off-line channel's name (default `off`).
    pub off: Option<String>,
    /// The IPDA hard target: `surface` or a layer's name.
    pub target: Option<String>,
    /// The echo window of the hard target \[m\].
    pub target_window_m: Option<f64>,
    /// Range cell of a range-resolved DIAL retrieval \[m\].
    pub dial_cell_m: Option<f64>,
    /// Start of the DIAL cells \[m\] (range).
    pub dial_start_m: Option<f64>,
    /// End of the DIAL cells \[m\] (range).
    pub dial_end_m: Option<f64>,
    /// Shot pairs averaged (or `averaging_length_km` with `platform_speed_m_per_s`).
    #[serde(default, deserialize_with = "crate::input::serde_count::option")]
    pub averaging_shots: Option<u64>,
    /// Along-track averaging length \[km\].
    pub averaging_length_km: Option<f64>,
    /// Platform speed \[m/s\].
    pub platform_speed_m_per_s: Option<f64>,
    /// Noisy realisations per product.
    #[serde(default, deserialize_with = "crate::input::serde_count::option")]
    pub realisations: Option<usize>,
    /// The retrieval's own line file (relative to the scene), if it differs from the truth's.
    pub lines: Option<String>,
    /// The retrieval's own line shape, if it differs from the truth's.
    pub line_shape: Option<String>,
    /// The retrieval's own line mixing, if it differs from the truth's.
    pub line_mixing: Option<bool>,
}

/// `[gas_absorption]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GasAbsorptionDescription {
    /// A HITRAN or CSV line file (relative to the scene); the built-in CO2 band if absent.
    pub lines: Option<String>,
    /// The molecules whose lines absorb (HITRAN names).
    pub molecules: Option<Vec<String>>,
    /// Line wing cutoff \[cm⁻¹\].
    pub wing_cm1: Option<f64>,
    /// A gas optical-depth table file to reuse or write (relative to the scene).
    pub table: Option<String>,
    /// Start of the table's grid \[cm⁻¹\].
    pub table_start_cm1: Option<f64>,
    /// End of the table's grid \[cm⁻¹\].
    pub table_end_cm1: Option<f64>,
    /// Step of the table's grid \[cm⁻¹\].
    pub table_step_cm1: Option<f64>,
    /// The line shape (`voigt`, …).
    pub line_shape: Option<String>,
    /// Line mixing on or off.
    pub line_mixing: Option<bool>,
}

/// `[lidar]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LidarDescription {
    /// Altitude \[m\] (or `altitude_km`).
    pub altitude_m: Option<f64>,
    /// Altitude \[km\] (or `altitude_m`).
    pub altitude_km: Option<f64>,
    /// Pointing from the upward vertical \[deg\].
    pub zenith_angle_deg: f64,
    /// Pointing azimuth \[deg\].
    pub azimuth_deg: Option<f64>,
    /// Pulse energy \[J\] (without a `[laser]`, which then holds it).
    pub pulse_energy_j: Option<f64>,
    /// Full divergence angle of the beam \[mrad\].
    pub beam_divergence_full_angle_mrad: f64,
    /// `uniform` (default) or `gaussian`.
    pub beam_profile: Option<String>,
    /// Telescope diameter \[m\].
    pub telescope_diameter_m: f64,
    /// Receiver optical efficiency.
    pub optical_efficiency: f64,
    /// Fields of view, full angles \[mrad\]: one or a list.
    pub fov_full_angle_mrad: PerChannel,
    /// `none` (default), `linear` or `circular`.
    pub polarisation: Option<String>,
}

/// `[[channel]]`: one laser line.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ChannelDescription {
    /// Name (`on`, `off`, …).
    pub name: String,
    /// Vacuum wavelength \[nm\] (or `wavenumber_cm1`).
    pub wavelength_nm: Option<f64>,
    /// Vacuum wavenumber \[cm⁻¹\] (or `wavelength_nm`).
    pub wavenumber_cm1: Option<f64>,
}

/// `[gates]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GatesDescription {
    /// Start of the first gate \[m\] (range).
    pub start_m: f64,
    /// End of the last gate \[m\] (range).
    pub end_m: f64,
    /// Gate width \[m\].
    pub width_m: f64,
}

/// `[atmosphere]`: one of a standard atmosphere, a profile-set file, or an air-density
/// profile given as values.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AtmosphereDescription {
    /// An AFGL standard atmosphere's name.
    pub standard: Option<String>,
    /// A profile-set file (relative to the scene).
    pub profile_file: Option<String>,
    /// The member of `profile_file`.
    pub profile_id: Option<String>,
    /// CO2 \[ppm\]: by default a well-mixed dry-air mole fraction at every level; see
    /// `co2_scaling`.
    pub co2_ppm: Option<f64>,
    /// How `co2_ppm` is applied: `well_mixed` (default; the dry-air mole fraction at every
    /// level) or `profile_shape` (the profile's CO2 rescaled by one factor to that dry-air
    /// column average).
    pub co2_scaling: Option<String>,
    /// A profile given by values, with its gases.
    pub profile: Option<ProfileDescription>,
    /// Altitudes of an air-density profile \[m\].
    pub altitude_m: Option<Vec<f64>>,
    /// Air number density at `altitude_m` \[1/m³\].
    pub air_number_density_per_m3: Option<Vec<f64>>,
    /// Top of the model atmosphere \[m\] (default: the profile's top).
    pub top_m: Option<f64>,
    /// Thickness of the optical layers \[m\] (default 100).
    pub layer_thickness_m: Option<f64>,
    /// Rayleigh scattering on (default) or off.
    pub rayleigh: Option<bool>,
    /// Molecular depolarisation factor per channel (Bucholtz 1995 if absent).
    pub depolarization_factor: Option<PerChannel>,
}

/// A profile given by values (`[atmosphere] profile = { … }`): the levels of
/// the atmosphere module's `Profile`, bottom up.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ProfileDescription {
    /// Name for messages (default `scene profile`).
    pub name: Option<String>,
    /// Altitude of each level \[m\], strictly increasing.
    pub altitude_m: Vec<f64>,
    /// Pressure at each level \[Pa\], strictly decreasing.
    pub pressure_pa: Vec<f64>,
    /// Temperature at each level \[K\].
    pub temperature_k: Vec<f64>,
    /// The gases, each a volume mixing ratio per level, in order.
    #[serde(default)]
    pub gases: Vec<GasDescription>,
}

/// One gas of a profile given by values.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GasDescription {
    /// Formula as HITRAN writes it (`CO2`, `H2O`, …).
    pub name: String,
    /// Volume mixing ratio at each level \[mol/mol\].
    pub vmr: Vec<f64>,
}

/// A laser line shape given by values (`[laser] line_shape_table = { … }`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LineShapeTableDescription {
    /// Where the values came from, for messages (default: the description).
    pub name: Option<String>,
    /// Frequency offset from the line centre \[MHz\], strictly increasing.
    pub offset_mhz: Vec<f64>,
    /// Relative intensity at each offset, ≥ 0, not normalised.
    pub relative_intensity: Vec<f64>,
}

/// `[[layer]]`: particles given by their optics or by a size distribution, and/or extra
/// absorption.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LayerDescription {
    /// Name for messages and retrieval targets.
    pub name: Option<String>,
    /// Base altitude \[m\].
    pub base_m: f64,
    /// Top altitude \[m\].
    pub top_m: f64,
    /// Particle extinction \[1/m\] (or `extinction_per_km`).
    pub extinction_per_m: Option<PerChannel>,
    /// Particle extinction \[1/km\] (or `extinction_per_m`).
    pub extinction_per_km: Option<PerChannel>,
    /// Liquid water content \[g/m³\], in place of an extinction: with `r_eff_um` in the
    /// geometric-optics limit, or the amount of a layer of Mie `particles`.
    pub lwc_g_per_m3: Option<f64>,
    /// Ice water content \[g/m³\], as `lwc_g_per_m3` for ice (ρ = 917 kg/m³).
    pub iwc_g_per_m3: Option<f64>,
    /// Effective radius ⟨r³⟩/⟨r²⟩ \[µm\] of `lwc_g_per_m3` / `iwc_g_per_m3` (of a lognormal
    /// `particles`, in place of `median_radius_um`).
    pub r_eff_um: Option<f64>,
    /// Particle single-scattering albedo.
    pub single_scattering_albedo: Option<PerChannel>,
    /// Particle phase function: one, or one per channel.
    pub phase: Option<OneOrMany<PhaseDescription>>,
    /// Extra (e.g. gas) absorption \[1/m\].
    pub absorption_per_m: Option<PerChannel>,
    /// Particle number density of a `particles` layer \[1/cm³\].
    pub number_density_per_cm3: Option<f64>,
    /// Particles by size distribution and refractive index (optics by Mie theory).
    pub particles: Option<ParticlesDescription>,
}

/// A layer's `particles`: a size distribution and refractive index, or an OPAC type.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ParticlesDescription {
    /// `lognormal`, `modified_gamma` or `opac`.
    pub distribution: String,
    /// Median radius of a lognormal \[µm\].
    pub median_radius_um: Option<f64>,
    /// Geometric standard deviation of a lognormal.
    pub sigma_g: Option<f64>,
    /// Modified gamma α.
    pub alpha: Option<f64>,
    /// Modified gamma b.
    pub b: Option<f64>,
    /// Modified gamma γ.
    pub gamma: Option<f64>,
    /// Smallest radius of a truncated distribution \[µm\].
    pub r_min_um: Option<f64>,
    /// Largest radius of a truncated distribution \[µm\].
    pub r_max_um: Option<f64>,
    /// The OPAC aerosol type of `distribution = "opac"`.
    pub aerosol_type: Option<String>,
    /// Complex refractive index (`"1.5+0.01i"`): one, or one per channel.
    pub refractive_index: Option<OneOrMany<String>>,
}

/// A layer's phase function (`phase = { kind = … }`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum PhaseDescription {
    /// Isotropic scattering.
    Isotropic {},
    /// Rayleigh scattering with a depolarisation factor (Bucholtz 1995's if absent).
    Rayleigh {
        /// Depolarisation factor ρ.
        depolarization_factor: Option<f64>,
    },
    /// Henyey-Greenstein.
    HenyeyGreenstein {
        /// Asymmetry parameter.
        g: f64,
    },
    /// Two Henyey-Greenstein lobes, `f` of the first.
    DoubleHenyeyGreenstein {
        /// Weight of the first lobe.
        f: f64,
        /// Asymmetry parameter of the first lobe.
        g1: f64,
        /// Asymmetry parameter of the second lobe.
        g2: f64,
    },
    /// A tabulated phase function: a file (relative to the scene) or a built-in table.
    Table {
        /// The table file.
        file: Option<String>,
        /// A built-in table's name.
        builtin: Option<String>,
    },
    /// A tabulated scattering matrix (relative to the scene).
    MatrixTable {
        /// The table file.
        file: String,
    },
}

/// `[surface]`: a Lambertian surface.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SurfaceDescription {
    /// Altitude \[m\].
    pub altitude_m: f64,
    /// Albedo per channel.
    pub albedo: PerChannel,
}

/// `[simulation]`: Monte Carlo settings; absent keys take their defaults.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SimulationDescription {
    /// Photon packets (0: the analytic lidar equation only).
    #[serde(default, deserialize_with = "crate::input::serde_count::option")]
    pub photons: Option<u64>,
    /// Random seed.
    #[serde(default, deserialize_with = "crate::input::serde_count::option")]
    pub seed: Option<u64>,
    /// Highest scattering order tallied separately.
    #[serde(default, deserialize_with = "crate::input::serde_count::option")]
    pub max_order: Option<u32>,
    /// Worker threads (0: all cores).
    #[serde(default, deserialize_with = "crate::input::serde_count::option")]
    pub threads: Option<usize>,
    /// Independent batches for the standard errors.
    #[serde(default, deserialize_with = "crate::input::serde_count::option")]
    pub batches: Option<usize>,
    /// Directory for cached Mie optics (relative to the scene).
    pub cache_dir: Option<String>,
    /// `auto` (default), `always` or `never`.
    pub multiple_scattering: Option<String>,
    /// The multiple-scattering share below which `auto` skips the Monte Carlo.
    pub multiple_scattering_tolerance: Option<f64>,
    /// Tally the returns' derivatives with respect to each layer's absorption, scattering
    /// and extinction (default false).
    pub jacobians: Option<bool>,
}

/// One number for every channel, or a list with one number per channel.
#[derive(Debug, Clone, PartialEq)]
pub enum PerChannel {
    /// The same value for every channel.
    One(f64),
    /// One value per channel.
    Many(Vec<f64>),
}

impl<'de> Deserialize<'de> for PerChannel {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct V;
        impl<'de> Visitor<'de> for V {
            type Value = PerChannel;
            fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
                f.write_str("a number or a list of numbers (one per channel)")
            }
            fn visit_f64<E: de::Error>(self, v: f64) -> Result<PerChannel, E> {
                Ok(PerChannel::One(v))
            }
            fn visit_i64<E: de::Error>(self, v: i64) -> Result<PerChannel, E> {
                Ok(PerChannel::One(v as f64))
            }
            fn visit_u64<E: de::Error>(self, v: u64) -> Result<PerChannel, E> {
                Ok(PerChannel::One(v as f64))
            }
            fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<PerChannel, A::Error> {
                let mut v = Vec::new();
                while let Some(x) = seq.next_element::<f64>()? {
                    v.push(x);
                }
                Ok(PerChannel::Many(v))
            }
        }
        d.deserialize_any(V)
    }
}

/// One item for every channel, or a list with one per channel.
#[derive(Debug, Clone, PartialEq)]
pub enum OneOrMany<T> {
    /// The same item for every channel.
    One(T),
    /// One item per channel.
    Many(Vec<T>),
}

impl<'de, T: Deserialize<'de>> Deserialize<'de> for OneOrMany<T> {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        // A table is one item, an array is one per channel; keep serde's own error for a bad
        // item so the message names the field at fault.
        let v = toml::Value::deserialize(d)?;
        match v {
            toml::Value::Array(items) => items
                .into_iter()
                .map(|i| T::deserialize(i).map_err(de::Error::custom))
                .collect::<Result<Vec<T>, _>>()
                .map(OneOrMany::Many),
            other => T::deserialize(other)
                .map(OneOrMany::One)
                .map_err(de::Error::custom),
        }
    }
}

impl Serialize for PerChannel {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        match self {
            PerChannel::One(x) => s.serialize_f64(*x),
            PerChannel::Many(v) => v.serialize(s),
        }
    }
}

impl<T: Serialize> Serialize for OneOrMany<T> {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        match self {
            OneOrMany::One(x) => x.serialize(s),
            OneOrMany::Many(v) => v.serialize(s),
        }
    }
}
