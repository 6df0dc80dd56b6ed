//! Line selection for a CO2 IPDA (`lidarsim select-lines`): for candidate on-line positions
//! next to one off-line, the systematic XCO2 errors a nadir IPDA makes when the atmospheric
//! state or the laser frequency it assumes is wrong, its random error, and a ranking.
//!
//! # What is computed
//!
//! For every profile (a built-in AFGL atmosphere or a member of a profile set), with its CO2
//! well mixed in dry air at `--co2-ppm` ([`set_co2_column_average`]), and every on-line position ν_on
//! (monochromatic laser, nadir from the top of the grid to the surface, μ = −1):
//!
//! * `daod_one_way`: D = τ(ν_on) − τ(ν_off), the one-way vertical optical depths of all gases
//!   with lines from the top of the grid to the surface;
//! * `wf_peak_hpa`: the pressure where the IPDA weighting function **per unit pressure**,
//!   WF_l = Δτ_CO2,l / (x_l Δp_l) (layer l, Δτ_CO2 its CO2 differential optical depth, x_l its
//!   dry-air CO2 mole fraction and Δp_l its pressure thickness in hPa, from the same hydrostatic
//!   integration as the columns, so that D_CO2 = Σ WF_l x_l Δp_l; [`weighting_function`]),
//!   peaks: the centre (mean ln p) of the largest layer, refined by a parabola in ln p through
//!   it and its neighbours (the resolution is the layer thickness near the surface);
//! * four sensitivities, XCO2 retrieved − XCO2 true \[ppm\] ([`Steps`]): a retrieval with the
//!   assumed state's reference ([`crate::retrieval::ReferenceState`]) fits the scale s of its
//!   CO2 to the true DAOD (`solve_scale`, which subtracts the assumed other-gas absorption), and
//!   reports s · X_assumed; the truth is the true profile's X over the same altitudes:
//!   * `dxco2_per_k_ppm`: truth = shift(T + 1 K), assumed = shift(none);
//!   * `dxco2_per_mhz_ppm`: truth = the on-line 1 MHz higher than assumed, same profile;
//!   * `dxco2_per_hpa_ppm`: truth = shift(none), assumed = shift(p_s + 1 hPa);
//!   * `dxco2_per_10pct_h2o_ppm`: truth = shift(H2O × 1.1), assumed = shift(none) (a profile
//!     without H2O has no water to change: 0).
//!
//!   "shift" is [`shift_member`], which re-levels hydrostatically; both sides are always shifted
//!   profiles, never a shifted one against the original (see its docs);
//! * the two-way gas transmission of the on-line, T² = exp(−2 τ(ν_on));
//! * with a [`NoiseModel`], the random error of an averaged measurement (docs/design.md §3),
//!   δX = X/(2D) · sqrt(Σ_ℓ [SNR_ℓ⁻² + ε_M² + (σ_j ∂ln E_ℓ/∂ν)²]) / √N over ℓ ∈ {on, off}, the
//!   form of [`crate::retrieval::products`] for a hard target.
//!
//! The layer grid runs from the profile's surface in steps of [`GridSpec::layer_m`] to
//! [`GridSpec::top_m`], clipped to the lowest top of the four shifted profiles so that every one
//! covers it (the last layer may be thinner). All on positions, the off-line and the on- and
//! off-line shifted by 1 MHz are lines of one reference state per profile and perturbation, so
//! each profile's line-by-line work is done once.
//!
//! A group of profiles (an atmosphere, a latitude class) is summarised by [`summarise`]: the
//! mean of each quantity over its members (and the standard deviation of T²), positions where
//! the on-line does not absorb more than the off-line in every member dropped, and a rank by the
//! total expected error ([`Uncertainties::total_ppm`]).

use crate::atmosphere::{AtmosphereError, Co2Scaling, Profile};
use crate::instrument::detector::{self, Detector};
use crate::instrument::line_shape::MHZ_PER_CM1;
use crate::retrieval::RetrievalError;
use crate::scene::Scene;
use crate::spectroscopy::{LblOptions, LineList, SpectroscopyError};

