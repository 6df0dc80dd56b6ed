//! `lidarsim mie`: the optics of one sphere, or the bulk optics of a size distribution (an OPAC
//! aerosol among them) with the checks of their Mie work, as the JSON it prints.

use std::path::Path;

use num_complex::Complex64;
use serde_json::json;

use super::ProductError;
use crate::particles::distribution::{
    BulkOptics, BulkOptions, Component, MieWork, format_refractive_index, mie_work,
};
use crate::particles::mie::{MieCoefficients, MieError};
use crate::particles::opac::{OpacComponent, OpacType};

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

/// The OPAC aerosol (Hess et al. 1998, "Optical Properties of Aerosols and Clouds: The Software
/// Package OPAC") of `lidarsim mie --distribution opac`, by name.
pub enum Opac<'a> {
    /// An aerosol type: a mixture of components.
    Type(&'a str),
    /// One component and its number density \[cm⁻³\].
    Component(&'a str, f64),
}

/// The bulk optics of an OPAC aerosol, with the refractive index (per component of a type) and
/// the description of its size distribution, and the Mie work it took.
pub struct OpacOptics {
    /// The bulk optics and tables.
    pub bulk: BulkOptics,
    /// Its refractive index, or per component of a type.
    pub indices: serde_json::Value,
    /// Its size distribution.
    pub description: String,
    /// The Mie work.
    pub work: MieWork,
}

/// The bulk optics of `which` at `wavelength_m` with OPAC's own refractive indices, after its
/// Mie work is checked ([`check_work`]).
pub fn opac(
    which: Opac,
    wavelength_m: f64,
    opts: &BulkOptions,
) -> Result<OpacOptics, ProductError> {
    opac_with_progress(which, wavelength_m, opts, &|_| {})
}

/// [`opac`], telling `progress` how far the size integration is.
pub fn opac_with_progress(
    which: Opac,
    wavelength_m: f64,
    opts: &BulkOptions,
    progress: &dyn Fn(&crate::particles::distribution::MieProgress),
) -> Result<OpacOptics, ProductError> {
    let (bulk, indices, description, work) = match which {
        Opac::Type(t) => {
            let t = OpacType::from_name(t).ok_or_else(|| {
                ProductError::Request(format!(
                    "--aerosol-type `{t}`: unknown OPAC type (known: {})",
                    OpacType::ALL.map(|t| t.name()).join(", ")
                ))
            })?;
            let comps = t
                .components(wavelength_m)
                .map_err(|e| ProductError::context("--wavelength-nm", e))?;
            let work = check_work(&comps, wavelength_m, opts)?;
            let b = t.bulk_optics_with_progress(wavelength_m, opts, progress)?;
            let indices: serde_json::Map<String, serde_json::Value> = comps
                .iter()
                .map(|c| {
                    (
                        c.name.clone(),
                        json!(format_refractive_index(c.refractive_index)),
                    )
                })
                .collect();
            let desc = b.phase.meta("distribution").unwrap_or_default().to_string();
            (b, serde_json::Value::Object(indices), desc, work)
        }
        Opac::Component(c, number_density_per_cm3) => {
            let c = OpacComponent::from_name(c).ok_or_else(|| {
                ProductError::Request(format!(
                    "--opac-component `{c}`: unknown OPAC component (known: {})",
                    OpacComponent::ALL.map(|c| c.name()).join(", ")
                ))
            })?;
            let m = c
                .refractive_index(wavelength_m)
                .map_err(|e| ProductError::context("--wavelength-nm", e))?;
            let work = check_work(
                &[c.component(number_density_per_cm3, wavelength_m)?],
                wavelength_m,
                opts,
            )?;
            let b =
                c.bulk_optics_with_progress(number_density_per_cm3, wavelength_m, opts, progress)?;
            let desc = c.size_distribution(number_density_per_cm3)?.to_string();
            (b, json!(format_refractive_index(m)), desc, work)
        }
    };
    Ok(OpacOptics {
        bulk,
        indices,
        description,
        work,
    })
}

/// Refuse, in milliseconds, a size integration beyond the limit of Mie work (README, "Limits"),
/// and say how long one above a minute will take before starting it.
pub fn check_work(
    components: &[Component],
    wavelength_m: f64,
    opts: &BulkOptions,
) -> Result<MieWork, ProductError> {
    let w = mie_work(components, wavelength_m, opts)?;
    w.check().map_err(ProductError::Request)?;
    if let Some(note) = w.warning() {
        crate::limits::warn(&note);
    }
    Ok(w)
}

/// Add the --meta KEY=VALUE lines before the final `source` line.
pub fn add_meta(b: &mut BulkOptics, meta: &[String]) -> Result<(), ProductError> {
    for kv in meta {
        let Some((k, v)) = kv.split_once('=') else {
            return Err(ProductError::Request(format!(
                "--meta `{kv}`: expected KEY=VALUE"
            )));
        };
        let k = k.trim();
        if k.is_empty() || !k.chars().all(|c| c.is_ascii_alphanumeric() || c == '_') {
            return Err(ProductError::Request(format!(
                "--meta `{kv}`: the key must be letters, digits and _"
            )));
        }
        if b.phase.meta(k).is_some() {
            return Err(ProductError::Request(format!(
                "--meta `{kv}`: key `{k}` is already set"
            )));
        }
        // Keep `source` last (the matrix table carries the same metadata).
        for meta in [&mut b.phase.meta, &mut b.matrix.meta] {
            let at = meta.len().saturating_sub(1);
            meta.insert(at, (k.to_string(), v.trim().to_string()));
        }
    }
    Ok(())
}
