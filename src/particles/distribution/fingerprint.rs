//! The cache key of a Mie computation: a stable text of its inputs and its FNV-1a hash.

use num_complex::Complex64;

use super::options::{BulkOptions, Component};

/// Format a complex refractive index as `1.3205+1.28e-6i` (the CLI's syntax).
pub fn format_refractive_index(m: Complex64) -> String {
    if m.im != 0.0 && m.im.abs() < 1e-3 {
        format!("{}+{:e}i", m.re, m.im)
    } else {
        format!("{}{:+}i", m.re, m.im)
    }
}

/// The version of the Mie computation that starts every [`fingerprint`].
pub const MIE_VERSION: &str = "lidarsim-mie-v4";

/// A stable text fingerprint of the inputs of [`bulk_optics_mixture`] (components, wavelength,
/// options, solver version): equal inputs give equal text on every machine (shortest round-trip
/// number formatting). Use [`fingerprint_hash`] for a short file name.
pub fn fingerprint(components: &[Component], wavelength_m: f64, opts: &BulkOptions) -> String {
    // The version of the Mie computation: bumped whenever its numbers change, so that cache
    // entries of another version are recomputed rather than read. v2: results carry the
    // scattering matrix (v1 entries hold the phase function only); v3: the size integration
    // refines panels where the integrals change (not one uniform grid); v4: the panels that
    // stop early are chosen by their change per unit cost (other final grids, same tolerance).
    let mut s = format!("{MIE_VERSION};wavelength_m={wavelength_m:e}");
    for c in components {
        s.push_str(&format!(
            ";component={}:m={:e}{:+e}i:{}",
            c.name, c.refractive_index.re, c.refractive_index.im, c.distribution
        ));
    }
    s.push_str(&format!(
        ";tail_fraction={:e};rel_tol={:e};min_step_x={:e};max_points={}",
        opts.tail_fraction, opts.rel_tol, opts.min_step_x, opts.max_points
    ));
    match &opts.angles_deg {
        None => s.push_str(";angles=default"),
        Some(a) => {
            s.push_str(";angles=");
            for (i, t) in a.iter().enumerate() {
                if i > 0 {
                    s.push(',');
                }
                s.push_str(&format!("{t:e}"));
            }
        }
    }
    s
}

/// 64-bit FNV-1a hash of [`fingerprint`] as 16 hex digits (stable across platforms and runs).
pub fn fingerprint_hash(components: &[Component], wavelength_m: f64, opts: &BulkOptions) -> String {
    let mut h = crate::digest::Fnv::new();
    h.update(fingerprint(components, wavelength_m, opts).as_bytes());
    format!("{:016x}", h.finish())
}