mod member;
mod summary;

pub use member::{
    MemberFailure, MemberResult, PositionResult, WeightingFunction, study_member, study_members,
    transmission_spectra, weighting_function,
};
pub use summary::{CSV_HEADER, Row, Uncertainties, summarise, to_csv, to_dataset};

/// GHz per cm⁻¹ (c = 299 792 458 m/s): 1 GHz = 1/29.979 cm⁻¹.
pub const GHZ_PER_CM1: f64 = MHZ_PER_CM1 / 1000.0;

/// Global upper quanta of the CO2 30012 level (HITRAN 2004+ format, spaces collapsed).
pub const BAND_UPPER_QUANTA: &str = "3 0 0 12";
/// Global lower quanta of the CO2 ground state 00001.
pub const BAND_LOWER_QUANTA: &str = "0 0 0 01";

/// Why a line-selection study cannot be done.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum SelectError {
    /// A profile that cannot be used or shifted.
    #[error(transparent)]
    Atmosphere(#[from] AtmosphereError),
    /// The retrieval's reference state failed.
    #[error(transparent)]
    Retrieval(#[from] RetrievalError),
    /// The line-by-line computation failed.
    #[error(transparent)]
    Spectroscopy(#[from] SpectroscopyError),
    /// An argument that is not a valid value.
    #[error("{name} = {value}: {reason}")]
    InvalidArgument {
        /// The argument (as the command line names it).
        name: &'static str,
        /// The value given.
        value: String,
        /// What is wrong.
        reason: String,
    },
    /// A line file that cannot be read.
    #[error("--lines {}: {error}", path.display())]
    Lines {
        /// The file.
        path: std::path::PathBuf,
        /// Why.
        error: SpectroscopyError,
    },
    /// A profile set file that cannot be read.
    #[error(transparent)]
    Input(#[from] crate::input::InputError),
    /// A generated ensemble that cannot be drawn.
    #[error(transparent)]
    Study(#[from] crate::study::dial::StudyError),
    /// Options that cannot be studied together; the message names the option.
    #[error("{0}")]
    Usage(String),
    /// A scene that lacks what the random error needs.
    #[error("scene {path}: {message}")]
    Scene {
        /// The scene file.
        path: String,
        /// What is missing.
        message: String,
    },
}

fn invalid(name: &'static str, value: impl ToString, reason: impl Into<String>) -> SelectError {
    SelectError::InvalidArgument {
        name,
        value: value.to_string(),
        reason: reason.into(),
    }
}

/// One line of the CO2 30012←00001 band (626) found in a line list.
#[derive(Debug, Clone, PartialEq)]
pub struct BandLine {
    /// Label as the reference study writes it: branch, J″ and symmetry, e.g. `R16e`.
    pub label: String,
    /// J″.
    pub j_lower: u32,
    /// Vacuum wavenumber at zero pressure [cm⁻¹].
    pub nu_cm1: f64,
}

/// The lines of the CO2 30012←00001 band of ¹²C¹⁶O₂ (molecule 2, isotopologue 1, global quanta
/// [`BAND_UPPER_QUANTA`] ← [`BAND_LOWER_QUANTA`]) in `lines`, labelled from their local lower
/// quanta (`R 16e` → `R16e`), in wavenumber order. The built-in band model names its lines the
/// same way.
pub fn band_lines(lines: &LineList) -> Vec<BandLine> {
    let collapse = |s: &str| s.split_whitespace().collect::<Vec<_>>().join(" ");
    lines
        .lines
        .iter()
        .filter(|l| {
            l.molecule_id == 2
                && l.iso_id == 1
                && collapse(l.global_upper_quanta()) == BAND_UPPER_QUANTA
                && collapse(l.global_lower_quanta()) == BAND_LOWER_QUANTA
        })
        .filter_map(|l| {
            let label: String = l.local_lower_quanta().split_whitespace().collect();
            let j: u32 = label
                .get(1..)?
                .trim_end_matches(|c: char| c.is_ascii_alphabetic())
                .parse()
                .ok()?;
            Some(BandLine {
                label,
                j_lower: j,
                nu_cm1: l.nu_cm1,
            })
        })
        .collect()
}

/// A candidate on-line position.
#[derive(Debug, Clone, PartialEq)]
pub struct OnPosition {
    /// Vacuum wavenumber [cm⁻¹].
    pub nu_cm1: f64,
    /// The band line it sits on (nearest within 0.5 cm⁻¹), if any.
    pub line: Option<String>,
    /// Offset from that line's centre (zero-pressure wavenumber) \[GHz\]; NaN without a line.
    pub offset_ghz: f64,
}

/// Candidate positions: every band line with J″ ≤ `max_j`, at each offset \[GHz\] from its
/// centre, in line order then offset order.
pub fn scan_positions(band: &[BandLine], max_j: u32, offsets_ghz: &[f64]) -> Vec<OnPosition> {
    band.iter()
        .filter(|b| b.j_lower <= max_j)
        .flat_map(|b| {
            offsets_ghz.iter().map(move |&o| OnPosition {
                nu_cm1: b.nu_cm1 + o / GHZ_PER_CM1,
                line: Some(b.label.clone()),
                offset_ghz: o,
            })
        })
        .collect()
}

/// Positions at given wavenumbers, each labelled with the nearest band line within 0.5 cm⁻¹.
pub fn label_positions(band: &[BandLine], nus_cm1: &[f64]) -> Vec<OnPosition> {
    nus_cm1
        .iter()
        .map(|&nu| {
            let near = band
                .iter()
                .min_by(|a, b| (a.nu_cm1 - nu).abs().total_cmp(&(b.nu_cm1 - nu).abs()))
                .filter(|b| (b.nu_cm1 - nu).abs() <= 0.5);
            OnPosition {
                nu_cm1: nu,
                line: near.map(|b| b.label.clone()),
                offset_ghz: near.map_or(f64::NAN, |b| (nu - b.nu_cm1) * GHZ_PER_CM1),
            }
        })
        .collect()
}

/// Give `profile` a CO2 dry-air column average of `ppm` as a well-mixed gas: `ppm` of dry air
/// at every level (moist-air mole fraction ppm·10⁻⁶·(1 − x_H2O)), its own CO2 replaced or
/// added ([`Profile::set_co2_ppm`] with [`Co2Scaling::WellMixed`]), as `lidarsim profiles
/// generate --co2-ppm` and a scene's `co2_ppm` do by default.
pub fn set_co2_column_average(profile: &mut Profile, ppm: f64) -> Result<(), AtmosphereError> {
    profile.set_co2_ppm(ppm, Co2Scaling::WellMixed)
}

/// The perturbations the sensitivities are defined by (the contract of `sensitivities.csv`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Steps {
    /// True temperature higher than assumed at every level \[K\].
    pub temperature_k: f64,
    /// True on-line frequency higher than assumed \[MHz\].
    pub frequency_mhz: f64,
    /// Assumed surface pressure higher than the truth \[hPa\].
    pub surface_pressure_hpa: f64,
    /// True water vapour mixing ratio = assumed × this factor.
    pub h2o_factor: f64,
}

impl Steps {
    /// 1 K, 1 MHz, 1 hPa, 10 % water vapour.
    pub const CONTRACT: Steps = Steps {
        temperature_k: 1.0,
        frequency_mhz: 1.0,
        surface_pressure_hpa: 1.0,
        h2o_factor: 1.1,
    };
}

/// The layer grid of a study.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GridSpec {
    /// Layer thickness \[m\], > 0.
    pub layer_m: f64,
    /// Top of the grid \[m\] (clipped to the lowest top of the shifted profiles).
    pub top_m: f64,
}

/// Layer edges from `surface_m` in steps of `layer_m` up to `top_m`: a remainder thinner than
/// 1 % of a layer is merged into the last layer.
pub fn layer_edges(surface_m: f64, top_m: f64, layer_m: f64) -> Result<Vec<f64>, SelectError> {
    if !(layer_m.is_finite() && layer_m > 0.0) {
        return Err(invalid("--layer-m", layer_m, "must be positive"));
    }
    if !(top_m.is_finite() && top_m > surface_m + layer_m) {
        return Err(invalid(
            "--top-km",
            top_m / 1e3,
            format!(
                "the top must lie at least one layer ({layer_m} m) above the surface ({surface_m} m)"
            ),
        ));
    }
    let n = ((top_m - surface_m) / layer_m - 0.01).ceil().max(1.0) as usize;
    let mut edges: Vec<f64> = (0..n).map(|i| surface_m + i as f64 * layer_m).collect();
    edges.push(top_m);
    Ok(edges)
}

/// What the random error needs of the instrument (from a scene: [`NoiseModel::from_scene`]).
#[derive(Debug, Clone, PartialEq)]
pub struct NoiseModel {
    /// Pulse energies of the on- and the off-line \[J\].
    pub pulse_energy_j: [f64; 2],
    /// Telescope area \[m²\].
    pub telescope_area_m2: f64,
    /// Receiver optical efficiency times the filter's peak transmission.
    pub receiver_efficiency: f64,
    /// Lidar altitude \[m\] (nadir; the range is this minus the profile's surface altitude).
    pub lidar_altitude_m: f64,
    /// Lambertian surface albedo.
    pub albedo: f64,
    /// Vertical optical depth of the scene's particle layers (extinction), one way.
    pub particle_optical_depth: f64,
    /// The detector.
    pub detector: Detector,
    /// Background power at the detector \[W\] (first field of view).
    pub background_power_w: f64,
    /// Integration time of the surface echo \[s\] (the target's gates).
    pub window_s: f64,
    /// Shot-to-shot frequency jitter, rms \[MHz\].
    pub frequency_jitter_rms_mhz: f64,
    /// Relative rms error of the energy monitor.
    pub energy_monitor_error_fraction: f64,
    /// Shot pairs averaged into one measurement.
    pub averaging_shots: u64,
}

impl NoiseModel {
    /// The instrument of a scene: its lidar (altitude, telescope, efficiency, first field of
    /// view), laser (energies of the retrieval's on- and off-line, jitter, energy monitor),
    /// receiver (filter, detector, background), surface albedo (first channel), particle layers
    /// (extinction of the first channel) and retrieval (averaging, target window).
    /// Errors name what the scene lacks.
    pub fn from_scene(scene: &Scene) -> Result<NoiseModel, SelectError> {
        let lacks = |message: &str| SelectError::Scene {
            path: scene.path.display().to_string(),
            message: format!("{message}: the random error of select-lines needs it"),
        };
        let receiver = scene
            .receiver
            .as_ref()
            .ok_or_else(|| lacks("no [receiver]"))?;
        let retrieval = scene
            .retrieval
            .as_ref()
            .ok_or_else(|| lacks("no [retrieval] (averaging)"))?;
        let surface = scene
            .surface
            .as_ref()
            .ok_or_else(|| lacks("no [surface]"))?;
        let albedo = *surface
            .albedo
            .first()
            .ok_or_else(|| lacks("no surface albedo"))?;
        let fov = *scene
            .lidar
            .fov_full_angle_mrad
            .first()
            .ok_or_else(|| lacks("no field of view"))?;
        let on = scene
            .lines
            .get(retrieval.on)
            .ok_or_else(|| lacks("no on-line"))?;
        let energy = |i: usize| scene.laser.pulse_energy_j.get(i).copied();
        let (e_on, e_off) = match (energy(retrieval.on), energy(retrieval.off)) {
            (Some(a), Some(b)) => (a, b),
            _ => return Err(lacks("no pulse energy for the retrieval's lines")),
        };
        let area = scene.lidar.telescope_area_m2();
        let eta = scene.lidar.optical_efficiency;
        let filter = &receiver.filter;
        let background_power_w = if receiver.background_radiance_w_per_m2_sr_um > 0.0 {
            // Δλ [µm] = Δν / ν² · 1e4 with ν in cm⁻¹, as the instrument stage does.
            let dl_um = filter.bandwidth_cm1 / (on.wavenumber_cm1 * on.wavenumber_cm1) * 1e4;
            detector::background_power_w(
                receiver.background_radiance_w_per_m2_sr_um,
                dl_um,
                fov,
                area,
                eta,
                filter.transmission,
            )
        } else {
            0.0
        };
        let gates = retrieval
            .target
            .as_ref()
            .map_or(1, |t| t.gates.len().max(1));
        let window_s =
            2.0 * gates as f64 * scene.gates.width_m / crate::constants::SPEED_OF_LIGHT_M_PER_S;
        let particle_optical_depth = scene
            .layers
            .iter()
            .map(|l| l.extinction_per_m.first().copied().unwrap_or(0.0) * (l.top_m - l.base_m))
            .sum();
        Ok(NoiseModel {
            pulse_energy_j: [e_on, e_off],
            telescope_area_m2: area,
            receiver_efficiency: eta * filter.transmission,
            lidar_altitude_m: scene.lidar.altitude_m,
            albedo,
            particle_optical_depth,
            detector: receiver.detector.clone(),
            background_power_w,
            window_s,
            frequency_jitter_rms_mhz: scene.laser.frequency_jitter_rms_mhz,
            energy_monitor_error_fraction: scene.laser.energy_monitor_error_fraction,
            averaging_shots: retrieval.averaging_shots,
        })
    }

    /// SNR of one pulse's surface echo (hard-target lidar equation, docs/design.md §3:
    /// E = E₀ η A/R² (ρ/π) T², T² the two-way transmission) through the detector
    /// ([`Detector::gate`]).
    pub fn snr(
        &self,
        line: usize,
        wavenumber_cm1: f64,
        range_m: f64,
        two_way_transmission: f64,
    ) -> f64 {
        let e = self.pulse_energy_j[line] * self.receiver_efficiency * self.telescope_area_m2
            / (range_m * range_m)
            * self.albedo
            / std::f64::consts::PI
            * two_way_transmission;
        self.detector
            .gate(e, self.background_power_w, wavenumber_cm1, self.window_s)
            .snr()
    }
}

/// A fine spectrum of the two-way transmission around a line (Figure 4 of the reference study).
#[derive(Debug, Clone, PartialEq)]
pub struct SpectrumWindow {
    /// The line's label.
    pub label: String,
    /// Its centre [cm⁻¹].
    pub centre_cm1: f64,
    /// Offsets from the centre \[GHz\].
    pub offsets_ghz: Vec<f64>,
}

/// What a study computes for every profile (and, [`StudyConfig::spectra`], for every group).
#[derive(Debug, Clone)]
pub struct StudyConfig {
    /// Lines of every gas, reaching every position with their wings.
    pub lines: LineList,
    /// Line-by-line options.
    pub options: LblOptions,
    /// The off-line [cm⁻¹].
    pub off_cm1: f64,
    /// The on-line positions.
    pub positions: Vec<OnPosition>,
    /// The layer grid.
    pub grid: GridSpec,
    /// The perturbations.
    pub steps: Steps,
    /// The instrument, for the random error (None: NaN).
    pub noise: Option<NoiseModel>,
    /// Fine transmission spectra of each group's mean profile, for the figures (may be empty;
    /// [`transmission_spectra`]).
    pub spectra: Vec<SpectrumWindow>,
}

#[cfg(test)]
mod tests;
