//! Line selection for a CO2 IPDA (`lidarsim select-lines`): for candidate on-line positions
//! next to one off-line, the systematic XCO2 errors a nadir IPDA makes when the atmospheric
//! state or the laser frequency it assumes is wrong, its random error, and a ranking.
//!
//! # What is computed
//!
//! For every profile (a built-in AFGL atmosphere or a member of a profile set), with its CO2
//! set to a dry-air column average ([`set_co2_column_average`]), and every on-line position ν_on
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
//! * with a [`NoiseModel`], the random error of an averaged measurement (DESIGN §3),
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

use rayon::prelude::*;

use crate::atmosphere::hydrostatic::HydrostaticProfile;
use crate::atmosphere::{
    AtmosphereError, LatitudeClass, Profile, SetMember, StateShift, shift_member,
};
use crate::instrument::detector::{self, Detector};
use crate::instrument::laser::{Filter, Laser, Line};
use crate::instrument::line_shape::MHZ_PER_CM1;
use crate::retrieval::{AssumedInstrument, ReferenceState, RetrievalError};
use crate::scene::Scene;
use crate::spectroscopy::{LblOptions, LineList, SpectroscopyError, layer_optical_depths_at};

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
    /// Label as the seed paper writes it: branch, J″ and symmetry, e.g. `R16e`.
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

/// Give `profile` a CO2 dry-air column average of `ppm`: rescale its CO2 by one factor
/// ([`Profile::rescale_gas`]) if it has CO2, else set CO2 to `ppm` of dry air at every level
/// (moist-air mole fraction ppm·10⁻⁶·(1 − x_H2O)), as `lidarsim profiles generate --co2-ppm`
/// does.
pub fn set_co2_column_average(profile: &mut Profile, ppm: f64) -> Result<(), AtmosphereError> {
    if !(ppm.is_finite() && ppm > 0.0 && ppm < 1e6) {
        return Err(AtmosphereError::InvalidArgument(format!(
            "CO2 column average {ppm} ppm must be positive and below 1e6"
        )));
    }
    if profile.gas("CO2").is_some() {
        profile.rescale_gas("CO2", ppm * 1e-6)?;
    } else {
        let h2o = profile.gas("H2O").map(|v| v.to_vec());
        let v = (0..profile.len())
            .map(|k| ppm * 1e-6 * (1.0 - h2o.as_ref().map_or(0.0, |h| h[k])))
            .collect();
        profile.set_gas("CO2", v)?;
    }
    Ok(())
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

    /// SNR of one pulse's surface echo (hard-target lidar equation, DESIGN §3:
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

/// A fine spectrum of the two-way transmission around a line (Figure 4 of the seed paper).
#[derive(Debug, Clone, PartialEq)]
pub struct SpectrumWindow {
    /// The line's label.
    pub label: String,
    /// Its centre [cm⁻¹].
    pub centre_cm1: f64,
    /// Offsets from the centre \[GHz\].
    pub offsets_ghz: Vec<f64>,
}

/// What a study computes for every profile.
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
    /// Fine transmission spectra to compute (may be empty).
    pub spectra: Vec<SpectrumWindow>,
}

/// The results of one on-line position for one profile.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PositionResult {
    /// One-way differential absorption optical depth, all gases, top to surface.
    pub daod_one_way: f64,
    /// Peak of the weighting function per unit pressure \[hPa\].
    pub wf_peak_hpa: f64,
    /// XCO2 error for a true temperature 1 K higher \[ppm\].
    pub dxco2_per_k_ppm: f64,
    /// XCO2 error for a true on-line frequency 1 MHz higher \[ppm\].
    pub dxco2_per_mhz_ppm: f64,
    /// XCO2 error for an assumed surface pressure 1 hPa higher \[ppm\].
    pub dxco2_per_hpa_ppm: f64,
    /// XCO2 error for a true humidity 10 % higher \[ppm\].
    pub dxco2_per_10pct_h2o_ppm: f64,
    /// Two-way gas transmission of the on-line, top to surface.
    pub t2_on: f64,
    /// Random error of one averaged measurement \[ppm\] (NaN without a noise model).
    pub random_error_ppm: f64,
}

