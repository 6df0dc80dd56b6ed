//! Bulk optics of a distribution or an external mixture: the options, the result and the
//! entry points ([`super`] module docs, "Bulk optics").

use std::f64::consts::PI;

use num_complex::Complex64;

use super::SizeDistribution;
use super::fingerprint::{fingerprint_hash, format_refractive_index};
use super::integrate::{MatrixSums, ModeGrid, angle_tables, integrate_mode, mode_range_um};
use super::options::*;
use super::work::mie_work;
use crate::particles::matrix::MatrixElements;
use crate::particles::matrix_table::MatrixTable;
use crate::particles::mie::{MieError, n_terms};
use crate::particles::table::PhaseTable;

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
    bulk_optics_mixture_with_progress(components, wavelength_m, opts, &|_| {})
}

/// [`bulk_optics_mixture`], telling `progress` how far it is ([`MieProgress`], after every
/// batch of a few thousand radii or fewer): for a progress display where the computation can
/// take seconds. The numbers do not depend on it.
pub fn bulk_optics_mixture_with_progress(
    components: &[Component],
    wavelength_m: f64,
    opts: &BulkOptions,
    progress: &dyn Fn(&MieProgress),
) -> Result<BulkOptics, MieError> {
    check_inputs(components, wavelength_m, opts)?;
    // Refused before any of it is done when it would run for hours (README, "Limits").
    let work = mie_work(components, wavelength_m, opts)?;
    work.check().map_err(MieError::Work)?;
    let wavelength_um = wavelength_m * 1e6;
    let k = 2.0 * PI / wavelength_um;
    // The angles and their tables come first: the angular integrals are summed on the fly,
    // from the same Mie coefficients as the efficiencies.
    let mut x_max = 0.0f64;
    let (mut area_moment, mut volume_moment) = (0.0, 0.0);
    let mut integrations = 0;
    for c in components {
        let n = c.distribution.number_density_per_cm3();
        area_moment += n * c.distribution.moment(2.0);
        volume_moment += n * c.distribution.moment(3.0);
        for mode in c.distribution.modes() {
            x_max = x_max.max(k * mode_range_um(&mode, k, opts)?.1);
            integrations += 1;
        }
    }
    let theta = match &opts.angles_deg {
        Some(a) => {
            check_angles(a)?;
            a.clone()
        }
        // The effective size parameter of the untruncated distributions, within the integrated
        // range: the grid mie_work counts.
        None => default_angle_grid((k * volume_moment / area_moment).min(x_max)),
    };
    let tables = (!theta.is_empty()).then(|| angle_tables(&theta, n_terms(x_max)));
    let mut grids = Vec::new();
    let mut convergence = Vec::new();
    let mut number_density = 0.0;
    let done = std::sync::atomic::AtomicU64::new(0);
    for c in components {
        number_density += c.distribution.number_density_per_cm3();
        for mode in c.distribution.modes() {
            let integration = grids.len() + 1;
            let tell = |radii: u64| {
                let radii = done.fetch_add(radii, std::sync::atomic::Ordering::Relaxed) + radii;
                progress(&MieProgress {
                    integration,
                    integrations,
                    component: c.name.clone(),
                    radii,
                    radii_bound: work.radii,
                });
            };
            let (g, conv) = integrate_mode(
                &c.name,
                &mode,
                c.refractive_index,
                wavelength_um,
                opts,
                tables.as_ref(),
                &tell,
            )?;
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

    let (phase_4pi, elements) = if theta.is_empty() {
        (Vec::new(), Vec::new())
    } else {
        mixture_matrix(&grids, theta.len(), sca)
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
                "{}: r {:.6e}..{:.6e} um, dx >= {:.3e}, {} radii, last change {:.1e}, {}",
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
            "lidarsim {} Mie (Wiscombe 1979/1980 method), trapezoid in size parameter on 16 panels refined where the integrals change, tail_fraction {:e}, rel_tol {:e}; fingerprint {}",
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

/// The phase function (normalised to 4π) and scattering matrix of a mixture on its `kk`
/// angles, from the angular integrals of its modes.
fn mixture_matrix(grids: &[ModeGrid], kk: usize, sca: f64) -> (Vec<f64>, Vec<MatrixElements>) {
    let mut dcdo = MatrixSums::zeros(kk);
    for g in grids {
        if let Some(m) = &g.matrix {
            dcdo.add(m);
        }
    }
    // F_ij = 4π ⟨dC_ij/dΩ⟩/⟨Csca⟩: every element normalised like the phase function; for
    // spheres F22 = F11 and F44 = F33.
    let norm = |d: f64| 4.0 * PI * d / sca;
    let phase_4pi: Vec<f64> = dcdo.s11.iter().map(|d| norm(*d)).collect();
    let elements = (0..kk)
        .map(|a| MatrixElements {
            f11: phase_4pi[a],
            f22: phase_4pi[a],
            f33: norm(dcdo.s33[a]),
            f44: norm(dcdo.s33[a]),
            f12: norm(dcdo.s12[a]),
            f34: norm(dcdo.s34[a]),
        })
        .collect();
    (phase_4pi, elements)
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
