//! The scene file as serde reads it, and the mapping of problems to file lines.

use std::path::Path;

use serde::Deserialize;
use serde::de::{self, Deserializer, SeqAccess, Visitor};

use crate::input::InputError;

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct SceneFile {
    pub description: Option<String>,
    pub lidar: LidarFile,
    #[serde(default)]
    pub channel: Vec<ChannelFile>,
    pub gates: GatesFile,
    pub atmosphere: Option<AtmosphereFile>,
    #[serde(default)]
    pub layer: Vec<LayerFile>,
    pub surface: Option<SurfaceFile>,
    pub gas_absorption: Option<GasAbsorptionFile>,
    pub simulation: Option<SimulationFile>,
    pub laser: Option<LaserFile>,
    pub receiver: Option<ReceiverFile>,
    pub background: Option<BackgroundFile>,
    pub retrieval: Option<RetrievalFile>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct LaserFile {
    pub pulse_energy_j: PerChannel,
    pub repetition_rate_hz: f64,
    pub line_shape: Option<String>,
    pub linewidth_fwhm_mhz: Option<f64>,
    pub line_shape_file: Option<String>,
    pub line_shape_nodes: Option<usize>,
    pub frequency_offset_mhz: Option<PerChannel>,
    pub frequency_jitter_rms_mhz: Option<f64>,
    pub spectral_purity: Option<f64>,
    pub impurity_wavenumber_cm1: Option<PerChannel>,
    pub pulse_energy_jitter_fraction: Option<f64>,
    pub energy_monitor_error_fraction: Option<f64>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct ReceiverFile {
    pub filter_bandwidth_nm: Option<f64>,
    pub filter_bandwidth_ghz: Option<f64>,
    pub filter_transmission: Option<f64>,
    pub quantum_efficiency: f64,
    pub gain: Option<f64>,
    pub excess_noise_factor: Option<f64>,
    pub ionization_ratio: Option<f64>,
    pub dark_current_a: Option<f64>,
    pub nep_w_per_sqrt_hz: Option<f64>,
    pub amplifier_noise_a_per_sqrt_hz: Option<f64>,
    pub readout_noise_electrons: Option<f64>,
    pub bandwidth_mhz: Option<f64>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct BackgroundFile {
    pub radiance_w_per_m2_sr_um: Option<f64>,
    pub solar_irradiance_w_per_m2_um: Option<f64>,
    pub solar_zenith_angle_deg: Option<f64>,
    pub reflectance: Option<f64>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RetrievalFile {
    pub gas: Option<String>,
    pub on: Option<String>,
    pub off: Option<String>,
    pub target: Option<String>,
    pub target_window_m: Option<f64>,
    pub dial_cell_m: Option<f64>,
    pub dial_start_m: Option<f64>,
    pub dial_end_m: Option<f64>,
    pub averaging_shots: Option<u64>,
    pub averaging_length_km: Option<f64>,
    pub platform_speed_m_per_s: Option<f64>,
    pub realisations: Option<usize>,
    pub lines: Option<String>,
    pub line_shape: Option<String>,
    pub line_mixing: Option<bool>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct GasAbsorptionFile {
    pub lines: Option<String>,
    pub molecules: Option<Vec<String>>,
    pub wing_cm1: Option<f64>,
    pub table: Option<String>,
    pub table_start_cm1: Option<f64>,
    pub table_end_cm1: Option<f64>,
    pub table_step_cm1: Option<f64>,
    pub line_shape: Option<String>,
    pub line_mixing: Option<bool>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct LidarFile {
    pub altitude_m: Option<f64>,
    pub altitude_km: Option<f64>,
    pub zenith_angle_deg: f64,
    pub azimuth_deg: Option<f64>,
    pub pulse_energy_j: Option<f64>,
    pub beam_divergence_full_angle_mrad: f64,
    pub beam_profile: Option<String>,
    pub telescope_diameter_m: f64,
    pub optical_efficiency: f64,
    pub fov_full_angle_mrad: PerChannel,
    pub polarisation: Option<String>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct ChannelFile {
    pub name: String,
    pub wavelength_nm: Option<f64>,
    pub wavenumber_cm1: Option<f64>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct GatesFile {
    pub start_m: f64,
    pub end_m: f64,
    pub width_m: f64,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct AtmosphereFile {
    pub standard: Option<String>,
    pub profile_file: Option<String>,
    pub profile_id: Option<String>,
    pub co2_ppm: Option<f64>,
    pub altitude_m: Option<Vec<f64>>,
    pub air_number_density_per_m3: Option<Vec<f64>>,
    pub top_m: Option<f64>,
    pub layer_thickness_m: Option<f64>,
    pub rayleigh: Option<bool>,
    pub depolarization_factor: Option<PerChannel>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct LayerFile {
    pub name: Option<String>,
    pub base_m: f64,
    pub top_m: f64,
    pub extinction_per_m: Option<PerChannel>,
    pub extinction_per_km: Option<PerChannel>,
    pub single_scattering_albedo: Option<PerChannel>,
    pub phase: Option<OneOrMany<PhaseSpecFile>>,
    pub absorption_per_m: Option<PerChannel>,
    pub number_density_per_cm3: Option<f64>,
    pub particles: Option<ParticlesFile>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct ParticlesFile {
    pub distribution: String,
    pub median_radius_um: Option<f64>,
    pub sigma_g: Option<f64>,
    pub alpha: Option<f64>,
    pub b: Option<f64>,
    pub gamma: Option<f64>,
    pub r_min_um: Option<f64>,
    pub r_max_um: Option<f64>,
    pub aerosol_type: Option<String>,
    pub refractive_index: Option<OneOrMany<String>>,
}

#[derive(Debug, Deserialize, PartialEq)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub(super) enum PhaseSpecFile {
    Isotropic {},
    Rayleigh {
        depolarization_factor: Option<f64>,
    },
    HenyeyGreenstein {
        g: f64,
    },
    DoubleHenyeyGreenstein {
        f: f64,
        g1: f64,
        g2: f64,
    },
    Table {
        file: Option<String>,
        builtin: Option<String>,
    },
    MatrixTable {
        file: String,
    },
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct SurfaceFile {
    pub altitude_m: f64,
    pub albedo: PerChannel,
}

#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct SimulationFile {
    pub photons: Option<u64>,
    pub seed: Option<u64>,
    pub max_order: Option<u32>,
    pub threads: Option<usize>,
    pub batches: Option<usize>,
    pub cache_dir: Option<String>,
    pub multiple_scattering: Option<String>,
    pub multiple_scattering_tolerance: Option<f64>,
}

/// One number for every channel, or a list with one number per channel.
#[derive(Debug, Clone, PartialEq)]
pub(super) enum PerChannel {
    One(f64),
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
#[derive(Debug, PartialEq)]
pub(super) enum OneOrMany<T> {
    One(T),
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

/// Where a value sits in the file: a section (`[name]`, or the i-th `[[name]]`) and a key.
#[derive(Debug, Clone)]
pub(super) struct KeyPath {
    section: Option<(String, Option<usize>)>,
    key: Option<String>,
}

impl KeyPath {
    pub fn root() -> Self {
        KeyPath {
            section: None,
            key: None,
        }
    }
    pub fn table(name: &str) -> Self {
        KeyPath {
            section: Some((name.into(), None)),
            key: None,
        }
    }
    pub fn array(name: &str, index: usize) -> Self {
        KeyPath {
            section: Some((name.into(), Some(index))),
            key: None,
        }
    }
    pub fn key(&self, key: &str) -> Self {
        KeyPath {
            section: self.section.clone(),
            key: Some(key.into()),
        }
    }

    /// `lidar.pulse_energy_j`, `layer.top_m`, `channel` …
    pub fn dotted(&self) -> String {
        match (&self.section, &self.key) {
            (Some((s, _)), Some(k)) => format!("{s}.{k}"),
            (Some((s, _)), None) => s.clone(),
            (None, Some(k)) => k.clone(),
            (None, None) => "(scene)".into(),
        }
    }

    /// 1-based line of the key (or of its section header when the key is absent).
    pub fn line(&self, text: &str) -> usize {
        let mut in_section = self.section.is_none();
        let mut header_line = 1;
        let mut seen = 0usize;
        for (i, raw) in text.lines().enumerate() {
            let line = raw.trim();
            if line.starts_with('[') {
                let (name, is_array) = if let Some(n) = line.strip_prefix("[[") {
                    (n.split("]]").next().unwrap_or("").trim(), true)
                } else {
                    (
                        line.trim_start_matches('[')
                            .split(']')
                            .next()
                            .unwrap_or("")
                            .trim(),
                        false,
                    )
                };
                in_section = match &self.section {
                    Some((s, None)) => !is_array && name == s,
                    Some((s, Some(idx))) => {
                        let hit = is_array && name == s && seen == *idx;
                        if is_array && name == s {
                            seen += 1;
                        }
                        hit
                    }
                    None => false,
                };
                if in_section {
                    header_line = i + 1;
                }
                continue;
            }
            if in_section
                && let Some(k) = &self.key
                && let Some(rest) = line.strip_prefix(k.as_str())
                && rest.trim_start().starts_with('=')
            {
                return i + 1;
            }
        }
        header_line
    }
}

/// The first float in the scene text that is not finite (`nan`, `inf`, or a literal beyond
/// the f64 range such as `1e400`), as an error at its own line and key: a NaN must be named
/// where it stands, not where a later comparison with it first fails.
pub(super) fn non_finite_value(path: &Path, text: &str) -> Result<(), InputError> {
    use toml::de::{DeTable, DeValue};
    type Found = (String, std::ops::Range<usize>, String);
    fn walk(key: &str, v: &toml::Spanned<DeValue<'_>>, out: &mut Vec<Found>) {
        match v.get_ref() {
            DeValue::Float(f) => {
                let raw = f.as_str().to_string();
                let finite = raw
                    .replace('_', "")
                    .parse::<f64>()
                    .is_ok_and(f64::is_finite);
                if !finite {
                    out.push((key.to_string(), v.span(), raw));
                }
            }
            DeValue::Array(items) => items.iter().for_each(|i| walk(key, i, out)),
            DeValue::Table(t) => {
                for (k, v) in t.iter() {
                    let name = if key.is_empty() {
                        k.get_ref().to_string()
                    } else {
                        format!("{key}.{}", k.get_ref())
                    };
                    walk(&name, v, out);
                }
            }
            _ => {}
        }
    }
    // The text has already been parsed by serde; a failure here cannot add anything.
    let Ok(doc) = DeTable::parse(text) else {
        return Ok(());
    };
    let mut all = Vec::new();
    for (k, v) in doc.get_ref().iter() {
        walk(k.get_ref(), v, &mut all);
    }
    // The table is sorted by key; report the first in the file.
    let found = all.into_iter().min_by_key(|(_, span, _)| span.start);
    match found {
        None => Ok(()),
        Some((key, span, raw)) => Err(InputError {
            path: path.to_path_buf(),
            line: Some(text[..span.start.min(text.len())].matches('\n').count() + 1),
            field: Some(key),
            message: format!("`{raw}` is not a finite number"),
        }),
    }
}

/// Turn a TOML/serde error into an [`InputError`] with the line and the key.
pub(super) fn toml_error(path: &Path, text: &str, e: &toml::de::Error) -> InputError {
    // One line: serde adds the inner key of an inline table on a line of its own
    // ("unknown variant `x`, expected …\nin `kind`").
    let message = e
        .message()
        .lines()
        .map(str::trim)
        .filter(|l| !l.is_empty())
        .collect::<Vec<_>>()
        .join(" ");
    let line = e
        .span()
        .map(|s| text[..s.start.min(text.len())].matches('\n').count() + 1);
    // The key: quoted in messages about unknown or missing fields, otherwise the key of the
    // line the span starts on (an unknown variant quotes the value, not the key).
    let quoted = ["unknown field `", "missing field `"]
        .iter()
        .find_map(|p| message.split(p).nth(1).and_then(|r| r.split('`').next()))
        .map(str::to_string);
    let field = quoted.or_else(|| {
        line.and_then(|l| text.lines().nth(l - 1)).and_then(|l| {
            l.split_once('=')
                .map(|(k, _)| k.trim().to_string())
                .filter(|k| !k.is_empty())
        })
    });
    InputError {
        path: path.to_path_buf(),
        line,
        field,
        message,
    }
}
