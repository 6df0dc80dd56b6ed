//! The instrument and retrieval sections of a scene: `[laser]`, `[receiver]`, `[background]`,
//! `[retrieval]`, checked and resolved into the instrument's and the retrieval's plain types
//! (part of step 3, as they build on the instrument and retrieval modules).

use std::sync::Arc;

use super::description::{BackgroundDescription, RetrievalDescription, SceneDescription};
use super::ranges::*;
use super::resolve::Resolver;
use super::source::KeyPath;
use super::{Atmosphere, Channel, GasAbsorption, Gates, Layer, Lidar, Surface};
use crate::input::{Bounds, InputError};
use crate::instrument::detector::{self, Detector};
use crate::instrument::laser::{Filter, Laser};
use crate::instrument::line_shape::{LineShape, LineShapeTable, MHZ_PER_CM1};
use crate::instrument::signals::Receiver;
use crate::retrieval::{AssumedSpectroscopy, DialCells, HardTarget, RetrievalConfig, TargetKind};
use crate::spectroscopy::isotopologues;
use crate::spectroscopy::{LineFilter, LineList};

/// Default number of line-shape quadrature nodes (odd, so the line centre is a node).
const DEFAULT_LINE_SHAPE_NODES: usize = 5;
/// Default number of noisy realisations per retrieval product.
const DEFAULT_REALISATIONS: usize = 1000;
/// Bandwidth stored when no white-noise term needs one \[Hz\] (it then enters no formula).
const UNUSED_BANDWIDTH_HZ: f64 = 1e15;

/// What the retrieval is checked against: the rest of the resolved scene.
pub(super) struct Resolved<'a> {
    pub lines: &'a [Channel],
    pub lidar: &'a Lidar,
    pub laser: &'a Laser,
    pub gates: &'a Gates,
    pub surface: Option<&'a Surface>,
    pub layers: &'a [Layer],
    pub atmosphere: Option<&'a Atmosphere>,
    pub gas: Option<&'a GasAbsorption>,
    pub has_receiver: bool,
}