/// The results for one profile.
#[derive(Debug, Clone, PartialEq)]
pub struct MemberResult {
    /// Profile id.
    pub id: String,
    /// Its latitude class.
    pub class: LatitudeClass,
    /// The layer edges used \[m\] (surface to top).
    pub edges_m: Vec<f64>,
    /// XCO2 of the unperturbed (shifted by nothing) profile over the grid \[ppm\].
    pub xco2_ppm: f64,
    /// One result per [`StudyConfig::positions`].
    pub positions: Vec<PositionResult>,
    /// Two-way gas transmission per [`StudyConfig::spectra`] window and offset.
    pub spectra: Vec<Vec<f64>>,
}

/// A profile that could not be studied, and why.
#[derive(Debug, Clone, PartialEq)]
pub struct MemberFailure {
    /// Profile id.
    pub id: String,
    /// The reason.
    pub reason: String,
}

/// The four shifted profiles of a member: none, temperature, water vapour, surface pressure.
fn shifted(member: &SetMember, steps: &Steps) -> Result<[Profile; 4], SelectError> {
    let none = shift_member(member, &StateShift::NONE)?;
    let t = shift_member(
        member,
        &StateShift {
            temperature_k: steps.temperature_k,
            ..StateShift::NONE
        },
    )?;
    // A profile without water vapour has none to change: the truth is the unshifted one.
    let q = if member.profile.gas("H2O").is_some() {
        shift_member(
            member,
            &StateShift {
                h2o_factor: steps.h2o_factor,
                ..StateShift::NONE
            },
        )?
    } else {
        none.clone()
    };
    let p = shift_member(
        member,
        &StateShift {
            surface_pressure_hpa: steps.surface_pressure_hpa,
            ..StateShift::NONE
        },
    )?;
    Ok([none.profile, t.profile, q.profile, p.profile])
}

/// The IPDA weighting function per unit pressure of one on/off pair on the layers of a
/// reference state (module docs): WF_l = Δτ_CO2,l/(x_l Δp_l).
#[derive(Debug, Clone, PartialEq)]
pub struct WeightingFunction {
    /// Centre of each layer, the mean of ln p \[Pa\] at its edges.
    pub ln_p_centre: Vec<f64>,
    /// Pressure thickness of each layer \[hPa\].
    pub dp_hpa: Vec<f64>,
    /// WF_l \[1/hPa\].
    pub per_hpa: Vec<f64>,
}

impl WeightingFunction {
    /// Pressure \[hPa\] where it peaks ([`peak_pressure_hpa`]'s parabola in ln p).
    pub fn peak_hpa(&self) -> f64 {
        peak_pressure_hpa(&self.ln_p_centre, &self.per_hpa)
    }
}

/// The weighting function of lines `on` and `off` (their first quadrature node: a
/// monochromatic laser) of `state`, computed on `profile` (the state's profile). The pressure
/// thickness Δp_l comes from the same hydrostatic integration as the state's columns
/// ([`HydrostaticProfile`]), so that x_l Δp_l is the layer's CO2 column times m g: within a
/// level interval the column per unit pressure is then constant up to humidity, and WF_l is
/// Δσ_l U_dry,l/Δp_l = Δσ_l (1 − x_w)/(m g) as the hydrostatic equation has it. (With Δp from
/// ln p linear in z it varied by ΔT/T across each interval, ±1 % in the tropics, and that
/// sawtooth set the peak where the weighting function is flat.)
pub fn weighting_function(
    profile: &Profile,
    state: &ReferenceState,
    on: usize,
    off: usize,
) -> WeightingFunction {
    let edges = &state.columns.edges_m;
    let hydro = HydrostaticProfile::new(profile);
    let p: Vec<f64> = edges.iter().map(|z| hydro.pressure_pa(*z)).collect();
    let n = edges.len().saturating_sub(1);
    let mut wf = WeightingFunction {
        ln_p_centre: Vec::with_capacity(n),
        dp_hpa: Vec::with_capacity(n),
        per_hpa: Vec::with_capacity(n),
    };
    for l in 0..n {
        let dp = (p[l] - p[l + 1]) / 100.0;
        let x = state.columns.gas_per_m2[l] / state.columns.dry_air_per_m2[l];
        let dt = state.target_tau[l][on][0] - state.target_tau[l][off][0];
        wf.ln_p_centre.push(0.5 * (p[l].ln() + p[l + 1].ln()));
        wf.dp_hpa.push(dp);
        wf.per_hpa.push(dt / (x * dp));
    }
    wf
}

