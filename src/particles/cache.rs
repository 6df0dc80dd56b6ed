//! Mie bulk optics computed on the fly for scenes, cached in memory for the life of the process
//! and, when a cache directory is given, on disk as phase-function tables.
//!
//! The key is the full text fingerprint of the inputs ([`fingerprint`]: components, wavelength,
//! size-integration options, solver version). A disk entry is `mie-<hash>.txt` in the
//! scattering-matrix format of [`super::matrix_table`] (whose F11 column is the phase
//! function) with the fingerprint and the bulk numbers in its metadata; an entry whose
//! fingerprint text differs (a hash collision, a file edited by hand, or an entry of an earlier
//! version — `lidarsim-mie-v1` entries hold the phase function only) is recomputed and
//! replaced, never trusted.

use std::collections::HashMap;
use std::path::Path;
use std::sync::{Arc, Mutex, OnceLock};

use super::distribution::{
    BulkOptions, Component, bulk_optics_mixture, fingerprint, fingerprint_hash,
};
use super::matrix_table::MatrixTable;
use crate::input::parse_f64;
use crate::output::OutputError;

/// What a scene needs of a particle population at one wavelength.
#[derive(Debug, Clone, PartialEq)]
pub struct LayerOptics {
    /// Mean extinction cross-section per particle \[m²\].
    pub extinction_cross_section_m2: f64,
    /// Single-scattering albedo.
    pub single_scattering_albedo: f64,
    /// Scattering matrix, normalised to 4π (its F11 column is the Mie stage's phase table,
    /// number for number: [`MatrixTable::f11_table`]).
    pub matrix: MatrixTable,
}

/// Where a result came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CacheUse {
    /// Computed now.
    Computed,
    /// Found in this process's memory.
    Memory,
    /// Read from the disk cache.
    Disk,
}

fn memory() -> &'static Mutex<HashMap<String, Arc<LayerOptics>>> {
    static CACHE: OnceLock<Mutex<HashMap<String, Arc<LayerOptics>>>> = OnceLock::new();
    CACHE.get_or_init(|| Mutex::new(HashMap::new()))
}

/// Bulk optics of an external mixture at one wavelength, from the caches when possible. Errors
/// (invalid distributions or refractive indices) come back as the Mie stage's message.
pub fn layer_optics(
    components: &[Component],
    wavelength_m: f64,
    opts: &BulkOptions,
    cache_dir: Option<&Path>,
) -> Result<(Arc<LayerOptics>, CacheUse), String> {
    let key = fingerprint(components, wavelength_m, opts);
    if let Some(hit) = memory().lock().ok().and_then(|m| m.get(&key).cloned()) {
        return Ok((hit, CacheUse::Memory));
    }
    let file = cache_dir.map(|d| {
        d.join(format!(
            "mie-{}.txt",
            fingerprint_hash(components, wavelength_m, opts)
        ))
    });
    if let Some(hit) = file.as_deref().and_then(|f| read_entry(f, &key)) {
        let hit = Arc::new(hit);
        if let Ok(mut m) = memory().lock() {
            m.insert(key, hit.clone());
        }
        return Ok((hit, CacheUse::Disk));
    }
    let bulk = bulk_optics_mixture(components, wavelength_m, opts).map_err(|e| e.to_string())?;
    // Pass the table through its text form, as a disk entry would, so that a run gives the
    // same numbers whether or not it found the entry (F11 is printed as the phase is).
    let matrix = MatrixTable::parse(Path::new("<mie>"), &bulk.matrix.to_text())
        .map_err(|e| format!("Mie scattering matrix: {e}"))?;
    let optics = Arc::new(LayerOptics {
        extinction_cross_section_m2: bulk.extinction_cross_section_m2,
        single_scattering_albedo: bulk.single_scattering_albedo,
        matrix,
    });
    if let (Some(dir), Some(f)) = (cache_dir, &file) {
        // A cache that cannot be written only costs time next run; the result stands.
        // Made first: threads that compute entries at once then do not race to create it.
        let _ = std::fs::create_dir_all(dir);
        let _ = write_entry(f, &key, &optics);
    }
    if let Ok(mut m) = memory().lock() {
        m.insert(key, optics.clone());
    }
    Ok((optics, CacheUse::Computed))
}

fn write_entry(path: &Path, key: &str, o: &LayerOptics) -> Result<(), OutputError> {
    let mut t = o.matrix.clone();
    t.meta.retain(|(k, _)| {
        !matches!(
            k.as_str(),
            "fingerprint" | "cache_extinction_cross_section_m2" | "cache_single_scattering_albedo"
        )
    });
    t.meta.push(("fingerprint".into(), key.to_string()));
    t.meta.push((
        "cache_extinction_cross_section_m2".into(),
        format!("{:e}", o.extinction_cross_section_m2),
    ));
    t.meta.push((
        "cache_single_scattering_albedo".into(),
        format!("{:e}", o.single_scattering_albedo),
    ));
    t.write(path)
}