impl Resolver<'_> {
    /// The laser: the `[laser]` section, or an ideal monochromatic laser with the lidar's pulse
    /// energy.
    pub(super) fn laser(
        &self,
        raw: &SceneDescription,
        lines: &[Channel],
        lidar_pulse_energy_j: Option<f64>,
    ) -> Result<Laser, InputError> {
        let n = lines.len();
        let lidar_key = KeyPath::table("lidar").key("pulse_energy_j");
        let Some(l) = &raw.laser else {
            let e = lidar_pulse_energy_j.ok_or_else(|| {
                self.err(
                    &lidar_key,
                    "missing: the lidar needs `pulse_energy_j` (or a [laser] section with it)",
                )
            })?;
            return Ok(Laser::ideal(self.range(&lidar_key, e, PULSE_ENERGY_J)?, n));
        };
        if lidar_pulse_energy_j.is_some() {
            return Err(self.err(
                &lidar_key,
                "with a [laser] section the pulse energy goes there (`laser.pulse_energy_j`)",
            ));
        }
        let sec = KeyPath::table("laser");
        let at = sec.key("pulse_energy_j");
        let pulse_energy_j = self.per_channel(&at, &l.pulse_energy_j, n)?;
        self.range_all(&at, &pulse_energy_j, PULSE_ENERGY_J)?;
        let repetition_rate_hz = self.range(
            &sec.key("repetition_rate_hz"),
            l.repetition_rate_hz,
            REPETITION_RATE_HZ,
        )?;
        let shape_at = sec.key("line_shape");
        let width_at = sec.key("linewidth_fwhm_mhz");
        let file_at = sec.key("line_shape_file");
        let kind = l.line_shape.as_deref().unwrap_or("monochromatic");
        let width = |w: Option<f64>| -> Result<f64, InputError> {
            let w = w.ok_or_else(|| {
                self.err(&shape_at, format!("`{kind}` needs `linewidth_fwhm_mhz`"))
            })?;
            self.range(&width_at, w, LINEWIDTH_MHZ)
        };
        let line_shape = match kind {
            "monochromatic" | "table" if l.linewidth_fwhm_mhz.is_some() => {
                return Err(self.err(
                    &width_at,
                    format!("goes with a gaussian or lorentzian line shape, not `{kind}`"),
                ));
            }
            "monochromatic" => LineShape::Monochromatic,
            "gaussian" => LineShape::gaussian(width(l.linewidth_fwhm_mhz)?)
                .map_err(|m| self.err(&width_at, m))?,
            "lorentzian" => LineShape::lorentzian(width(l.linewidth_fwhm_mhz)?)
                .map_err(|m| self.err(&width_at, m))?,
            "table" => {
                let f = l.line_shape_file.as_ref().ok_or_else(|| {
                    self.err(
                        &shape_at,
                        "`table` needs `line_shape_file` (relative to the scene)",
                    )
                })?;
                let p = self.base_dir.join(f);
                LineShape::Table(
                    LineShapeTable::read(&p)
                        .map_err(|e| self.err(&file_at, format!("line-shape table: {e}")))?,
                )
            }
            other => {
                return Err(self.err(
                    &shape_at,
                    format!(
                        "`{other}` is not a line shape (monochromatic, gaussian, lorentzian, table)"
                    ),
                ));
            }
        };
        if kind != "table" && l.line_shape_file.is_some() {
            return Err(self.err(&file_at, "goes with line_shape = \"table\""));
        }
        let nodes_at = sec.key("line_shape_nodes");
        let nodes = match (l.line_shape_nodes, &line_shape) {
            (Some(_), LineShape::Monochromatic) => {
                return Err(self.err(&nodes_at, "goes with a line shape other than monochromatic"));
            }
            (Some(k), _) if !(1..=64).contains(&k) => {
                return Err(self.err(&nodes_at, format!("{k} must lie in 1..=64")));
            }
            (Some(k), _) => k,
            (None, LineShape::Monochromatic) => 1,
            (None, _) => DEFAULT_LINE_SHAPE_NODES,
        };
        let frequency_offset_mhz = match &l.frequency_offset_mhz {
            Some(v) => {
                let at = sec.key("frequency_offset_mhz");
                let o = self.per_channel(&at, v, n)?;
                self.range_all(&at, &o, FREQUENCY_OFFSET_MHZ)?;
                o
            }
            None => vec![0.0; n],
        };
        let frequency_jitter_rms_mhz = self.range(
            &sec.key("frequency_jitter_rms_mhz"),
            l.frequency_jitter_rms_mhz.unwrap_or(0.0),
            FREQUENCY_JITTER_MHZ,
        )?;
        let purity_at = sec.key("spectral_purity");
        let spectral_purity = self.range(&purity_at, l.spectral_purity.unwrap_or(1.0), PURITY)?;
        let imp_at = sec.key("impurity_wavenumber_cm1");
        let impurity_wavenumber_cm1 = match (&l.impurity_wavenumber_cm1, spectral_purity < 1.0) {
            (Some(v), true) => {
                let w = self.per_channel(&imp_at, v, n)?;
                self.range_all(&imp_at, &w, WAVENUMBER_CM1)?;
                w
            }
            (None, true) => {
                return Err(self.err(
                    &purity_at,
                    "spectral purity below 1 needs `impurity_wavenumber_cm1` (where the rest of the energy goes)",
                ));
            }
            (Some(_), false) => {
                return Err(self.err(&imp_at, "goes with `spectral_purity` below 1"));
            }
            (None, false) => vec![f64::NAN; n],
        };
        let fraction = |key: &str, v: Option<f64>| -> Result<f64, InputError> {
            self.range(&sec.key(key), v.unwrap_or(0.0), FRACTION_BELOW_1)
        };
        Ok(Laser {
            line_shape,
            nodes,
            frequency_offset_mhz,
            frequency_jitter_rms_mhz,
            spectral_purity,
            impurity_wavenumber_cm1,
            pulse_energy_j,
            repetition_rate_hz,
            pulse_energy_jitter_fraction: fraction(
                "pulse_energy_jitter_fraction",
                l.pulse_energy_jitter_fraction,
            )?,
            energy_monitor_error_fraction: fraction(
                "energy_monitor_error_fraction",
                l.energy_monitor_error_fraction,
            )?,
        })
    }

    /// The `[receiver]` and `[background]` sections.
    pub(super) fn receiver(
        &self,
        raw: &SceneDescription,
        lines: &[Channel],
        surface_albedo: Option<f64>,
    ) -> Result<Option<Receiver>, InputError> {
        let Some(r) = &raw.receiver else {
            if raw.background.is_some() {
                return Err(self.err(&KeyPath::table("background"), "needs a [receiver]"));
            }
            return Ok(None);
        };
        let sec = KeyPath::table("receiver");
        // Filter width as a wavenumber interval at the lines' mean wavenumber.
        let nu = lines.iter().map(|c| c.wavenumber_cm1).sum::<f64>() / lines.len() as f64;
        let bandwidth_cm1 = match (r.filter_bandwidth_nm, r.filter_bandwidth_ghz) {
            (None, None) => f64::INFINITY,
            _ => {
                let (_, nm) = self.one_of(
                    &sec,
                    (
                        "filter_bandwidth_nm",
                        r.filter_bandwidth_nm,
                        1.0,
                        FILTER_WIDTH_NM,
                    ),
                    // Δλ = λ² Δν: GHz → cm⁻¹ → nm at the mean wavenumber.
                    (
                        "filter_bandwidth_ghz",
                        r.filter_bandwidth_ghz,
                        1e3 / MHZ_PER_CM1 * 1e7 / (nu * nu),
                        FILTER_WIDTH_GHZ,
                    ),
                )?;
                nm * nu * nu * 1e-7
            }
        };
        let t_at = sec.key("filter_transmission");
        let transmission = self.range(&t_at, r.filter_transmission.unwrap_or(1.0), EFFICIENCY)?;
        let quantum_efficiency = self.range(
            &sec.key("quantum_efficiency"),
            r.quantum_efficiency,
            EFFICIENCY,
        )?;
        let gain = self.range(&sec.key("gain"), r.gain.unwrap_or(1.0), GAIN)?;
        let excess_noise_factor = match (r.excess_noise_factor, r.ionization_ratio) {
            (None, None) => 1.0,
            _ => {
                let (_, v) = self.one_of(
                    &sec,
                    (
                        "excess_noise_factor",
                        r.excess_noise_factor,
                        1.0,
                        EXCESS_NOISE,
                    ),
                    ("ionization_ratio", r.ionization_ratio, 1.0, FRACTION),
                )?;
                if r.ionization_ratio.is_some() {
                    detector::excess_noise_factor(gain, v)
                } else {
                    v
                }
            }
        };
        let opt = |key: &str, v: Option<f64>, bounds: Bounds| {
            self.range(&sec.key(key), v.unwrap_or(0.0), bounds)
        };
        let nep = opt("nep_w_per_sqrt_hz", r.nep_w_per_sqrt_hz, NOISE_DENSITY)?;
        let amp = opt(
            "amplifier_noise_a_per_sqrt_hz",
            r.amplifier_noise_a_per_sqrt_hz,
            NOISE_DENSITY,
        )?;
        let bandwidth_hz = match r.bandwidth_mhz {
            Some(b) => self.range(&sec.key("bandwidth_mhz"), b, BANDWIDTH_MHZ)? * 1e6,
            None if nep > 0.0 || amp > 0.0 => {
                return Err(self.err(
                    &sec,
                    "NEP or amplifier noise needs the electrical bandwidth `bandwidth_mhz`",
                ));
            }
            None => UNUSED_BANDWIDTH_HZ,
        };
        let detector = Detector {
            quantum_efficiency,
            gain,
            excess_noise_factor,
            dark_current_a: opt("dark_current_a", r.dark_current_a, DARK_CURRENT_A)?,
            nep_w_per_sqrt_hz: nep,
            amplifier_noise_a_per_sqrt_hz: amp,
            readout_noise_electrons: opt(
                "readout_noise_electrons",
                r.readout_noise_electrons,
                READOUT_NOISE_E,
            )?,
            bandwidth_hz,
        };
        detector.validate().map_err(|m| self.err(&sec, m))?;
        let background_radiance_w_per_m2_sr_um = match &raw.background {
            None => 0.0,
            Some(b) => self.background(b, surface_albedo, bandwidth_cm1)?,
        };
        Ok(Some(Receiver {
            filter: Filter {
                bandwidth_cm1,
                transmission,
            },
            detector,
            background_radiance_w_per_m2_sr_um,
        }))
    }

    /// Background radiance: given, or sunlight reflected by a Lambertian scene,
    /// L = ρ E_sun cos θ_sun / π (no atmospheric attenuation of the sunlight).
    fn background(
        &self,
        b: &BackgroundDescription,
        surface_albedo: Option<f64>,
        filter_bandwidth_cm1: f64,
    ) -> Result<f64, InputError> {
        let sec = KeyPath::table("background");
        if !filter_bandwidth_cm1.is_finite() {
            return Err(self.err(
                &sec,
                "a background needs the filter's width (`receiver.filter_bandwidth_nm` or `_ghz`)",
            ));
        }
        let solar = b.solar_irradiance_w_per_m2_um.is_some()
            || b.solar_zenith_angle_deg.is_some()
            || b.reflectance.is_some();
        match (b.radiance_w_per_m2_sr_um, solar) {
            (Some(l), false) => self.range(&sec.key("radiance_w_per_m2_sr_um"), l, RADIANCE),
            (None, true) => {
                let e_at = sec.key("solar_irradiance_w_per_m2_um");
                let e = b
                    .solar_irradiance_w_per_m2_um
                    .ok_or_else(|| self.err(&sec, "sunlight needs `solar_irradiance_w_per_m2_um`"))?;
                let e = self.range(&e_at, e, IRRADIANCE)?;
                let z_at = sec.key("solar_zenith_angle_deg");
                let z = b
                    .solar_zenith_angle_deg
                    .ok_or_else(|| self.err(&sec, "sunlight needs `solar_zenith_angle_deg`"))?;
                let z = self.range(&z_at, z, SOLAR_ZENITH_DEG)?;
                let rho = match (b.reflectance, surface_albedo) {
                    (Some(r), _) => self.range(&sec.key("reflectance"), r, FRACTION)?,
                    (None, Some(a)) => a,
                    (None, None) => {
                        return Err(self.err(
                            &sec,
                            "sunlight needs `reflectance` (there is no [surface] to take it from)",
                        ));
                    }
                };
                Ok(rho * e * z.to_radians().cos() / std::f64::consts::PI)
            }
            (Some(_), true) => Err(self.err(
                &sec.key("radiance_w_per_m2_sr_um"),
                "give the radiance or the sunlight (`solar_irradiance_w_per_m2_um`, `solar_zenith_angle_deg`, `reflectance`), not both",
            )),
            (None, false) => Err(self.err(
                &sec,
                "needs `radiance_w_per_m2_sr_um` or `solar_irradiance_w_per_m2_um` with `solar_zenith_angle_deg`",
            )),
        }
    }

    /// The `[retrieval]` section.
    pub(super) fn retrieval(
        &self,
        raw: &SceneDescription,
        scene: &Resolved,
    ) -> Result<Option<RetrievalConfig>, InputError> {
        let Resolved {
            lines,
            lidar,
            laser,
            gates,
            surface,
            layers,
            atmosphere,
            gas,
            has_receiver,
        } = *scene;
        let Some(r) = &raw.retrieval else {
            return Ok(None);
        };
        let sec = KeyPath::table("retrieval");
        let gas_name = r.gas.clone().unwrap_or_else(|| "CO2".into());
        let gas_at = sec.key("gas");
        let (Some(atm), Some(g)) = (atmosphere, gas) else {
            return Err(self.err(
                &sec,
                "needs an [atmosphere] with gas profiles and [gas_absorption]",
            ));
        };
        let id = isotopologues::molecule_id(&gas_name).ok_or_else(|| {
            self.err(
                &gas_at,
                format!("`{gas_name}` is not a HITRAN molecule lidarsim knows"),
            )
        })?;
        if atm.profile.gas(&gas_name).is_none() {
            return Err(self.err(
                &gas_at,
                format!("the atmosphere has no `{gas_name}` profile"),
            ));
        }
        if !g.lines.molecules().contains(&id) {
            return Err(self.err(
                &gas_at,
                format!("the gas absorption has no {gas_name} lines near the channels"),
            ));
        }
        if !has_receiver {
            return Err(self.err(&sec, "needs a [receiver] (detector and noise)"));
        }
        let line = |key: &str, v: &Option<String>, default: &str| -> Result<usize, InputError> {
            let name = v.as_deref().unwrap_or(default);
            lines.iter().position(|c| c.name == name).ok_or_else(|| {
                let names: Vec<&str> = lines.iter().map(|c| c.name.as_str()).collect();
                self.err(
                    &sec.key(key),
                    format!("no channel named `{name}` (channels: {})", names.join(", ")),
                )
            })
        };
        let on = line("on", &r.on, "on")?;
        let off = line("off", &r.off, "off")?;
        if on == off {
            return Err(self.err(&sec.key("off"), "must differ from the on-line"));
        }
        let target = self.target(r, lidar, gates, surface, layers)?;
        let dial = self.dial_cells(r, lidar, gates, surface)?;
        if target.is_none() && dial.is_none() {
            return Err(self.err(
                &sec.key("target"),
                "nothing to retrieve: no hard target in range (IPDA) and no `dial_cell_m` (DIAL)",
            ));
        }
        let (averaging_shots, averaging_label) = match (
            r.averaging_shots,
            r.averaging_length_km,
            r.platform_speed_m_per_s,
        ) {
            (Some(n), None, None) => {
                if n == 0 || n > 1_000_000_000 {
                    return Err(self.err(
                        &sec.key("averaging_shots"),
                        format!("{n} must lie in 1..=1e9"),
                    ));
                }
                (n, format!("{n} shot pairs"))
            }
            (None, Some(len), Some(v)) => {
                let len = self.range(&sec.key("averaging_length_km"), len, AVERAGING_LENGTH_KM)?;
                let v = self.range(&sec.key("platform_speed_m_per_s"), v, SPEED_M_PER_S)?;
                if !laser.repetition_rate_hz.is_finite() {
                    return Err(self.err(
                        &sec.key("averaging_length_km"),
                        "an averaging length needs the laser's `repetition_rate_hz` ([laser])",
                    ));
                }
                let n = (len * 1e3 / v * laser.repetition_rate_hz).round();
                if !(1.0..=1e9).contains(&n) {
                    return Err(self.err(
                        &sec.key("averaging_length_km"),
                        format!("makes {n} shot pairs; must be 1 to 1e9"),
                    ));
                }
                (n as u64, format!("{len} km along track ({n} shot pairs)"))
            }
            (None, None, None) => {
                return Err(self.err(
                        &sec,
                        "needs `averaging_shots`, or `averaging_length_km` with `platform_speed_m_per_s`",
                    ));
            }
            _ => {
                return Err(self.err(
                        &sec.key("averaging_shots"),
                        "give `averaging_shots` or `averaging_length_km` with `platform_speed_m_per_s`, not both",
                    ));
            }
        };
        let realisations = r.realisations.unwrap_or(DEFAULT_REALISATIONS);
        if !(10..=1_000_000).contains(&realisations) {
            return Err(self.err(
                &sec.key("realisations"),
                format!("{realisations} must lie in 10..=1000000"),
            ));
        }
        let spectroscopy = self.assumed_spectroscopy(r, g)?;
        Ok(Some(RetrievalConfig {
            gas: gas_name,
            on,
            off,
            target,
            dial,
            averaging_shots,
            averaging_label,
            realisations,
            spectroscopy,
        }))
    }

    /// `[retrieval]`'s own spectroscopy (`lines`, `line_shape`, `line_mixing`), if it differs
    /// from the truth's: lines cut like the truth's, the truth's options otherwise.
    fn assumed_spectroscopy(
        &self,
        r: &RetrievalDescription,
        g: &GasAbsorption,
    ) -> Result<Option<AssumedSpectroscopy>, InputError> {
        if r.lines.is_none() && r.line_shape.is_none() && r.line_mixing.is_none() {
            return Ok(None);
        }
        let sec = KeyPath::table("retrieval");
        let mut options = g.options;
        if let Some(shape) = &r.line_shape {
            options.line_shape = shape
                .parse()
                .map_err(|m: String| self.err(&sec.key("line_shape"), m))?;
        }
        if let Some(m) = r.line_mixing {
            options.line_mixing = m;
        }
        let lines = match &r.lines {
            Some(f) => {
                let path = self.base_dir.join(f);
                let (lo, hi) = g
                    .lines
                    .lines
                    .iter()
                    .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), l| {
                        (a.min(l.nu_cm1), b.max(l.nu_cm1))
                    });
                let molecules = Some(g.lines.molecules());
                let filter = LineFilter {
                    molecules,
                    isotopologues: None,
                    min_cm1: Some(lo - 1.0),
                    max_cm1: Some(hi + 1.0),
                };
                Arc::new(
                    LineList::read(&path, &filter)
                        .map_err(|e| self.err(&sec.key("lines"), format!("line file: {e}")))?,
                )
            }
            None => g.lines.clone(),
        };
        options.check_lines(&lines).map_err(|e| {
            let key = if r.line_shape.is_some() {
                "line_shape"
            } else if r.line_mixing.is_some() {
                "line_mixing"
            } else {
                "lines"
            };
            self.err(&sec.key(key), e.to_string())
        })?;
        Ok(Some(AssumedSpectroscopy { lines, options }))
    }

    /// The IPDA hard target: given, or the surface when it is in range.
    fn target(
        &self,
        r: &RetrievalDescription,
        lidar: &Lidar,
        gates: &Gates,
        surface: Option<&Surface>,
        layers: &[Layer],
    ) -> Result<Option<HardTarget>, InputError> {
        let at = KeyPath::table("retrieval").key("target");
        let mu = lidar.axis().z;
        let z0 = lidar.altitude_m;
        let gate_of = |range: f64| -> Option<usize> {
            let x = (range - gates.start_m) / gates.width_m;
            (x >= 0.0 && x < gates.count as f64).then_some(x as usize)
        };
        let (kind, range_m, altitude_m, window_m) = match r.target.as_deref() {
            None | Some("surface") => {
                let explicit = r.target.is_some();
                let in_range = surface
                    .filter(|_| mu < -1e-12)
                    .map(|s| (s, (z0 - s.altitude_m) / -mu))
                    .filter(|(_, range)| gate_of(*range).is_some());
                match in_range {
                    Some((s, range)) => (TargetKind::Surface, range, s.altitude_m, 0.0),
                    None if !explicit => return Ok(None),
                    None => {
                        let why = match surface {
                            None => "the scene has no [surface]".to_string(),
                            Some(_) if mu >= -1e-12 => {
                                "the lidar does not look down at the surface".into()
                            }
                            Some(s) => format!(
                                "the surface is {:.1} m away, outside the gates {}–{} m",
                                (z0 - s.altitude_m) / -mu,
                                gates.start_m,
                                gates.end_m()
                            ),
                        };
                        return Err(self.err(&at, format!("no hard target in range: {why}")));
                    }
                }
            }
            Some(name) => {
                let (index, layer) = layers
                    .iter()
                    .enumerate()
                    .find(|(_, l)| l.name == name)
                    .ok_or_else(|| {
                        let names: Vec<&str> = layers.iter().map(|l| l.name.as_str()).collect();
                        self.err(
                            &at,
                            format!(
                                "`{name}` is neither `surface` nor a layer name (layers: {})",
                                names.join(", ")
                            ),
                        )
                    })?;
                if mu.abs() < 1e-12 {
                    return Err(self.err(&at, "a horizontal beam has no layer top to hit"));
                }
                // The near side of the layer: its top seen from above, its base from below.
                let near = if mu < 0.0 { layer.top_m } else { layer.base_m };
                let range = (near - z0) / mu;
                if !(range > 0.0) || gate_of(range).is_none() {
                    return Err(self.err(
                        &at,
                        format!(
                            "no hard target in range: layer `{name}` begins {range:.1} m along the beam, outside the gates {}–{} m",
                            gates.start_m,
                            gates.end_m()
                        ),
                    ));
                }
                let thickness = (layer.top_m - layer.base_m) / mu.abs();
                (
                    TargetKind::Layer {
                        index,
                        name: name.to_string(),
                    },
                    range,
                    near,
                    thickness,
                )
            }
        };
        let w_at = KeyPath::table("retrieval").key("target_window_m");
        let window_m = match r.target_window_m {
            Some(w) => self.range(&w_at, w, PATH_LENGTH_M)?,
            None => window_m,
        };
        let first = gate_of(range_m).unwrap_or(0);
        // The last gate the echo reaches (a window ending on a gate edge stays in that gate).
        let last = ((range_m + window_m - gates.start_m) / gates.width_m).ceil() as usize;
        let last = last.max(first + 1);
        if last > gates.count {
            return Err(self.err(
                &w_at,
                format!(
                    "the echo window {range_m:.1}–{:.1} m reaches beyond the last gate ({} m)",
                    range_m + window_m,
                    gates.end_m()
                ),
            ));
        }
        Ok(Some(HardTarget {
            kind,
            range_m,
            altitude_m,
            gates: first..last,
        }))
    }

    /// Range cells of a range-resolved DIAL retrieval, if `dial_cell_m` is given.
    fn dial_cells(
        &self,
        r: &RetrievalDescription,
        lidar: &Lidar,
        gates: &Gates,
        surface: Option<&Surface>,
    ) -> Result<Option<DialCells>, InputError> {
        let sec = KeyPath::table("retrieval");
        let Some(cell) = r.dial_cell_m else {
            for (k, given) in [
                ("dial_start_m", r.dial_start_m.is_some()),
                ("dial_end_m", r.dial_end_m.is_some()),
            ] {
                if given {
                    return Err(self.err(&sec.key(k), "goes with `dial_cell_m`"));
                }
            }
            return Ok(None);
        };
        let at = sec.key("dial_cell_m");
        let cell = self.range(&at, cell, Bounds::positive(PATH_LENGTH_M.hi))?;
        if cell < gates.width_m * (1.0 - 1e-9) {
            return Err(self.err(
                &at,
                format!(
                    "a range cell of {cell} m is shorter than a gate ({} m)",
                    gates.width_m
                ),
            ));
        }
        let k = (cell / gates.width_m).round();
        if (cell / gates.width_m - k).abs() > 1e-6 * k {
            return Err(self.err(
                &at,
                format!(
                    "{cell} m is not a whole number of {} m gates",
                    gates.width_m
                ),
            ));
        }
        let k = k as usize;
        let centre = |g: usize| gates.centre_m(g);
        // The last usable gate: inside the gates, and wholly before the surface if the beam
        // hits one (the surface echo would swamp the atmospheric return of its gate).
        let mut last = gates.count - 1;
        let mu = lidar.axis().z;
        if let Some(s) = surface.filter(|_| mu < -1e-12) {
            let rs = (lidar.altitude_m - s.altitude_m) / -mu;
            let x = ((rs - gates.start_m) / gates.width_m).floor();
            if x < 1.0 {
                return Err(self.err(&at, "no gate lies wholly before the surface"));
            }
            last = last.min(x as usize - 1);
        }
        let first = match r.dial_start_m {
            Some(s) => {
                let s_at = sec.key("dial_start_m");
                let g = ((s - gates.start_m) / gates.width_m - 0.5).ceil().max(0.0);
                if !(s.is_finite()) || g as usize > last {
                    return Err(self.err(
                        &s_at,
                        format!(
                            "{s} m is beyond the last usable gate centre ({} m)",
                            centre(last)
                        ),
                    ));
                }
                g as usize
            }
            None => 0,
        };
        let end_gate = match r.dial_end_m {
            Some(e) => {
                let e_at = sec.key("dial_end_m");
                let g = ((e - gates.start_m) / gates.width_m - 0.5).floor();
                if !(e.is_finite()) || g < first as f64 {
                    return Err(self.err(
                        &e_at,
                        format!(
                            "{e} m is before the first cell starts ({} m)",
                            centre(first)
                        ),
                    ));
                }
                (g as usize).min(last)
            }
            None => last,
        };
        let cells = (end_gate - first) / k;
        if cells == 0 {
            return Err(self.err(
                &at,
                format!(
                    "no whole {cell} m cell fits between the gate centres {} and {} m",
                    centre(first),
                    centre(end_gate)
                ),
            ));
        }
        Ok(Some(DialCells {
            cell_m: cell,
            first_gate: first,
            gates_per_cell: k,
            cells,
        }))
    }
}