/// Pressure \[hPa\] where `wf` (per layer, centres at ln p `x`) peaks: the largest layer,
/// refined by a parabola through it and its neighbours when it has two.
fn peak_pressure_hpa(x: &[f64], wf: &[f64]) -> f64 {
    let Some((k, _)) = wf
        .iter()
        .enumerate()
        .filter(|(_, v)| v.is_finite())
        .max_by(|a, b| a.1.total_cmp(b.1))
    else {
        return f64::NAN;
    };
    let mut ln_p = x[k];
    if k > 0 && k + 1 < wf.len() {
        let (x0, x1, x2) = (x[k - 1], x[k], x[k + 1]);
        let (y0, y1, y2) = (wf[k - 1], wf[k], wf[k + 1]);
        let num = (x1 - x0).powi(2) * (y1 - y2) - (x1 - x2).powi(2) * (y1 - y0);
        let den = (x1 - x0) * (y1 - y2) - (x1 - x2) * (y1 - y0);
        if den != 0.0 {
            let v = x1 - 0.5 * num / den;
            ln_p = v.clamp(x0.min(x2), x0.max(x2));
        }
    }
    ln_p.exp() / 100.0
}

/// Study one profile (module docs). The member's CO2 is used as it is: set it first with
/// [`set_co2_column_average`].
pub fn study_member(member: &SetMember, cfg: &StudyConfig) -> Result<MemberResult, SelectError> {
    let n = cfg.positions.len();
    if n == 0 {
        return Err(invalid(
            "--on-cm1",
            "(none)",
            "no on-line position to study",
        ));
    }
    let profiles = shifted(member, &cfg.steps)?;
    let surface_m = profiles[0].altitude_m[0];
    let top_m = profiles
        .iter()
        .map(|p| p.altitude_m[p.len() - 1])
        .fold(cfg.grid.top_m, f64::min);
    let edges = layer_edges(surface_m, top_m, cfg.grid.layer_m)?;
    let z_top = edges[edges.len() - 1];

    // Lines: on positions, off, on + δν, off + δν (the last two only for the unshifted state).
    let dnu = cfg.steps.frequency_mhz / MHZ_PER_CM1;
    let named = |name: String, nu: f64| Line {
        name,
        wavenumber_cm1: nu,
    };
    let mut base: Vec<Line> = cfg
        .positions
        .iter()
        .enumerate()
        .map(|(i, p)| named(format!("on{i}"), p.nu_cm1))
        .collect();
    base.push(named("off".into(), cfg.off_cm1));
    let mut all = base.clone();
    all.extend(
        cfg.positions
            .iter()
            .enumerate()
            .map(|(i, p)| named(format!("on{i}+"), p.nu_cm1 + dnu)),
    );
    all.push(named("off+".into(), cfg.off_cm1 + dnu));
    let off = n;
    let state = |profile: &Profile, lines: &[Line]| -> Result<ReferenceState, SelectError> {
        Ok(ReferenceState::new(
            profile,
            &edges,
            "CO2",
            &cfg.lines,
            &cfg.options,
            AssumedInstrument {
                laser: &Laser::ideal(1.0, lines.len()),
                lines,
                filter: &Filter::none(),
            },
        )?)
    };
    let s0 = state(&profiles[0], &all)?;
    let s_t = state(&profiles[1], &base)?;
    let s_q = if member.profile.gas("H2O").is_some() {
        Some(state(&profiles[2], &base)?)
    } else {
        None
    };
    let s_p = state(&profiles[3], &base)?;
    let s_q = s_q.as_ref().unwrap_or(&s0);

    let path = |s: &ReferenceState| s.path(z_top, surface_m, -1.0);
    let xco2 = |s: &ReferenceState| {
        let (g, d) = s.columns.between(z_top, surface_m);
        g / d
    };
    let (p0, p_t, p_q, p_p) = (path(&s0), path(&s_t), path(s_q), path(&s_p));
    let (x0, x_t, x_q, x_p) = (xco2(&s0), xco2(&s_t), xco2(s_q), xco2(&s_p));
    let tau = |p: &crate::retrieval::PathDepths, line: usize| {
        p.target_scaled[line][0] + p.target_fixed[line][0] + p.other[line][0]
    };
    // The error of a retrieval whose reference is (state, path, X) given the true DAOD.
    let error_ppm =
        |s: &ReferenceState,
         p: &crate::retrieval::PathDepths,
         x_assumed: f64,
         on: usize,
         d_true: f64,
         x_true: f64| { (s.solve_scale(p, on, off, d_true) * x_assumed - x_true) * 1e6 };

    // Rayleigh optical depth of the air column over the grid (Bucholtz 1995).
    let rayleigh_tau = match &cfg.noise {
        Some(_) => {
            let wavelength_nm = 1e7 / cfg.off_cm1;
            let sigma = crate::particles::rayleigh::cross_section_m2(wavelength_nm)
                .map_err(|e| invalid("--off-cm1", cfg.off_cm1, e.to_string()))?;
            let air: f64 = crate::spectroscopy::layers::curtis_godson_layers(&profiles[0], &edges)?
                .iter()
                .map(|l| l.air_column_per_cm2 * 1e4)
                .sum();
            sigma * air
        }
        None => 0.0,
    };
    let tau_off = tau(&p0, off);
    let slope_off = tau(&p0, 2 * n + 1) - tau_off;

    let mut positions = Vec::with_capacity(n);
    for (i, pos) in cfg.positions.iter().enumerate() {
        let d0 = tau(&p0, i) - tau_off;
        // Weighting function per unit pressure of the unshifted profile.
        let wf = weighting_function(&profiles[0], &s0, i, off);
        let d_of = |s: &ReferenceState, p: &crate::retrieval::PathDepths| s.daod(p, i, off, 1.0).0;
        let d_f = s0.daod(&p0, n + 1 + i, off, 1.0).0;
        let t2_on = (-2.0 * tau(&p0, i)).exp();
        let random_error_ppm = match &cfg.noise {
            Some(m) => {
                let range = m.lidar_altitude_m - surface_m;
                let extra = 2.0 * (rayleigh_tau + m.particle_optical_depth);
                let t2 = |t: f64| (-2.0 * t - extra).exp();
                let snr_on = m.snr(0, pos.nu_cm1, range, t2(tau(&p0, i)));
                let snr_off = m.snr(1, cfg.off_cm1, range, t2(tau_off));
                // ∂ln E/∂ν = −2 ∂τ/∂ν per MHz, from the lines shifted by the step.
                let per_mhz = 1.0 / cfg.steps.frequency_mhz;
                let slope_on = -2.0 * (tau(&p0, n + 1 + i) - tau(&p0, i)) * per_mhz;
                let slope_off = -2.0 * slope_off * per_mhz;
                let inv2 = |snr: f64| {
                    if snr > 0.0 {
                        1.0 / (snr * snr)
                    } else {
                        f64::INFINITY
                    }
                };
                let sj = m.frequency_jitter_rms_mhz;
                let var = inv2(snr_on)
                    + inv2(snr_off)
                    + 2.0 * m.energy_monitor_error_fraction.powi(2)
                    + (sj * slope_on).powi(2)
                    + (sj * slope_off).powi(2);
                x0 * 1e6 * var.sqrt() / (2.0 * d0 * (m.averaging_shots as f64).sqrt())
            }
            None => f64::NAN,
        };
        positions.push(PositionResult {
            daod_one_way: d0,
            wf_peak_hpa: wf.peak_hpa(),
            dxco2_per_k_ppm: error_ppm(&s0, &p0, x0, i, d_of(&s_t, &p_t), x_t),
            dxco2_per_mhz_ppm: error_ppm(&s0, &p0, x0, i, d_f, x0),
            dxco2_per_hpa_ppm: error_ppm(&s_p, &p_p, x_p, i, d_of(&s0, &p0), x0),
            dxco2_per_10pct_h2o_ppm: error_ppm(&s0, &p0, x0, i, d_of(s_q, &p_q), x_q),
            t2_on,
            random_error_ppm,
        });
    }

    // Fine spectra of the unshifted profile: two-way transmission, top to surface.
    let mut spectra = Vec::with_capacity(cfg.spectra.len());
    for w in &cfg.spectra {
        let nus: Vec<f64> = w
            .offsets_ghz
            .iter()
            .map(|o| w.centre_cm1 + o / GHZ_PER_CM1)
            .collect();
        let t = layer_optical_depths_at(&profiles[0], &cfg.lines, &edges, &nus, &cfg.options)?;
        spectra.push(
            (0..nus.len())
                .map(|k| (-2.0 * t.iter().map(|row| row[k]).sum::<f64>()).exp())
                .collect(),
        );
    }
    Ok(MemberResult {
        id: member.meta.id.clone(),
        class: member.meta.class(),
        edges_m: edges,
        xco2_ppm: x0 * 1e6,
        positions,
        spectra,
    })
}

