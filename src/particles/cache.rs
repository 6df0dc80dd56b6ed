//! Mie bulk optics computed on the fly for scenes, cached in memory for the life of the process
//! and on disk as phase-function tables — by default in the user's cache directory
//! ([`default_cache_dir`]), so that a scene with a Mie layer pays for its Mie theory once.
//!
//! The key is the full text fingerprint of the inputs ([`fingerprint`]: components, wavelength,
//! size-integration options, and the version of the Mie computation, bumped whenever its
//! numbers change). A disk entry is `mie-<hash>.txt` in the scattering-matrix format of
//! [`super::matrix_table`] (whose F11 column is the phase function) with the fingerprint and
//! the bulk numbers in its metadata. An entry is written to a temporary file beside it and
//! renamed into place, so a run that reads it (another process on a shared file system, say)
//! sees the whole entry or none. An entry that cannot be read or whose fingerprint text differs
//! (a corrupt or truncated file, a file edited by hand, a hash collision, an entry of another
//! version under the same name) is recomputed and replaced, never trusted, with a warning.

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex, OnceLock};

use super::distribution::{
    BulkOptions, Component, MieProgress, bulk_optics_mixture_with_progress, fingerprint,
    fingerprint_hash, progress_lines,
};
use super::matrix_table::MatrixTable;
use crate::input::parse_f64;

/// The environment variable that moves the Mie cache (`LIDARSIM_CACHE_DIR=/scratch/me/mie`)
/// or, set to `off` or to nothing, turns it off (README, "The Mie cache").
pub const CACHE_DIR_ENV: &str = "LIDARSIM_CACHE_DIR";

/// The Mie cache directory when a scene names none (README, "The Mie cache"):
/// `$LIDARSIM_CACHE_DIR` (`off` or empty: no disk cache), else `$XDG_CACHE_HOME/lidarsim`, else
/// `$HOME/.cache/lidarsim` (the XDG Base Directory Specification's default), else
/// `%LOCALAPPDATA%\lidarsim` (Windows), else none. The variables are read directly: the rule is
/// the specification's three lines, and it gives the same place on a Linux workstation, a Mac
/// and a cluster node, where users look for it.
///
/// In the library's own unit tests there is no default: they must not write into the user's
/// cache (the integration tests turn it off with [`CACHE_DIR_ENV`]).
pub fn default_cache_dir() -> Option<PathBuf> {
    if cfg!(test) {
        return None;
    }
    cache_dir_from(&|k| std::env::var_os(k))
}

/// [`default_cache_dir`] with the environment given as a lookup (for tests).
pub fn cache_dir_from(env: &dyn Fn(&str) -> Option<std::ffi::OsString>) -> Option<PathBuf> {
    if let Some(v) = env(CACHE_DIR_ENV) {
        return (!(v.is_empty() || v == "off")).then(|| PathBuf::from(v));
    }
    // The specification: a relative XDG_CACHE_HOME is invalid and is ignored.
    let absolute = |k: &str| env(k).map(PathBuf::from).filter(|p| p.is_absolute());
    if let Some(x) = absolute("XDG_CACHE_HOME") {
        return Some(x.join("lidarsim"));
    }
    if let Some(h) = absolute("HOME") {
        return Some(h.join(".cache").join("lidarsim"));
    }
    absolute("LOCALAPPDATA").map(|d| d.join("lidarsim"))
}

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
/// (invalid distributions or refractive indices) come back as the Mie stage's message; a disk
/// cache that cannot be read or written costs time only (with a warning), never the result.
///
/// A computation that takes over 2 s says how far it is on standard error every 2 s
/// ([`progress_lines`]); [`layer_optics_with_progress`] takes another report.
pub fn layer_optics(
    components: &[Component],
    wavelength_m: f64,
    opts: &BulkOptions,
    cache_dir: Option<&Path>,
) -> Result<(Arc<LayerOptics>, CacheUse), String> {
    let what = format!(
        "lidarsim: Mie optics at {} nm",
        (wavelength_m * 1e18).round() / 1e9
    );
    layer_optics_with_progress(
        components,
        wavelength_m,
        opts,
        cache_dir,
        &progress_lines(what),
    )
}

/// [`layer_optics`], telling `progress` how far a computation is (nothing when the result
/// comes from a cache).
pub fn layer_optics_with_progress(
    components: &[Component],
    wavelength_m: f64,
    opts: &BulkOptions,
    cache_dir: Option<&Path>,
    progress: &dyn Fn(&MieProgress),
) -> Result<(Arc<LayerOptics>, CacheUse), String> {
    lookup_with(components, wavelength_m, opts, cache_dir, true, progress)
}

