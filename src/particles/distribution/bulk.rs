//! Bulk optics of a distribution or an external mixture: the options, the result and the
//! entry points ([`super`] module docs, "Bulk optics").

use std::f64::consts::PI;

use num_complex::Complex64;

use super::fingerprint::{fingerprint_hash, format_refractive_index};
use super::integrate::{
    MIN_INDEX_CONTRAST, MatrixSums, ModeGrid, angle_tables, integrate_mode, matrix_integral,
};
use super::work::mie_work;
use super::{SizeDistribution, param};
use crate::particles::matrix::MatrixElements;
use crate::particles::matrix_table::MatrixTable;
use crate::particles::mie::{MieError, check_refractive_index, n_terms};
use crate::particles::table::PhaseTable;

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
    /// Final size-parameter step.
    pub step_x: f64,
    /// Number of radii on the final grid.
    pub points: usize,
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

/// Bulk optics of `dist` with one refractive index `m` (imaginary part ≥ 0 absorbing) at
/// `wavelength_m`: see the module documentation.
pub fn bulk_optics(
    dist: &SizeDistribution,
    m: Complex64,
    wavelength_m: f64,
    opts: &BulkOptions,
) -> Result<BulkOptics, MieError> {
    bulk_optics_mixture(
        &[Component {
            name: "particles".into(),
            distribution: dist.clone(),
            refractive_index: m,
        }],
        wavelength_m,
        opts,
    )
}

/// Bulk optics of an external mixture of `components` at `wavelength_m`: cross-sections are
/// number-weighted over all components, the phase function scattering-weighted (see the module
/// documentation). The phase table's metadata records the inputs and the results.
pub fn bulk_optics_mixture(
    components: &[Component],
    wavelength_m: f64,
    opts: &BulkOptions,
) -> Result<BulkOptics, MieError> {
    check_inputs(components, wavelength_m, opts)?;
    // Refused before any of it is done when it would run for hours (README, "Limits").
    mie_work(components, wavelength_m, opts)?
        .check()
        .map_err(MieError::Work)?;
    let wavelength_um = wavelength_m * 1e6;
    let mut grids = Vec::new();
    let mut convergence = Vec::new();
    let mut number_density = 0.0;
    for c in components {
        number_density += c.distribution.number_density_per_cm3();
        for mode in c.distribution.modes() {
            let (g, conv) =
                integrate_mode(&c.name, &mode, c.refractive_index, wavelength_um, opts)?;
            grids.push(g);
            convergence.push(conv);
        }
    }
    let mut tot = [0.0; 6];
    for g in &grids {
        for (t, v) in tot.iter_mut().zip(g.sums.0) {
            *t += v;
        }
    }
    let [ext, sca, back, gsca, area, vol] = tot;
    let um2_to_m2 = 1e-12;
    let per = |v: f64| v / number_density * um2_to_m2;
    let r_eff = vol / area;
    let ssa = sca / ext;
    let asym = gsca / sca;
    let lidar_ratio = 4.0 * PI * ext / back;

    // Phase function on the final grids.
    let x_eff = 2.0 * PI / wavelength_um * r_eff;
    let theta = match &opts.angles_deg {
        Some(a) => {
            check_angles(a)?;
            a.clone()
        }
        None => default_angle_grid(x_eff),
    };
    let (phase_4pi, elements) = if theta.is_empty() {
        (Vec::new(), Vec::new())
    } else {
        mixture_matrix(&grids, &theta, sca)?
    };

    let mut meta = mixture_description(components, wavelength_m);
    let mut push = |k: &str, v: String| meta.push((k.to_string(), v));
    push("number_density_per_cm3", format!("{number_density:.6e}"));
    push(
        "extinction_cross_section_um2",
        format!("{:.9e}", ext / number_density),
    );
    push(
        "scattering_cross_section_um2",
        format!("{:.9e}", sca / number_density),
    );
    push(
        "backscatter_cross_section_um2",
        format!("{:.9e}", back / number_density),
    );
    push("single_scattering_albedo", format!("{ssa:.9}"));
    push("asymmetry", format!("{asym:.9}"));
    push("lidar_ratio_sr", format!("{lidar_ratio:.6}"));
    push("effective_radius_um", format!("{r_eff:.6}"));
    for c in &convergence {
        push(
            "size_grid",
            format!(
                "{}: r {:.6e}..{:.6e} um, dx = {:.3e}, {} radii, last change {:.1e}, {}",
                c.component,
                c.r_range_um.0,
                c.r_range_um.1,
                c.step_x,
                c.points,
                c.last_rel_change,
                if c.converged {
                    "converged"
                } else {
                    "NOT converged"
                }
            ),
        );
    }
    // Metadata keys must be unique: number the size_grid lines.
    let mut n_grid = 0;
    for (k, _) in meta.iter_mut() {
        if k == "size_grid" {
            n_grid += 1;
            *k = format!("size_grid_{n_grid}");
        }
    }
    meta.push((
        "source".to_string(),
        format!(
            "lidarsim {} Mie (Wiscombe 1979/1980 method), trapezoid in size parameter, tail_fraction {:e}, rel_tol {:e}; fingerprint {}",
            env!("CARGO_PKG_VERSION"),
            opts.tail_fraction,
            opts.rel_tol,
            fingerprint_hash(components, wavelength_m, opts)
        ),
    ));
    Ok(BulkOptics {
        wavelength_m,
        extinction_cross_section_m2: per(ext),
        scattering_cross_section_m2: per(sca),
        backscatter_cross_section_m2: per(back),
        single_scattering_albedo: ssa,
        asymmetry: asym,
        lidar_ratio_sr: lidar_ratio,
        number_density_per_m3: number_density * 1e6,
        effective_radius_um: r_eff,
        matrix: MatrixTable {
            meta: meta.clone(),
            theta_deg: theta.clone(),
            elements,
            circular: true,
        },
        phase: PhaseTable {
            meta,
            theta_deg: theta,
            phase_4pi,
        },
        convergence,
    })
}

