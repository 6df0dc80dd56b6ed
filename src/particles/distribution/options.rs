//! What a bulk-optics computation is asked (the components and options), what it returns, and
//! the checks of its inputs: the types every other part of the computation shares.

use num_complex::Complex64;

use super::{SizeDistribution, param};
use crate::particles::matrix_table::MatrixTable;
use crate::particles::mie::{MieError, check_refractive_index};
use crate::particles::table::PhaseTable;

/// Least index contrast |m − 1| a size integration accepts: the cross-sections scale as |m − 1|²
/// (Rayleigh–Gans) and are rounding noise near |m − 1| = 10⁻¹⁵ (C.1-like drops at 532 nm: 25 %
/// off the |m − 1|² scaling there, none at 10⁻⁷); at m = 1 Cback is 0 and the lidar ratio has no
/// value. 10⁻⁶ keeps a wide margin and is below any particle in the atmosphere.
pub const MIN_INDEX_CONTRAST: f64 = 1e-6;

/// One component of an external mixture: a size distribution and its refractive index
/// (imaginary part ≥ 0 absorbing).
#[derive(Debug, Clone, PartialEq)]
pub struct Component {
    /// A short name for tables and reports (e.g. `waso`).
    pub name: String,
    /// Size distribution (number density in cm⁻³).
    pub distribution: SizeDistribution,
    /// Refractive index relative to the medium.
    pub refractive_index: Complex64,
}

/// Options of the size integration.
#[derive(Debug, Clone, PartialEq)]
pub struct BulkOptions {
    /// Fraction of each mode's geometric cross-section left outside the integration range
    /// (half below, half above). Default 1e-5.
    pub tail_fraction: f64,
    /// Relative change of the extinction, scattering, backscatter and g·scattering integrals
    /// below which two successive halvings of the size step count as converged. Default 1e-3.
    pub rel_tol: f64,
    /// Smallest size-parameter step tried. Default 1e-3.
    pub min_step_x: f64,
    /// Most grid points per mode. Default 2²⁰.
    pub max_points: usize,
    /// Scattering angles \[deg\] of the phase function (0 … 180, increasing); `None` chooses
    /// [`default_angle_grid`]. An empty vector skips the phase function.
    pub angles_deg: Option<Vec<f64>>,
}

impl Default for BulkOptions {
    fn default() -> Self {
        BulkOptions {
            tail_fraction: 1e-5,
            rel_tol: 1e-3,
            min_step_x: 1e-3,
            max_points: 1 << 20,
            angles_deg: None,
        }
    }
}

/// How one mode's integration ended.
#[derive(Debug, Clone, PartialEq)]
pub struct ModeConvergence {
    /// Component name.
    pub component: String,
    /// Radius range integrated \[µm\].
    pub r_range_um: (f64, f64),
    /// Smallest size-parameter step of the final grid (the panels' steps differ).
    pub step_x: f64,
    /// Number of radii on the final grid.
    pub points: usize,
    /// The final grid, panel by panel: (first size parameter, step, intervals); each panel is
    /// a trapezoid rule from its first point to the next panel's first (the last to the top of
    /// the range).
    pub panels: Vec<(f64, f64, usize)>,
    /// Largest relative change of the four integrals at the last halving.
    pub last_rel_change: f64,
    /// True when the tolerance was met (false: stopped at `min_step_x` or `max_points`).
    pub converged: bool,
}

