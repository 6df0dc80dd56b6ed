//! What `lidarsim mie` prints: the optics of one sphere, or the bulk optics of a size
//! distribution, as JSON.

use std::path::Path;

use num_complex::Complex64;
use serde_json::json;

use crate::particles::distribution::{BulkOptics, MieWork, format_refractive_index};
use crate::particles::mie::{MieCoefficients, MieError};

/// One sphere of refractive index `m` and size parameter `x` (its coefficients `k`): its
/// efficiencies (qext, qsca, qback), g and single-scattering albedo, and with `angles_deg` its
/// amplitudes S1, S2 there.
pub fn sphere_json(
    k: &MieCoefficients,
    m: Complex64,
    x: f64,
    angles_deg: &[f64],
) -> Result<serde_json::Value, MieError> {
    let e = k.efficiencies();
    let mut out = json!({
        "refractive_index": format_refractive_index(m),
        "size_parameter": x,
        "qext": e.qext,
        "qsca": e.qsca,
        "qback": e.qback,
        "g": e.g,
        "ssa": e.ssa,
        "n_terms": e.n_terms,
    });
    if !angles_deg.is_empty() {
        let mu: Vec<f64> = angles_deg.iter().map(|t| t.to_radians().cos()).collect();
        let (s1, s2) = k.amplitudes(&mu)?;
        out["amplitudes"] = json!(
            angles_deg
                .iter()
                .zip(s1.iter().zip(&s2))
                .map(|(t, (a, b))| json!({"theta_deg": t, "s1": [a.re, a.im], "s2": [b.re, b.im]}))
                .collect::<Vec<_>>()
        );
    }
    Ok(out)
}

/// The bulk optics `b` of a size distribution at `wavelength_nm`: its refractive index (or
/// indices) and description as given, cross-sections per particle, albedo, asymmetry, lidar
/// ratio, the size grid's convergence, the Mie `work`, and the `tables` (phase function,
/// scattering matrix) written.
pub fn bulk_json(
    b: &BulkOptics,
    wavelength_nm: f64,
    refractive_index: serde_json::Value,
    distribution: String,
    work: &MieWork,
    (table, matrix_table): (Option<&Path>, Option<&Path>),
) -> serde_json::Value {
    let out = json!({
        "wavelength_nm": wavelength_nm,
        "refractive_index": refractive_index,
        "distribution": distribution,
        "number_density_per_cm3": b.number_density_per_m3 * 1e-6,
        "extinction_cross_section_um2": b.extinction_cross_section_m2 * 1e12,
        "scattering_cross_section_um2": b.scattering_cross_section_m2 * 1e12,
        "backscatter_cross_section_um2": b.backscatter_cross_section_m2 * 1e12,
        "extinction_per_km": b.extinction_per_m(b.number_density_per_m3) * 1e3,
        "single_scattering_albedo": b.single_scattering_albedo,
        "asymmetry": b.asymmetry,
        "lidar_ratio_sr": b.lidar_ratio_sr,
        "phase_180": b.phase_180(),
        "effective_radius_um": b.effective_radius_um,
        "size_grid": b.convergence.iter().map(|c| json!({
            "component": c.component,
            "r_min_um": c.r_range_um.0, "r_max_um": c.r_range_um.1, "step_x": c.step_x,
            "points": c.points, "last_rel_change": c.last_rel_change, "converged": c.converged,
        })).collect::<Vec<_>>(),
        "mie_work": json!({
            "term_angles": work.work, "radii_bound": work.radii, "terms": work.terms,
            "angles": work.angles, "estimated_seconds_one_core": work.seconds(),
        }),
        "table": table.map(|p| p.display().to_string()),
        "matrix_table": matrix_table.map(|p| p.display().to_string()),
    });
    out
}