/// The phase function (normalised to 4π) and scattering matrix of a mixture at `theta` \[°\],
/// on the final grids of its modes.
fn mixture_matrix(
    grids: &[ModeGrid],
    theta: &[f64],
    sca: f64,
) -> Result<(Vec<f64>, Vec<MatrixElements>), MieError> {
    let n_max = grids
        .iter()
        .map(|g| n_terms(g.x_lo + g.points as f64 * g.dx))
        .max()
        .unwrap_or(1);
    let tables = angle_tables(theta, n_max);
    let mut dcdo = MatrixSums::zeros(theta.len());
    for g in grids {
        dcdo.add(&matrix_integral(g, &tables)?);
    }
    // F_ij = 4π ⟨dC_ij/dΩ⟩/⟨Csca⟩: every element normalised like the phase function; for
    // spheres F22 = F11 and F44 = F33.
    let norm = |d: f64| 4.0 * PI * d / sca;
    let phase_4pi: Vec<f64> = dcdo.s11.iter().map(|d| norm(*d)).collect();
    let elements = (0..theta.len())
        .map(|a| MatrixElements {
            f11: phase_4pi[a],
            f22: phase_4pi[a],
            f33: norm(dcdo.s33[a]),
            f44: norm(dcdo.s33[a]),
            f12: norm(dcdo.s12[a]),
            f34: norm(dcdo.s34[a]),
        })
        .collect();
    Ok((phase_4pi, elements))
}

/// The metadata that describe a mixture: wavelength, refractive index and distribution (of
/// each component when there are several).
fn mixture_description(components: &[Component], wavelength_m: f64) -> Vec<(String, String)> {
    let refr = if components.len() == 1 {
        format_refractive_index(components[0].refractive_index)
    } else {
        "external mixture (see component_* keys)".to_string()
    };
    let distribution = if components.len() == 1 {
        components[0].distribution.to_string()
    } else {
        components
            .iter()
            .map(|c| c.name.clone())
            .collect::<Vec<_>>()
            .join(" + ")
    };
    let mut meta = vec![
        (
            "wavelength_nm".to_string(),
            // Rounded to 1e-9 nm so 1572e-9 m prints as 1572, not 1572.0000000000002.
            format!("{}", (wavelength_m * 1e18).round() / 1e9),
        ),
        ("refractive_index".to_string(), refr),
        ("distribution".to_string(), distribution),
    ];
    if components.len() > 1 {
        for (i, c) in components.iter().enumerate() {
            meta.push((
                format!("component_{}", i + 1),
                format!(
                    "{}: m = {}, {}",
                    c.name,
                    format_refractive_index(c.refractive_index),
                    c.distribution
                ),
            ));
        }
    }
    meta
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

fn check_angles(a: &[f64]) -> Result<(), MieError> {
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