/// The path of the disk entry of these inputs in `dir`.
pub fn entry_path(
    dir: &Path,
    components: &[Component],
    wavelength_m: f64,
    opts: &BulkOptions,
) -> PathBuf {
    dir.join(format!(
        "mie-{}.txt",
        fingerprint_hash(components, wavelength_m, opts)
    ))
}

/// [`layer_optics`], with or without the memory cache (tests take the disk path with it off).
#[cfg(test)]
fn lookup(
    components: &[Component],
    wavelength_m: f64,
    opts: &BulkOptions,
    cache_dir: Option<&Path>,
    use_memory: bool,
) -> Result<(Arc<LayerOptics>, CacheUse), String> {
    lookup_with(
        components,
        wavelength_m,
        opts,
        cache_dir,
        use_memory,
        &|_| {},
    )
}

fn lookup_with(
    components: &[Component],
    wavelength_m: f64,
    opts: &BulkOptions,
    cache_dir: Option<&Path>,
    use_memory: bool,
    progress: &dyn Fn(&MieProgress),
) -> Result<(Arc<LayerOptics>, CacheUse), String> {
    let key = fingerprint(components, wavelength_m, opts);
    if use_memory && let Some(hit) = memory().lock().ok().and_then(|m| m.get(&key).cloned()) {
        return Ok((hit, CacheUse::Memory));
    }
    let file = cache_dir.map(|d| entry_path(d, components, wavelength_m, opts));
    if let Some(f) = &file
        && f.exists()
    {
        match read_entry(f, &key) {
            Ok(hit) => {
                let hit = Arc::new(hit);
                if let Ok(mut m) = memory().lock() {
                    m.insert(key, hit.clone());
                }
                return Ok((hit, CacheUse::Disk));
            }
            Err(why) => crate::limits::warn(&format!(
                "Mie cache entry {}: {why}; recomputed and replaced",
                f.display()
            )),
        }
    }
    let bulk = bulk_optics_mixture_with_progress(components, wavelength_m, opts, progress)
        .map_err(|e| e.to_string())?;
    // Pass the table through its text form, as a disk entry would, so that a run gives the
    // same numbers whether or not it found the entry (F11 is printed as the phase is).
    let matrix = MatrixTable::parse(Path::new("<mie>"), &bulk.matrix.to_text())
        .map_err(|e| format!("Mie scattering matrix: {e}"))?;
    let optics = Arc::new(LayerOptics {
        extinction_cross_section_m2: bulk.extinction_cross_section_m2,
        single_scattering_albedo: bulk.single_scattering_albedo,
        matrix,
    });
    if let (Some(dir), Some(f)) = (cache_dir, &file)
        && let Err(e) = write_entry(dir, f, &key, &optics)
    {
        // A cache that cannot be written only costs time next run: said once a process.
        static SAID: AtomicBool = AtomicBool::new(false);
        if !SAID.swap(true, Ordering::Relaxed) {
            crate::limits::warn(&format!(
                "cannot write the Mie cache in {}: {e} (the result stands; next run computes \
                 it again; set {CACHE_DIR_ENV} to another directory, or to `off`)",
                dir.display()
            ));
        }
    }
    if let Ok(mut m) = memory().lock() {
        m.insert(key, optics.clone());
    }
    Ok((optics, CacheUse::Computed))
}

/// The text of a disk entry: the matrix table with the fingerprint and the bulk numbers
/// (shortest round-trip formatting: read back, they are the same numbers bit for bit).
fn entry_text(key: &str, o: &LayerOptics) -> String {
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
    t.to_text()
}

/// Write the entry to a temporary file in `dir` (unique to this process and call) and rename
/// it onto `path`: a rename within a directory is atomic, so readers never see half an entry,
/// and of two processes writing the same entry at once the last rename wins whole.
fn write_entry(dir: &Path, path: &Path, key: &str, o: &LayerOptics) -> std::io::Result<()> {
    use std::io::Write;
    static SEQ: AtomicU64 = AtomicU64::new(0);
    std::fs::create_dir_all(dir)?;
    let name = path.file_name().unwrap_or_default().to_string_lossy();
    let tmp = dir.join(format!(
        ".{name}.{}-{}.tmp",
        std::process::id(),
        SEQ.fetch_add(1, Ordering::Relaxed)
    ));
    let written = (|| {
        let mut f = std::fs::File::create(&tmp)?;
        f.write_all(entry_text(key, o).as_bytes())?;
        f.sync_all()?;
        std::fs::rename(&tmp, path)
    })();
    if written.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    written
}

