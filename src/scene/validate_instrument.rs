//! Step 2 for the instrument sections, `[laser]`, `[receiver]` and `[background]`: every check
//! of their values, with no file read (a line-shape table is read by resolve). What they say is
//! handed to resolve as plain values, which builds the instrument's types from them.

use super::Channel;
use super::description::{
    BackgroundDescription, LaserDescription, LineShapeTableDescription, SceneDescription,
};
use super::ranges::*;
use super::source::KeyPath;
use super::validator::Validator;
use crate::input::{Bounds, InputError, check_finite_range};

/// Default number of line-shape quadrature nodes (odd, so the line centre is a node).
const DEFAULT_LINE_SHAPE_NODES: usize = 5;

/// The emitter's line shape as the description gives it.
#[derive(Debug, Clone, PartialEq)]
pub(super) enum LaserLineShape {
    /// A single frequency.
    Monochromatic,
    /// A gaussian line of this full width at half maximum \[MHz\].
    Gaussian(f64),
    /// A lorentzian line of this full width at half maximum \[MHz\].
    Lorentzian(f64),
    /// A table read from this file (relative to the scene).
    TableFile(String),
    /// A table given by values.
    TableValues(LineShapeTableDescription),
}

/// The laser's checked values: an ideal monochromatic laser, or the `[laser]` section's.
#[derive(Debug, Clone)]
pub(super) enum LaserValues {
    /// No `[laser]`: an ideal laser with `[lidar] pulse_energy_j`.
    Ideal {
        /// Pulse energy of every line \[J\].
        pulse_energy_j: f64,
    },
    /// The `[laser]` section, one value per line where per-line.
    Given(GivenLaser),
}

/// The values of a `[laser]` section, per line where per-line.
#[derive(Debug, Clone)]
pub(super) struct GivenLaser {
    pub line_shape: LaserLineShape,
    pub nodes: usize,
    pub frequency_offset_mhz: Vec<f64>,
    pub frequency_jitter_rms_mhz: f64,
    pub spectral_purity: f64,
    pub impurity_wavenumber_cm1: Vec<f64>,
    pub pulse_energy_j: Vec<f64>,
    pub repetition_rate_hz: f64,
    pub pulse_energy_jitter_fraction: f64,
    pub energy_monitor_error_fraction: f64,
}

impl LaserValues {
    /// The pulse repetition rate \[Hz\] (NaN for the ideal laser, which has none).
    pub fn repetition_rate_hz(&self) -> f64 {
        match self {
            LaserValues::Ideal { .. } => f64::NAN,
            LaserValues::Given(l) => l.repetition_rate_hz,
        }
    }
}

/// The filter's width as given, in its key's unit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum FilterWidth {
    /// No filter (an infinitely wide one).
    None,
    /// `filter_bandwidth_nm`.
    Nm(f64),
    /// `filter_bandwidth_ghz`.
    Ghz(f64),
}

/// The background's checked values.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum BackgroundValues {
    /// No `[background]`.
    None,
    /// A given radiance \[W/(m² sr µm)\].
    Radiance(f64),
    /// Sunlight reflected by a Lambertian scene.
    Sunlight {
        /// Solar irradiance \[W/(m² µm)\].
        irradiance_w_per_m2_um: f64,
        /// Solar zenith angle \[deg\].
        zenith_deg: f64,
        /// Reflectance of the scene.
        reflectance: f64,
    },
}

/// The receiver's checked values (`[receiver]` and `[background]`).
#[derive(Debug, Clone)]
pub(super) struct ReceiverValues {
    pub filter_width: FilterWidth,
    pub filter_transmission: f64,
    pub quantum_efficiency: f64,
    pub gain: f64,
    /// The excess noise factor, or (when `from_ionization_ratio`) the APD ionisation ratio.
    pub excess_noise: f64,
    pub from_ionization_ratio: bool,
    pub dark_current_a: f64,
    pub nep_w_per_sqrt_hz: f64,
    pub amplifier_noise_a_per_sqrt_hz: f64,
    pub readout_noise_electrons: f64,
    /// `None`: no white-noise term needs a bandwidth.
    pub bandwidth_hz: Option<f64>,
    pub background: BackgroundValues,
}