fn read_entry(path: &Path, key: &str) -> Option<LayerOptics> {
    let t = MatrixTable::read(path).ok()?;
    if t.meta("fingerprint")? != key || !t.circular {
        return None;
    }
    let num = |k: &str| t.meta(k).and_then(|v| parse_f64(path, 0, k, v).ok());
    Some(LayerOptics {
        extinction_cross_section_m2: num("cache_extinction_cross_section_m2")?,
        single_scattering_albedo: num("cache_single_scattering_albedo")?,
        matrix: t,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::particles::distribution::SizeDistribution;
    use crate::particles::table::PhaseTable;
    use num_complex::Complex64;

    #[test]
    fn disk_cache_round_trips_and_rejects_other_inputs() {
        let dir = tempfile::tempdir().unwrap();
        let comp = |m: f64| Component {
            name: "p".into(),
            distribution: SizeDistribution::lognormal(1.0, 0.3, 1.6).unwrap(),
            refractive_index: Complex64::new(m, 1e-3),
        };
        let opts = BulkOptions {
            angles_deg: Some((0..=180).map(f64::from).collect()),
            ..Default::default()
        };
        let (a, how) = layer_optics(&[comp(1.5)], 1.064e-6, &opts, Some(dir.path())).unwrap();
        assert_eq!(how, CacheUse::Computed);
        let file = std::fs::read_dir(dir.path())
            .unwrap()
            .next()
            .unwrap()
            .unwrap()
            .path();
        let back = read_entry(&file, &fingerprint(&[comp(1.5)], 1.064e-6, &opts)).unwrap();
        assert_eq!(
            back.extinction_cross_section_m2,
            a.extinction_cross_section_m2
        );
        assert_eq!(back.single_scattering_albedo, a.single_scattering_albedo);
        // The disk entry gives the same matrix as the computed result, and its F11 column is
        // the Mie stage's phase table as that table prints itself.
        assert_eq!(back.matrix.theta_deg, a.matrix.theta_deg);
        assert_eq!(back.matrix.elements, a.matrix.elements);
        let bulk = bulk_optics_mixture(&[comp(1.5)], 1.064e-6, &opts).unwrap();
        let phase = PhaseTable::parse(Path::new("p"), &bulk.phase.to_text()).unwrap();
        assert_eq!(back.matrix.f11_table().phase_4pi, phase.phase_4pi);
        assert_eq!(back.matrix.theta_deg, phase.theta_deg);
        assert!(read_entry(&file, &fingerprint(&[comp(1.51)], 1.064e-6, &opts)).is_none());
    }

    /// An entry of the previous cache version (a scalar phase table, fingerprint
    /// `lidarsim-mie-v1…`) under the current file name is not read: it is recomputed and
    /// replaced by an entry with the matrix.
    #[test]
    fn entries_of_the_scalar_cache_version_are_recomputed() {
        let dir = tempfile::tempdir().unwrap();
        let comp = Component {
            name: "p".into(),
            distribution: SizeDistribution::lognormal(1.0, 0.2, 1.5).unwrap(),
            refractive_index: Complex64::new(1.45, 1e-4),
        };
        let opts = BulkOptions {
            angles_deg: Some((0..=36).map(|i| 5.0 * i as f64).collect()),
            ..Default::default()
        };
        let key = fingerprint(std::slice::from_ref(&comp), 532e-9, &opts);
        let file = dir.path().join(format!(
            "mie-{}.txt",
            fingerprint_hash(std::slice::from_ref(&comp), 532e-9, &opts)
        ));
        // A v1 entry: the phase table format, with the old fingerprint text.
        let mut old = PhaseTable {
            meta: crate::particles::table::REQUIRED_KEYS
                .iter()
                .map(|k| (k.to_string(), "none".to_string()))
                .collect(),
            theta_deg: vec![0.0, 180.0],
            phase_4pi: vec![1.0, 1.0],
        };
        old.meta.push((
            "fingerprint".into(),
            key.replacen("lidarsim-mie-v2", "lidarsim-mie-v1", 1),
        ));
        old.meta
            .push(("cache_extinction_cross_section_m2".into(), "1e-12".into()));
        old.meta
            .push(("cache_single_scattering_albedo".into(), "1".into()));
        old.write(&file).unwrap();
        assert!(read_entry(&file, &key).is_none());
        let (o, how) =
            layer_optics(std::slice::from_ref(&comp), 532e-9, &opts, Some(dir.path())).unwrap();
        assert_eq!(how, CacheUse::Computed);
        assert_eq!(o.matrix.theta_deg.len(), 37);
        assert!(
            read_entry(&file, &key).is_some(),
            "replaced by the new entry"
        );
    }
}