/// Study every member with its CO2 set to a dry-air column average of `co2_ppm` first
/// ([`set_co2_column_average`]), in parallel (rayon) and in member order; the numbers do not
/// depend on the thread count (each member is computed alone). `progress` is called once per
/// member.
pub fn study_members(
    members: &[&SetMember],
    cfg: &StudyConfig,
    co2_ppm: f64,
    progress: &(dyn Fn() + Sync),
) -> Vec<Result<MemberResult, MemberFailure>> {
    members
        .par_iter()
        .map(|m| {
            let mut m = (*m).clone();
            let r = set_co2_column_average(&mut m.profile, co2_ppm)
                .map_err(SelectError::from)
                .and_then(|()| study_member(&m, cfg))
                .map_err(|e| MemberFailure {
                    id: m.meta.id.clone(),
                    reason: e.to_string(),
                });
            progress();
            r
        })
        .collect()
}

/// The uncertainties of the assumed state and laser frequency that make the total error.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Uncertainties {
    /// Temperature \[K\] (default 1: a good NWP analysis).
    pub temperature_k: f64,
    /// Laser frequency \[MHz\] (default 1).
    pub frequency_mhz: f64,
    /// Surface pressure \[hPa\] (default 1).
    pub surface_pressure_hpa: f64,
    /// Water vapour \[%\] (default 10).
    pub h2o_percent: f64,
}