/// The entry at `path` if it is one for `key`, else why not.
fn read_entry(path: &Path, key: &str) -> Result<LayerOptics, String> {
    let t = MatrixTable::read(path).map_err(|e| format!("unreadable ({e})"))?;
    if t.meta("fingerprint") != Some(key) {
        return Err("made for other inputs or another version of the Mie computation".into());
    }
    if !t.circular {
        return Err("not a scattering-matrix table of this version".into());
    }
    let num = |k: &str| {
        t.meta(k)
            .ok_or_else(|| format!("no `{k}`"))
            .and_then(|v| parse_f64(path, 0, k, v).map_err(|e| e.to_string()))
    };
    let extinction_cross_section_m2 = num("cache_extinction_cross_section_m2")?;
    let single_scattering_albedo = num("cache_single_scattering_albedo")?;
    let in_range = extinction_cross_section_m2 > 0.0
        && extinction_cross_section_m2.is_finite()
        && (0.0..=1.0).contains(&single_scattering_albedo);
    if !in_range {
        return Err("bulk numbers out of range".into());
    }
    Ok(LayerOptics {
        extinction_cross_section_m2,
        single_scattering_albedo,
        matrix: t,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::particles::distribution::{SizeDistribution, bulk_optics_mixture};
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
        assert!(read_entry(&file, &fingerprint(&[comp(1.51)], 1.064e-6, &opts)).is_err());
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
            key.replacen(
                crate::particles::distribution::MIE_VERSION,
                "lidarsim-mie-v1",
                1,
            ),
        ));
        old.meta
            .push(("cache_extinction_cross_section_m2".into(), "1e-12".into()));
        old.meta
            .push(("cache_single_scattering_albedo".into(), "1".into()));
        old.write(&file).unwrap();
        assert!(read_entry(&file, &key).is_err());
        let (o, how) =
            layer_optics(std::slice::from_ref(&comp), 532e-9, &opts, Some(dir.path())).unwrap();
        assert_eq!(how, CacheUse::Computed);
        assert_eq!(o.matrix.theta_deg.len(), 37);
        assert!(read_entry(&file, &key).is_ok(), "replaced by the new entry");
    }

    fn small_component(m: f64) -> Component {
        Component {
            name: "p".into(),
            distribution: SizeDistribution::lognormal(1.0, 0.2, 1.5).unwrap(),
            refractive_index: Complex64::new(m, 1e-3),
        }
    }

    fn coarse_angles() -> BulkOptions {
        BulkOptions {
            angles_deg: Some((0..=36).map(|i| 5.0 * i as f64).collect()),
            ..Default::default()
        }
    }

    /// A second lookup (another process: no memory cache) reads the entry the first wrote and
    /// gives the same numbers bit for bit; the write leaves no temporary file behind.
    #[test]
    fn second_lookup_reads_the_entry_bit_for_bit() {
        let dir = tempfile::tempdir().unwrap();
        let comps = [small_component(1.45)];
        let opts = coarse_angles();
        let (a, how) = lookup(&comps, 532e-9, &opts, Some(dir.path()), false).unwrap();
        assert_eq!(how, CacheUse::Computed);
        let (b, how) = lookup(&comps, 532e-9, &opts, Some(dir.path()), false).unwrap();
        assert_eq!(how, CacheUse::Disk);
        assert_eq!(
            a.extinction_cross_section_m2.to_bits(),
            b.extinction_cross_section_m2.to_bits()
        );
        assert_eq!(
            a.single_scattering_albedo.to_bits(),
            b.single_scattering_albedo.to_bits()
        );
        assert_eq!(a.matrix.theta_deg, b.matrix.theta_deg);
        assert_eq!(a.matrix.elements, b.matrix.elements);
        let names: Vec<String> = std::fs::read_dir(dir.path())
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        assert_eq!(
            names,
            [format!(
                "mie-{}.txt",
                fingerprint_hash(&comps, 532e-9, &opts)
            )]
        );
    }

    /// A damaged entry (truncated mid-file, garbage, bulk numbers removed) is not trusted: it
    /// is recomputed, to the same numbers, and replaced by a whole entry.
    #[test]
    fn damaged_entries_are_recomputed_and_replaced() {
        let dir = tempfile::tempdir().unwrap();
        let comps = [small_component(1.5)];
        let opts = coarse_angles();
        let (want, _) = lookup(&comps, 1064e-9, &opts, Some(dir.path()), false).unwrap();
        let file = entry_path(dir.path(), &comps, 1064e-9, &opts);
        let whole = std::fs::read_to_string(&file).unwrap();
        let damaged: [Vec<u8>; 4] = [
            whole.as_bytes()[..whole.len() / 2].to_vec(),
            b"not a table\n".to_vec(),
            whole
                .lines()
                .filter(|l| !l.contains("cache_extinction"))
                .map(|l| format!("{l}\n"))
                .collect::<String>()
                .into_bytes(),
            Vec::new(),
        ];
        for text in damaged {
            std::fs::write(&file, &text).unwrap();
            assert!(read_entry(&file, &fingerprint(&comps, 1064e-9, &opts)).is_err());
            let (got, how) = lookup(&comps, 1064e-9, &opts, Some(dir.path()), false).unwrap();
            assert_eq!(how, CacheUse::Computed);
            assert_eq!(*got, *want);
            assert_eq!(std::fs::read_to_string(&file).unwrap(), whole);
        }
    }

    /// The key changes with every input that changes the result, and names the version of
    /// the Mie computation.
    #[test]
    fn the_key_changes_with_every_input() {
        let base = small_component(1.45);
        let opts = coarse_angles();
        let key = |c: &Component, wl: f64, o: &BulkOptions| {
            fingerprint_hash(std::slice::from_ref(c), wl, o)
        };
        let k0 = key(&base, 532e-9, &opts);
        assert!(
            fingerprint(std::slice::from_ref(&base), 532e-9, &opts)
                .starts_with(crate::particles::distribution::MIE_VERSION)
        );
        let mut others = vec![key(&base, 532.001e-9, &opts)];
        let mut c = base.clone();
        c.refractive_index.re = 1.4500001;
        others.push(key(&c, 532e-9, &opts));
        let mut c = base.clone();
        c.refractive_index.im = 1.1e-3;
        others.push(key(&c, 532e-9, &opts));
        let mut c = base.clone();
        c.distribution = SizeDistribution::lognormal(1.0, 0.2, 1.51).unwrap();
        others.push(key(&c, 532e-9, &opts));
        let mut c = base.clone();
        c.distribution = c.distribution.truncated(0.01, 5.0).unwrap();
        others.push(key(&c, 532e-9, &opts));
        for o in [
            BulkOptions {
                tail_fraction: 2e-5,
                ..opts.clone()
            },
            BulkOptions {
                rel_tol: 5e-4,
                ..opts.clone()
            },
            BulkOptions {
                min_step_x: 2e-3,
                ..opts.clone()
            },
            BulkOptions {
                max_points: 1 << 19,
                ..opts.clone()
            },
            BulkOptions {
                angles_deg: None,
                ..opts.clone()
            },
            BulkOptions {
                angles_deg: Some(vec![0.0, 90.0, 180.0]),
                ..opts.clone()
            },
        ] {
            others.push(key(&base, 532e-9, &o));
        }
        let mut all = others.clone();
        all.push(k0.clone());
        all.sort();
        all.dedup();
        assert_eq!(all.len(), others.len() + 1, "{others:?}");
        // Two mixtures with the same components in another order are other inputs.
        let two = [base.clone(), small_component(1.6)];
        let owt = [small_component(1.6), base.clone()];
        assert_ne!(
            fingerprint_hash(&two, 532e-9, &opts),
            fingerprint_hash(&owt, 532e-9, &opts)
        );
    }

    /// The default directory: LIDARSIM_CACHE_DIR (off or empty: none), else XDG_CACHE_HOME
    /// (when absolute), else ~/.cache, else LOCALAPPDATA.
    #[test]
    fn the_default_directory_follows_xdg() {
        let with = |vars: &[(&str, &str)]| {
            let vars: Vec<(String, String)> = vars
                .iter()
                .map(|(k, v)| (k.to_string(), v.to_string()))
                .collect();
            cache_dir_from(&move |k| {
                vars.iter()
                    .find(|(n, _)| n == k)
                    .map(|(_, v)| std::ffi::OsString::from(v))
            })
        };
        let p = |s: &str| Some(PathBuf::from(s));
        let home = ("HOME", "/home/u");
        assert_eq!(with(&[home]), p("/home/u/.cache/lidarsim"));
        assert_eq!(
            with(&[home, ("XDG_CACHE_HOME", "/xdg")]),
            p("/xdg/lidarsim")
        );
        assert_eq!(
            with(&[home, ("XDG_CACHE_HOME", "relative")]),
            p("/home/u/.cache/lidarsim")
        );
        assert_eq!(
            with(&[
                home,
                ("XDG_CACHE_HOME", "/xdg"),
                (CACHE_DIR_ENV, "/scratch/mie")
            ]),
            p("/scratch/mie")
        );
        assert_eq!(with(&[home, (CACHE_DIR_ENV, "off")]), None);
        assert_eq!(with(&[home, (CACHE_DIR_ENV, "")]), None);
        assert_eq!(
            with(&[("LOCALAPPDATA", "/c/appdata")]),
            p("/c/appdata/lidarsim")
        );
        assert_eq!(with(&[]), None);
        // Not in the library's own unit tests.
        assert_eq!(default_cache_dir(), None);
    }
}