/// Bulk optical properties of a size distribution (per particle, number-weighted).
#[derive(Debug, Clone, PartialEq)]
pub struct BulkOptics {
    /// Wavelength \[m\].
    pub wavelength_m: f64,
    /// Mean extinction cross-section per particle ⟨Cext⟩ \[m²\]: a layer's extinction
    /// coefficient [1/m] is its number density [1/m³] times this.
    pub extinction_cross_section_m2: f64,
    /// Mean scattering cross-section per particle ⟨Csca⟩ \[m²\].
    pub scattering_cross_section_m2: f64,
    /// Mean backscatter ("radar") cross-section ⟨Cback⟩ = 4π ⟨dCsca/dΩ(180°)⟩ \[m²\].
    pub backscatter_cross_section_m2: f64,
    /// ⟨Csca⟩/⟨Cext⟩.
    pub single_scattering_albedo: f64,
    /// Asymmetry parameter ⟨g Csca⟩/⟨Csca⟩.
    pub asymmetry: f64,
    /// Extinction-to-backscatter ratio 4π⟨Cext⟩/⟨Cback⟩ \[sr\].
    pub lidar_ratio_sr: f64,
    /// Number density of the distribution as given [1/m³].
    pub number_density_per_m3: f64,
    /// Effective radius ∫r³n/∫r²n over the integrated range \[µm\] (all components).
    pub effective_radius_um: f64,
    /// Phase function (normalised to 4π) with metadata; empty angles if none was asked for.
    pub phase: PhaseTable,
    /// The scattering matrix on the same angles with the same metadata, every element
    /// normalised like the phase function (its F11 column is `phase`, number for number); for
    /// spheres F22 = F11 and F44 = F33.
    pub matrix: MatrixTable,
    /// Per mode: range, step and convergence of the size integration.
    pub convergence: Vec<ModeConvergence>,
}

impl BulkOptics {
    /// Extinction coefficient [1/m] of a layer with `number_density_per_m3` particles.
    pub fn extinction_per_m(&self, number_density_per_m3: f64) -> f64 {
        number_density_per_m3 * self.extinction_cross_section_m2
    }

    /// Number density [1/m³] that gives the extinction coefficient `extinction_per_m` [1/m].
    pub fn number_density_for_extinction(&self, extinction_per_m: f64) -> f64 {
        extinction_per_m / self.extinction_cross_section_m2
    }

    /// Phase function at 180° (normalised to 4π), from the integrals: ⟨Cback⟩/⟨Csca⟩.
    pub fn phase_180(&self) -> f64 {
        self.backscatter_cross_section_m2 / self.scattering_cross_section_m2
    }
}

/// The default angle grid \[deg\] for a distribution whose largest effective size parameter is
/// `x_eff`: the 1391-angle grid of the reference files (0.01° to 1°, 0.05° to 5°, 0.1° to 20°,
/// 0.25° to 160°, 0.1° to 175°, 0.02° to 178°, 0.01° to 180°), with the forward step reduced
/// below 0.01° when the diffraction peak (width ≈ 1/x_eff rad) is narrower than 0.2°, so that it
/// is always resolved by at least 20 steps.
pub fn default_angle_grid(x_eff: f64) -> Vec<f64> {
    let peak_deg = (1.0 / x_eff.max(1e-3)).to_degrees();
    let fwd = (peak_deg / 20.0).min(0.01);
    let n_fwd = (1.0 / fwd).ceil() as usize;
    let mut v: Vec<f64> = (0..n_fwd).map(|i| i as f64 / n_fwd as f64).collect();
    let segments = [
        (1.0, 5.0, 80usize),
        (5.0, 20.0, 150),
        (20.0, 160.0, 560),
        (160.0, 175.0, 150),
        (175.0, 178.0, 150),
        (178.0, 180.0, 200),
    ];
    for (a, b, n) in segments {
        for i in 0..n {
            // Round to 1e-9 deg so the printed grid is clean.
            let t = a + (b - a) * i as f64 / n as f64;
            v.push((t * 1e9).round() / 1e9);
        }
    }
    v.push(180.0);
    v
}