impl Default for Uncertainties {
    fn default() -> Self {
        Uncertainties {
            temperature_k: 1.0,
            frequency_mhz: 1.0,
            surface_pressure_hpa: 1.0,
            h2o_percent: 10.0,
        }
    }
}

impl Uncertainties {
    /// The systematic contributions \[ppm\]: each sensitivity times its uncertainty in units of
    /// the sensitivity's step (linear in the step): T, frequency, surface pressure, H2O.
    pub fn contributions_ppm(&self, r: &Row) -> [f64; 4] {
        [
            r.dxco2_per_k_ppm * self.temperature_k,
            r.dxco2_per_mhz_ppm * self.frequency_mhz,
            r.dxco2_per_hpa_ppm * self.surface_pressure_hpa,
            r.dxco2_per_10pct_h2o_ppm * self.h2o_percent / 10.0,
        ]
    }

    /// Total expected error \[ppm\]: the root-sum-square of the random error (left out when
    /// NaN, i.e. without a noise model) and the four contributions.
    pub fn total_ppm(&self, r: &Row) -> f64 {
        let sys: f64 = self.contributions_ppm(r).iter().map(|c| c * c).sum();
        let rand = if r.random_error_ppm.is_nan() {
            0.0
        } else {
            r.random_error_ppm.powi(2)
        };
        (sys + rand).sqrt()
    }
}