impl Validator<'_> {
    /// The laser: the `[laser]` section, or an ideal monochromatic laser with the lidar's pulse
    /// energy.
    pub(super) fn laser(
        &self,
        raw: &SceneDescription,
        lines: &[Channel],
        lidar_pulse_energy_j: Option<f64>,
    ) -> Result<LaserValues, InputError> {
        let n = lines.len();
        let lidar_key = KeyPath::table("lidar").key("pulse_energy_j");
        let Some(l) = &raw.laser else {
            let e = lidar_pulse_energy_j.ok_or_else(|| {
                self.err(
                    &lidar_key,
                    "missing: the lidar needs `pulse_energy_j` (or a [laser] section with it)",
                )
            })?;
            return Ok(LaserValues::Ideal {
                pulse_energy_j: self.range(&lidar_key, e, PULSE_ENERGY_J)?,
            });
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
        let (line_shape, nodes) = self.laser_line_shape(l)?;
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
        Ok(LaserValues::Given(GivenLaser {
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
        }))
    }

    /// `[laser]`'s line shape and its quadrature nodes.
    fn laser_line_shape(
        &self,
        l: &LaserDescription,
    ) -> Result<(LaserLineShape, usize), InputError> {
        let sec = KeyPath::table("laser");
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
            "monochromatic" => LaserLineShape::Monochromatic,
            "gaussian" => LaserLineShape::Gaussian(width(l.linewidth_fwhm_mhz)?),
            "lorentzian" => LaserLineShape::Lorentzian(width(l.linewidth_fwhm_mhz)?),
            "table" => match (&l.line_shape_file, &l.line_shape_table) {
                (Some(f), None) => LaserLineShape::TableFile(f.clone()),
                (None, Some(t)) => {
                    let at = sec.key("line_shape_table");
                    if t.offset_mhz.len() != t.relative_intensity.len() {
                        return Err(self.err(
                            &at,
                            "needs as many `relative_intensity` values as `offset_mhz`",
                        ));
                    }
                    for x in t.offset_mhz.iter().chain(&t.relative_intensity) {
                        check_finite_range(*x, Bounds::closed(-f64::MAX, f64::MAX))
                            .map_err(|m| self.err(&at, m))?;
                    }
                    LaserLineShape::TableValues(t.clone())
                }
                (Some(_), Some(_)) => {
                    return Err(self.err(
                        &sec.key("line_shape_table"),
                        "give `line_shape_file` or `line_shape_table`, not both",
                    ));
                }
                (None, None) => {
                    return Err(self.err(
                        &shape_at,
                        "`table` needs `line_shape_file` (relative to the scene)",
                    ));
                }
            },
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
        if kind != "table" && l.line_shape_table.is_some() {
            return Err(self.err(
                &sec.key("line_shape_table"),
                "goes with line_shape = \"table\"",
            ));
        }
        let nodes_at = sec.key("line_shape_nodes");
        let monochromatic = line_shape == LaserLineShape::Monochromatic;
        let nodes = match (l.line_shape_nodes, monochromatic) {
            (Some(_), true) => {
                return Err(self.err(&nodes_at, "goes with a line shape other than monochromatic"));
            }
            (Some(k), _) if !(1..=64).contains(&k) => {
                return Err(self.err(&nodes_at, format!("{k} must lie in 1..=64")));
            }
            (Some(k), _) => k,
            (None, true) => 1,
            (None, false) => DEFAULT_LINE_SHAPE_NODES,
        };
        Ok((line_shape, nodes))
    }

    /// The `[receiver]` and `[background]` sections.
    pub(super) fn receiver(
        &self,
        raw: &SceneDescription,
        surface_albedo: Option<f64>,
    ) -> Result<Option<ReceiverValues>, InputError> {
        let Some(r) = &raw.receiver else {
            if raw.background.is_some() {
                return Err(self.err(&KeyPath::table("background"), "needs a [receiver]"));
            }
            return Ok(None);
        };
        let sec = KeyPath::table("receiver");
        let filter_width = match (r.filter_bandwidth_nm, r.filter_bandwidth_ghz) {
            (None, None) => FilterWidth::None,
            _ => {
                let (_, v) = self.one_of(
                    &sec,
                    (
                        "filter_bandwidth_nm",
                        r.filter_bandwidth_nm,
                        1.0,
                        FILTER_WIDTH_NM,
                    ),
                    (
                        "filter_bandwidth_ghz",
                        r.filter_bandwidth_ghz,
                        1.0,
                        FILTER_WIDTH_GHZ,
                    ),
                )?;
                if r.filter_bandwidth_nm.is_some() {
                    FilterWidth::Nm(v)
                } else {
                    FilterWidth::Ghz(v)
                }
            }
        };
        let t_at = sec.key("filter_transmission");
        let filter_transmission =
            self.range(&t_at, r.filter_transmission.unwrap_or(1.0), EFFICIENCY)?;
        let quantum_efficiency = self.range(
            &sec.key("quantum_efficiency"),
            r.quantum_efficiency,
            EFFICIENCY,
        )?;
        let gain = self.range(&sec.key("gain"), r.gain.unwrap_or(1.0), GAIN)?;
        let excess_noise = match (r.excess_noise_factor, r.ionization_ratio) {
            (None, None) => 1.0,
            _ => {
                self.one_of(
                    &sec,
                    (
                        "excess_noise_factor",
                        r.excess_noise_factor,
                        1.0,
                        EXCESS_NOISE,
                    ),
                    ("ionization_ratio", r.ionization_ratio, 1.0, FRACTION),
                )?
                .1
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
            Some(b) => Some(self.range(&sec.key("bandwidth_mhz"), b, BANDWIDTH_MHZ)? * 1e6),
            None if nep > 0.0 || amp > 0.0 => {
                return Err(self.err(
                    &sec,
                    "NEP or amplifier noise needs the electrical bandwidth `bandwidth_mhz`",
                ));
            }
            None => None,
        };
        let dark_current_a = opt("dark_current_a", r.dark_current_a, DARK_CURRENT_A)?;
        let readout_noise_electrons = opt(
            "readout_noise_electrons",
            r.readout_noise_electrons,
            READOUT_NOISE_E,
        )?;
        let background = match &raw.background {
            None => BackgroundValues::None,
            Some(b) => self.background(b, surface_albedo, filter_width)?,
        };
        Ok(Some(ReceiverValues {
            filter_width,
            filter_transmission,
            quantum_efficiency,
            gain,
            excess_noise,
            from_ionization_ratio: r.ionization_ratio.is_some(),
            dark_current_a,
            nep_w_per_sqrt_hz: nep,
            amplifier_noise_a_per_sqrt_hz: amp,
            readout_noise_electrons,
            bandwidth_hz,
            background,
        }))
    }

    /// Background light: a radiance, or sunlight reflected by the scene.
    fn background(
        &self,
        b: &BackgroundDescription,
        surface_albedo: Option<f64>,
        filter_width: FilterWidth,
    ) -> Result<BackgroundValues, InputError> {
        let sec = KeyPath::table("background");
        if filter_width == FilterWidth::None {
            return Err(self.err(
                &sec,
                "a background needs the filter's width (`receiver.filter_bandwidth_nm` or `_ghz`)",
            ));
        }
        let solar = b.solar_irradiance_w_per_m2_um.is_some()
            || b.solar_zenith_angle_deg.is_some()
            || b.reflectance.is_some();
        match (b.radiance_w_per_m2_sr_um, solar) {
            (Some(l), false) => Ok(BackgroundValues::Radiance(self.range(
                &sec.key("radiance_w_per_m2_sr_um"),
                l,
                RADIANCE,
            )?)),
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
                Ok(BackgroundValues::Sunlight {
                    irradiance_w_per_m2_um: e,
                    zenith_deg: z,
                    reflectance: rho,
                })
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
}