/// The checks of [`bulk_optics_mixture`]'s inputs that need no Mie theory.
pub(super) fn check_inputs(
    components: &[Component],
    wavelength_m: f64,
    opts: &BulkOptions,
) -> Result<(), MieError> {
    if components.is_empty() {
        return Err(param("components", 0.0, "at least one component is needed"));
    }
    if !(wavelength_m.is_finite() && wavelength_m > 1e-8 && wavelength_m < 1e-3) {
        return Err(param(
            "wavelength_m",
            wavelength_m,
            "must lie in (10 nm, 1 mm)",
        ));
    }
    if !(opts.tail_fraction > 0.0 && opts.tail_fraction < 0.1) {
        return Err(param(
            "tail_fraction",
            opts.tail_fraction,
            "must lie in (0, 0.1)",
        ));
    }
    if !(opts.rel_tol > 0.0 && opts.rel_tol < 0.5) {
        return Err(param("rel_tol", opts.rel_tol, "must lie in (0, 0.5)"));
    }
    if !(opts.min_step_x > 0.0) {
        return Err(param("min_step_x", opts.min_step_x, "must be > 0"));
    }
    if opts.max_points < 257 {
        return Err(param("max_points", opts.max_points as f64, "must be ≥ 257"));
    }
    for c in components {
        check_refractive_index(c.refractive_index)?;
        let contrast = (c.refractive_index - 1.0).norm();
        if contrast < MIN_INDEX_CONTRAST {
            return Err(param(
                "|refractive_index − 1|",
                contrast,
                "must be ≥ 1e-6: particles with (nearly) the medium's index scatter \
                 (nearly) nothing, no phase function or lidar ratio follows, and their Mie sums \
                 are rounding noise",
            ));
        }
        if matches!(&c.distribution, SizeDistribution::Sum(v) if v.is_empty()) {
            return Err(param("modes", 0.0, "a sum needs at least one mode"));
        }
    }
    if let Some(a) = &opts.angles_deg {
        check_angles(a)?;
    }
    Ok(())
}

pub(super) fn check_angles(a: &[f64]) -> Result<(), MieError> {
    if a.is_empty() {
        return Ok(());
    }
    if a[0] != 0.0 || a[a.len() - 1] != 180.0 {
        return Err(param(
            "angles_deg",
            a[0],
            "must run from exactly 0 to exactly 180",
        ));
    }
    for w in a.windows(2) {
        if !(w[1] > w[0]) {
            return Err(param("angles_deg", w[1], "must strictly increase"));
        }
    }
    Ok(())
}

/// Progress of a size integration, as [`super::bulk_optics_mixture_with_progress`] reports
/// it (after every batch of radii, at most a few thousand radii apart).
#[derive(Debug, Clone, PartialEq)]
pub struct MieProgress {
    /// The integration (mode) under way, from 1.
    pub integration: usize,
    /// Integrations in all (modes of all components).
    pub integrations: usize,
    /// The component whose mode is integrated.
    pub component: String,
    /// Radii evaluated so far, all integrations.
    pub radii: u64,
    /// Most radii the integrations can take ([`super::MieWork::radii`]): the refinement
    /// usually stops well before, so this bounds the remaining work rather than predicting it.
    pub radii_bound: u64,
}

/// When [`progress_lines`] first prints \[s\] (f64 bits; infinite: never).
static PROGRESS_AFTER_S: std::sync::atomic::AtomicU64 =
    std::sync::atomic::AtomicU64::new(2.0f64.to_bits());

/// When the progress lines of [`progress_lines`] start, for the whole process: after `after_s`
/// seconds of a computation (2 s unless set), or never (`None`). The command line's `--quiet`
/// turns them off, so that a scene's first Mie computation, reported from inside the library
/// while the scene is resolved, is silent too; `LIDARSIM_PROGRESS_AFTER_S` moves the start as
/// it does for the command line's own progress. Errors and warnings are not progress and
/// still print.
pub fn set_progress_lines(after_s: Option<f64>) {
    let s = after_s.filter(|s| *s >= 0.0).unwrap_or(f64::INFINITY);
    PROGRESS_AFTER_S.store(s.to_bits(), std::sync::atomic::Ordering::Relaxed);
}

/// A progress report for [`super::bulk_optics_mixture_with_progress`] as plain lines on standard
/// error, `{what}: COMPONENT (size integration I of N): R radii, at most B, T s`, every 2 s once
/// the computation has run for 2 s (nothing for a shorter one; [`set_progress_lines`] moves
/// that or turns the lines off): what a batch job's log or a terminal shows until a command has
/// a progress display of its own.
pub fn progress_lines(what: String) -> impl Fn(&MieProgress) {
    let started = std::time::Instant::now();
    let next = std::cell::Cell::new(f64::from_bits(
        PROGRESS_AFTER_S.load(std::sync::atomic::Ordering::Relaxed),
    ));
    move |p: &MieProgress| {
        let t = started.elapsed().as_secs_f64();
        if t >= next.get() {
            next.set(t + 2.0);
            eprintln!(
                "{what}: {} (size integration {} of {}): {} radii, at most {}, {:.0} s",
                p.component, p.integration, p.integrations, p.radii, p.radii_bound, t
            );
        }
    }
}