/// One row of `sensitivities.csv`.
#[derive(Debug, Clone, PartialEq)]
pub struct Row {
    /// Atmosphere, latitude class or profile id.
    pub atmosphere: String,
    /// The on-line position.
    pub position: OnPosition,
    /// The off-line [cm⁻¹].
    pub off_cm1: f64,
    /// Mean one-way DAOD.
    pub daod_one_way: f64,
    /// Mean weighting-function peak \[hPa\].
    pub wf_peak_hpa: f64,
    /// Mean sensitivity to +1 K \[ppm\].
    pub dxco2_per_k_ppm: f64,
    /// Mean sensitivity to +1 MHz \[ppm\].
    pub dxco2_per_mhz_ppm: f64,
    /// Mean sensitivity to an assumed surface pressure +1 hPa \[ppm\].
    pub dxco2_per_hpa_ppm: f64,
    /// Mean sensitivity to +10 % H2O \[ppm\].
    pub dxco2_per_10pct_h2o_ppm: f64,
    /// Mean two-way transmission of the on-line.
    pub t2_on_mean: f64,
    /// Its standard deviation over the members (n − 1; 0 for one member).
    pub t2_on_std: f64,
    /// Mean random error \[ppm\].
    pub random_error_ppm: f64,
    /// Total expected error \[ppm\] ([`Uncertainties::total_ppm`]).
    pub total_error_ppm: f64,
    /// Rank within the atmosphere by total error (1 = smallest).
    pub rank: usize,
    /// Members averaged.
    pub profiles: usize,
}

/// Header of `sensitivities.csv` (the first nine columns are the contract).
pub const CSV_HEADER: &str = "atmosphere,nu_on_cm1,nu_off_cm1,daod_one_way,wf_peak_hpa,dxco2_per_k_ppm,dxco2_per_mhz_ppm,dxco2_per_hpa_ppm,dxco2_per_10pct_h2o_ppm,line,offset_ghz,t2_on_mean,t2_on_std,random_error_ppm,total_error_ppm,rank,profiles";

fn mean_std(v: &[f64]) -> (f64, f64) {
    let n = v.len() as f64;
    let m = v.iter().sum::<f64>() / n;
    let s = if v.len() > 1 {
        (v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (n - 1.0)).sqrt()
    } else {
        0.0
    };
    (m, s)
}

/// Rows of one group of member results (at least one): the mean over members of every quantity
/// per position, positions where the on-line does not absorb more than the off-line (or a
/// sensitivity is not finite) in any member dropped, ranked by total error. Returns the rows in
/// rank order and the indices of the dropped positions.
pub fn summarise(
    atmosphere: &str,
    results: &[&MemberResult],
    cfg: &StudyConfig,
    unc: &Uncertainties,
) -> (Vec<Row>, Vec<usize>) {
    let mut rows = Vec::new();
    let mut dropped = Vec::new();
    if results.is_empty() {
        return (rows, (0..cfg.positions.len()).collect());
    }
    for (i, pos) in cfg.positions.iter().enumerate() {
        let r: Vec<&PositionResult> = results.iter().map(|m| &m.positions[i]).collect();
        let usable = r.iter().all(|p| {
            p.daod_one_way > 0.0
                && [
                    p.dxco2_per_k_ppm,
                    p.dxco2_per_mhz_ppm,
                    p.dxco2_per_hpa_ppm,
                    p.dxco2_per_10pct_h2o_ppm,
                ]
                .iter()
                .all(|v| v.is_finite())
        });
        if !usable {
            dropped.push(i);
            continue;
        }
        let mean =
            |f: fn(&PositionResult) -> f64| mean_std(&r.iter().map(|p| f(p)).collect::<Vec<_>>()).0;
        let (t2_mean, t2_std) = mean_std(&r.iter().map(|p| p.t2_on).collect::<Vec<_>>());
        let mut row = Row {
            atmosphere: atmosphere.to_string(),
            position: pos.clone(),
            off_cm1: cfg.off_cm1,
            daod_one_way: mean(|p| p.daod_one_way),
            wf_peak_hpa: mean(|p| p.wf_peak_hpa),
            dxco2_per_k_ppm: mean(|p| p.dxco2_per_k_ppm),
            dxco2_per_mhz_ppm: mean(|p| p.dxco2_per_mhz_ppm),
            dxco2_per_hpa_ppm: mean(|p| p.dxco2_per_hpa_ppm),
            dxco2_per_10pct_h2o_ppm: mean(|p| p.dxco2_per_10pct_h2o_ppm),
            t2_on_mean: t2_mean,
            t2_on_std: t2_std,
            random_error_ppm: mean(|p| p.random_error_ppm),
            total_error_ppm: f64::NAN,
            rank: 0,
            profiles: results.len(),
        };
        row.total_error_ppm = unc.total_ppm(&row);
        rows.push(row);
    }
    // Stable sort: equal totals keep the position order.
    rows.sort_by(|a, b| a.total_error_ppm.total_cmp(&b.total_error_ppm));
    for (k, r) in rows.iter_mut().enumerate() {
        r.rank = k + 1;
    }
    (rows, dropped)
}

/// The CSV text (header and rows, in the order given).
pub fn to_csv(rows: &[Row]) -> String {
    use std::fmt::Write as _;
    let mut s = String::from(CSV_HEADER);
    s.push('\n');
    for r in rows {
        let _ = writeln!(
            s,
            "{},{:.6},{:.6},{:.6e},{:.2},{:.6e},{:.6e},{:.6e},{:.6e},{},{},{:.6e},{:.6e},{:.6e},{:.6e},{},{}",
            crate::output::csv_field(&r.atmosphere),
            r.position.nu_cm1,
            r.off_cm1,
            r.daod_one_way,
            r.wf_peak_hpa,
            r.dxco2_per_k_ppm,
            r.dxco2_per_mhz_ppm,
            r.dxco2_per_hpa_ppm,
            r.dxco2_per_10pct_h2o_ppm,
            crate::output::csv_field(r.position.line.as_deref().unwrap_or("")),
            if r.position.offset_ghz.is_nan() {
                String::new()
            } else {
                format!("{:.4}", r.position.offset_ghz)
            },
            r.t2_on_mean,
            r.t2_on_std,
            r.random_error_ppm,
            r.total_error_ppm,
            r.rank,
            r.profiles
        );
    }
    s
}

/// The rows as a CF NetCDF file (`sensitivities.nc`), the columns of `sensitivities.csv` at
/// full precision over the dimension `row` ([`crate::netcdf::table_file`]).
pub fn to_netcdf(
    rows: &[Row],
    title: &str,
    history: &str,
) -> Result<Vec<u8>, crate::netcdf::NetcdfError> {
    use crate::netcdf::{Column, ColumnValues::Number, ColumnValues::Text, table_file};
    let num = |name, long_name, units, f: fn(&Row) -> f64| Column {
        name,
        long_name,
        units: Some(units),
        values: Number(rows.iter().map(f).collect()),
    };
    // UDUNITS: ppm as "1e-6" (CF-1.8 §3.1).
    let columns = [
        Column {
            name: "atmosphere",
            long_name: "atmosphere, latitude class or profile id",
            units: None,
            values: Text(rows.iter().map(|r| r.atmosphere.clone()).collect()),
        },
        num("nu_on_cm1", "on-line vacuum wavenumber", "cm-1", |r| {
            r.position.nu_cm1
        }),
        num("nu_off_cm1", "off-line vacuum wavenumber", "cm-1", |r| {
            r.off_cm1
        }),
        num(
            "daod_one_way",
            "one-way differential absorption optical depth, on - off",
            "1",
            |r| r.daod_one_way,
        ),
        num(
            "wf_peak_hpa",
            "pressure of the peak of the weighting function per unit pressure",
            "hPa",
            |r| r.wf_peak_hpa,
        ),
        num(
            "dxco2_per_k_ppm",
            "XCO2 error for a true temperature 1 K above the assumed",
            "1e-6",
            |r| r.dxco2_per_k_ppm,
        ),
        num(
            "dxco2_per_mhz_ppm",
            "XCO2 error for a true on-line frequency 1 MHz above the assumed",
            "1e-6",
            |r| r.dxco2_per_mhz_ppm,
        ),
        num(
            "dxco2_per_hpa_ppm",
            "XCO2 error for an assumed surface pressure 1 hPa above the truth",
            "1e-6",
            |r| r.dxco2_per_hpa_ppm,
        ),
        num(
            "dxco2_per_10pct_h2o_ppm",
            "XCO2 error for a true humidity 10 % above the assumed",
            "1e-6",
            |r| r.dxco2_per_10pct_h2o_ppm,
        ),
        Column {
            name: "line",
            long_name: "CO2 30012<-00001 line the on-line sits on",
            units: None,
            values: Text(
                rows.iter()
                    .map(|r| r.position.line.clone().unwrap_or_default())
                    .collect(),
            ),
        },
        num(
            "offset_ghz",
            "on-line offset from the line centre",
            "GHz",
            |r| r.position.offset_ghz,
        ),
        num(
            "t2_on_mean",
            "two-way gas transmission of the on-line, mean over the profiles",
            "1",
            |r| r.t2_on_mean,
        ),
        num(
            "t2_on_std",
            "two-way gas transmission of the on-line, standard deviation over the profiles",
            "1",
            |r| r.t2_on_std,
        ),
        num(
            "random_error_ppm",
            "random error of one averaged measurement",
            "1e-6",
            |r| r.random_error_ppm,
        ),
        num(
            "total_error_ppm",
            "root-sum-square of the random error and each sensitivity times its uncertainty",
            "1e-6",
            |r| r.total_error_ppm,
        ),
        num(
            "rank",
            "rank within the atmosphere by total error (1 = smallest)",
            "1",
            |r| r.rank as f64,
        ),
        num("profiles", "profiles averaged", "1", |r| r.profiles as f64),
    ];
    table_file("row", &columns, title, history)
}

/// Mean and standard deviation over members of each fine spectrum ([`StudyConfig::spectra`]):
/// per window, (mean, std) per offset.
pub fn spectrum_statistics(results: &[&MemberResult], windows: usize) -> Vec<(Vec<f64>, Vec<f64>)> {
    (0..windows)
        .map(|w| {
            let len = results.first().map_or(0, |r| r.spectra[w].len());
            (0..len)
                .map(|k| mean_std(&results.iter().map(|r| r.spectra[w][k]).collect::<Vec<_>>()))
                .unzip()
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn band_model_lines_are_found_and_labelled() {
        let band = band_lines(&LineList::co2_30012_band_model());
        assert_eq!(band.len(), 60);
        let r16 = band.iter().find(|b| b.label == "R16e").unwrap();
        assert_eq!(r16.j_lower, 16);
        assert!((r16.nu_cm1 - 6359.967).abs() < 0.002);
        let pos = scan_positions(&band, 40, &[-1.0, 0.0, 2.0]);
        // P2..P40 (20) and R0..R40 (21), three offsets each.
        assert_eq!(pos.len(), 41 * 3);
        let lab = label_positions(&band, &[r16.nu_cm1 + 2.0 / GHZ_PER_CM1, 6000.0]);
        assert_eq!(lab[0].line.as_deref(), Some("R16e"));
        assert!((lab[0].offset_ghz - 2.0).abs() < 1e-9);
        assert!(lab[1].line.is_none() && lab[1].offset_ghz.is_nan());
    }

    #[test]
    fn edges_reach_the_top_and_reject_bad_input() {
        let e = layer_edges(100.0, 1100.0, 250.0).unwrap();
        assert_eq!(e, vec![100.0, 350.0, 600.0, 850.0, 1100.0]);
        let e = layer_edges(0.0, 1001.0, 250.0).unwrap();
        assert_eq!(e.last(), Some(&1001.0));
        assert_eq!(e.len(), 5);
        assert!(layer_edges(0.0, 100.0, 250.0).is_err());
        assert!(layer_edges(0.0, 1000.0, 0.0).is_err());
    }

    #[test]
    fn parabola_finds_the_vertex() {
        // y = −(x − 0.3)² sampled at −1, 0, 1, 2: the vertex 0.3 exactly.
        let x = [-1.0, 0.0, 1.0, 2.0];
        let y: Vec<f64> = x.iter().map(|v: &f64| -(v - 0.3).powi(2)).collect();
        assert!((peak_pressure_hpa(&x, &y) - 0.3f64.exp() / 100.0).abs() < 1e-15);
    }

    #[test]
    fn co2_is_set_where_absent() {
        let mut p = crate::atmosphere::StandardAtmosphere::Tropical.profile();
        p.gases.retain(|g| g.name != "CO2");
        set_co2_column_average(&mut p, 400.0).unwrap();
        let x = p.column_average_dry_vmr("CO2").unwrap();
        assert!((x / 400e-6 - 1.0).abs() < 1e-9, "{x}");
        assert!(set_co2_column_average(&mut p, -1.0).is_err());
    }
}
