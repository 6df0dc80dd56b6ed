//! Shared test helpers: the one copy of what more than one test module needs. Paths (the
//! project root, tests-only data under `../shared`, scene text with absolute paths, command-line
//! arguments), running the binary (plain, requiring success, bounded in memory and time), reading
//! CSV files, checking written outputs (CSV, JSON, NetCDF: finite, non-negative where they must
//! be, nothing half-written), and rebuilding shard files (header, FNV-1a checksum).
#![allow(dead_code)]

use std::path::{Path, PathBuf};

/// The project root (where Cargo.toml is).
pub fn project_root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// A file under `../shared` (or under `$LIDARSIM_SHARED` when set), or `None` after printing one
/// line naming the missing file: tests that need "tests only" data skip when it is absent.
pub fn shared_file(relative: &str) -> Option<PathBuf> {
    let base = std::env::var_os("LIDARSIM_SHARED")
        .map(PathBuf::from)
        .unwrap_or_else(|| project_root().join("../shared"));
    let p = base.join(relative);
    if p.is_file() {
        Some(p)
    } else {
        println!("skipped: {} is absent", p.display());
        None
    }
}

/// The records of a HITRAN `.par` file whose line position (columns 4–15) lies in
/// [`lo_cm1`, `hi_cm1`), each with its newline: a small line file for a test scene.
pub fn par_records_in(path: &Path, lo_cm1: f64, hi_cm1: f64) -> String {
    std::fs::read_to_string(path)
        .unwrap()
        .lines()
        .filter(|l| {
            l.get(3..15)
                .and_then(|nu| nu.trim().parse::<f64>().ok())
                .is_some_and(|nu| (lo_cm1..hi_cm1).contains(&nu))
        })
        .map(|l| format!("{l}\n"))
        .collect()
}

/// Path of the lidarsim binary built for these tests. Run it through [`lidarsim_command`] (or
/// give the command [`NO_MIE_CACHE`] yourself), so that it does not write into the user's cache.
pub fn lidarsim_bin() -> &'static Path {
    Path::new(env!("CARGO_BIN_EXE_lidarsim"))
}

/// The environment that turns the Mie disk cache off (`LIDARSIM_CACHE_DIR=off`): every process
/// the tests start that may run lidarsim's Mie theory gets it, so no test writes into the user's
/// cache directory. The test of the cache itself
/// (`particles::mie_cache_is_on_by_default_in_the_user_cache_directory`) sets its own.
pub const NO_MIE_CACHE: (&str, &str) = (lidarsim::particles::cache::CACHE_DIR_ENV, "off");

/// A `lidarsim` command with the Mie disk cache off ([`NO_MIE_CACHE`]).
pub fn lidarsim_command() -> Command {
    let mut c = Command::new(lidarsim_bin());
    c.env(NO_MIE_CACHE.0, NO_MIE_CACHE.1);
    c
}

/// The scene override that turns the Mie disk cache off for a scene resolved in this process
/// (`simulation.cache_dir = "off"`: the scene's own setting wins over the environment, see
/// `Scene::read_with`), for in-process tests that run Mie theory.
pub fn no_mie_cache() -> Vec<lidarsim::scene::SceneOverride> {
    vec![lidarsim::scene::SceneOverride {
        key: "simulation.cache_dir".into(),
        value: "\"off\"".into(),
    }]
}

/// [`lidarsim::scene::Scene::from_toml`] with the Mie disk cache off ([`no_mie_cache`]).
pub fn scene_from_toml(
    path: &Path,
    text: &str,
) -> Result<lidarsim::scene::Scene, lidarsim::input::InputError> {
    lidarsim::scene::Scene::from_toml_with(
        path,
        text,
        path.parent().unwrap_or(Path::new(".")),
        &no_mie_cache(),
    )
}

/// [`lidarsim::scene::Scene::read`] with the Mie disk cache off ([`no_mie_cache`]).
pub fn scene_read(path: &Path) -> Result<lidarsim::scene::Scene, lidarsim::input::InputError> {
    lidarsim::scene::Scene::read_with(path, &no_mie_cache())
}

/// Run `lidarsim` with arguments (the Mie disk cache off) and return its output.
pub fn lidarsim<I, S>(args: I) -> std::process::Output
where
    I: IntoIterator<Item = S>,
    S: AsRef<std::ffi::OsStr>,
{
    lidarsim_command()
        .args(args)
        .output()
        .expect("lidarsim runs")
}

/// Run `lidarsim`, require success (showing its stderr otherwise) and return its stdout.
pub fn lidarsim_ok<I, S>(args: I) -> String
where
    I: IntoIterator<Item = S>,
    S: AsRef<std::ffi::OsStr>,
{
    let out = lidarsim(args);
    assert!(
        out.status.success(),
        "lidarsim failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

// ---------------------------------------------------------------------------------------------
// Bounded runs of the binary and checks of what it wrote (the fuzz tests, tests/roundtrip.rs).

use std::ffi::OsString;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// Address space of a bounded run: a case that makes lidarsim allocate more is a failure (a
/// problem size the validation should have refused), and the machine stays usable.
pub const MEMORY_LIMIT_KIB: u64 = 4 << 20;

/// How a bounded run of the binary ended.
pub struct Bounded {
    /// The exit code (`None`: ended by a signal).
    pub code: Option<i32>,
    /// The exit status as text, for messages.
    pub status: String,
    /// What it printed.
    pub stdout: String,
    /// What it printed on stderr.
    pub stderr: String,
    /// Its wall time.
    pub took: Duration,
}

/// Run `lidarsim args` in `cwd` with its address space limited to [`MEMORY_LIMIT_KIB`] (by the
/// shell's `ulimit -v`, where there is a `/bin/sh`) and stdin closed, its stdout and stderr
/// written to `logs/stdout` and `logs/stderr`; killed after `limit`, which is an `Err`.
pub fn lidarsim_bounded(
    args: &[OsString],
    cwd: &Path,
    logs: &Path,
    limit: Duration,
) -> Result<Bounded, String> {
    let log = |name: &str| std::fs::File::create(logs.join(name)).map(Stdio::from);
    let mut cmd = if cfg!(unix) && Path::new("/bin/sh").exists() {
        let mut c = Command::new("/bin/sh");
        c.env(NO_MIE_CACHE.0, NO_MIE_CACHE.1)
            .arg("-c")
            .arg(format!(
                "ulimit -v {MEMORY_LIMIT_KIB} && exec \"$0\" \"$@\""
            ))
            .arg(lidarsim_bin());
        c
    } else {
        lidarsim_command()
    };
    cmd.args(args)
        .current_dir(cwd)
        .stdin(Stdio::null())
        .stdout(log("stdout").map_err(|e| e.to_string())?)
        .stderr(log("stderr").map_err(|e| e.to_string())?);
    let started = Instant::now();
    let mut child = cmd
        .spawn()
        .map_err(|e| format!("cannot start lidarsim: {e}"))?;
    let status = loop {
        if let Some(s) = child.try_wait().map_err(|e| e.to_string())? {
            break s;
        }
        if started.elapsed() > limit {
            let _ = child.kill();
            let _ = child.wait();
            return Err(format!("no end after {limit:?} (killed)"));
        }
        std::thread::sleep(Duration::from_millis(5));
    };
    let took = started.elapsed();
    let read = |name: &str| {
        std::fs::read(logs.join(name))
            .map(|b| String::from_utf8_lossy(&b).into_owned())
            .unwrap_or_default()
    };
    Ok(Bounded {
        code: status.code(),
        status: status.to_string(),
        stdout: read("stdout"),
        stderr: read("stderr"),
        took,
    })
}

/// Every file and directory under `dir` (recursively), as paths relative to it, sorted.
pub fn tree(dir: &Path) -> Vec<PathBuf> {
    fn walk(base: &Path, at: &Path, out: &mut Vec<PathBuf>) {
        let Ok(rd) = std::fs::read_dir(at) else {
            return;
        };
        for e in rd.flatten() {
            let p = e.path();
            out.push(p.strip_prefix(base).unwrap_or(&p).to_path_buf());
            if p.is_dir() {
                walk(base, &p, out);
            }
        }
    }
    let mut out = Vec::new();
    walk(dir, dir, &mut out);
    out.sort();
    out
}

/// Columns of lidarsim's CSV outputs that hold text (names, labels, reasons): any other
/// field must be empty (a value that cannot be computed, as the contracts say) or a number.
pub const TEXT_COLUMNS: [&str; 22] = [
    "source",
    "channel",
    "order",
    "method",
    "channel_pair",
    "quantity",
    "unit",
    "polarisation",
    "profile",
    "profile_id",
    "id",
    "class",
    "pair",
    "atmosphere",
    "line",
    "reason",
    "time_utc",
    "basis",
    "element",
    "component",
    "name",
    "kind",
];

/// Columns that are energies, counts, standard deviations, cross-sections or optical depths:
/// never negative.
pub const NON_NEGATIVE_COLUMNS: [&str; 20] = [
    "energy_j",
    "stderr_j",
    "attenuated_backscatter_per_m_sr",
    "attenuated_backscatter_stderr_per_m_sr",
    "range_corrected_signal_j_m2",
    "range_corrected_signal_stderr_j_m2",
    "lidar_constant_j_m2",
    "signal_photoelectrons",
    "background_photoelectrons",
    "dark_electrons",
    "noise_std_photoelectrons",
    "mc_stderr",
    "random_error_per_shot_pair",
    "random_error_averaged",
    "simulated_error_per_shot_pair",
    "simulated_error_averaged",
    "tau_vertical",
    "tau_slant",
    "sd_ppm",
    "random_error_rms_ppm",
];

/// A number field's text that is not finite as lidarsim (Rust) or another program prints it.
pub fn non_finite_text(field: &str) -> bool {
    let f = field.trim().to_ascii_lowercase();
    let f = f.trim_start_matches(['+', '-']);
    f == "nan" || f == "inf" || f == "infinity" || f.parse::<f64>().is_ok_and(|v| !v.is_finite())
}

/// A CSV text as lidarsim writes it (`#` comment lines, a header, RFC 4180 quoting) parses,
/// and every field that is not text is empty or a finite number, non-negative in the columns
/// of [`NON_NEGATIVE_COLUMNS`] and in cross-section columns (`sigma_*`). Returns the rows.
pub fn check_csv_text(name: &str, text: &str) -> Result<usize, String> {
    let mut r = csv::ReaderBuilder::new()
        .comment(Some(b'#'))
        .flexible(false)
        .from_reader(text.as_bytes());
    let header: Vec<String> = r
        .headers()
        .map_err(|e| format!("{name}: {e}"))?
        .iter()
        .map(str::to_string)
        .collect();
    let mut rows = 0;
    for (n, rec) in r.records().enumerate() {
        let rec = rec.map_err(|e| format!("{name} record {}: {e}", n + 1))?;
        rows += 1;
        for (col, field) in header.iter().zip(rec.iter()) {
            if TEXT_COLUMNS.contains(&col.as_str()) || field.is_empty() {
                continue;
            }
            if non_finite_text(field) {
                return Err(format!("{name} record {}: `{col}` = {field}", n + 1));
            }
            // retrieval.csv's value columns carry their unit (`mc_stderr_ppm`, …).
            let bare = ["_ppm", "_molecules_per_m2", "_molecules_per_m3"]
                .iter()
                .find_map(|u| col.strip_suffix(u))
                .unwrap_or(col);
            let non_negative = NON_NEGATIVE_COLUMNS.contains(&col.as_str())
                || NON_NEGATIVE_COLUMNS.contains(&bare)
                || (col.starts_with("sigma_") && col.ends_with("_cm2"));
            if non_negative
                && let Ok(v) = field.trim().parse::<f64>()
                && v < 0.0
            {
                return Err(format!(
                    "{name} record {}: `{col}` = {field} is negative",
                    n + 1
                ));
            }
        }
    }
    Ok(rows)
}

/// A JSON text parses and holds no `null` (serde_json writes NaN and ±inf as null), but where
/// a contract says a value may be missing: `run`'s summary.json leaves the Monte Carlo
/// retrieval entries that retrieval.csv leaves empty as null (README, retrieval.csv).
pub fn check_json_text(name: &str, text: &str) -> Result<(), String> {
    check_json_text_allowing(name, text, &[])
}

/// [`check_json_text`], with `null` allowed at the paths `allowed` (`.key.key`), where it
/// means "not written" rather than a number.
pub fn check_json_text_allowing(name: &str, text: &str, allowed: &[&str]) -> Result<(), String> {
    fn find_null(v: &serde_json::Value, at: &str, allowed: &[&str]) -> Option<String> {
        match v {
            serde_json::Value::Null if allowed.contains(&at) => None,
            serde_json::Value::Null => Some(at.to_string()),
            serde_json::Value::Object(o)
                if at.starts_with(".retrieval.") && o.get("source") == Some(&"mc".into()) =>
            {
                None
            }
            serde_json::Value::Array(a) => a
                .iter()
                .enumerate()
                .find_map(|(i, x)| find_null(x, &format!("{at}[{i}]"), allowed)),
            serde_json::Value::Object(o) => o
                .iter()
                .find_map(|(k, x)| find_null(x, &format!("{at}.{k}"), allowed)),
            _ => None,
        }
    }
    let v: serde_json::Value = serde_json::from_str(text).map_err(|e| format!("{name}: {e}"))?;
    match find_null(&v, "", allowed) {
        Some(at) => Err(format!("{name}: `{at}` is null (a NaN or an infinity)")),
        None => Ok(()),
    }
}

/// Every floating-point value of every variable of a NetCDF file is finite (a missing value
/// is the `_FillValue`, 9.969e36).
pub fn check_netcdf(path: &Path) -> Result<(), String> {
    let name = path.display();
    let mut r = netcdf3::FileReader::open(path).map_err(|e| format!("{name}: {e:?}"))?;
    let vars = r.read_all_vars().map_err(|e| format!("{name}: {e:?}"))?;
    let mut names: Vec<&String> = vars.keys().collect();
    names.sort();
    for v in names {
        let bad = match &vars[v] {
            netcdf3::DataVector::F64(x) => x.iter().position(|x| !x.is_finite()),
            netcdf3::DataVector::F32(x) => x.iter().position(|x| !x.is_finite()),
            _ => None,
        };
        if let Some(i) = bad {
            return Err(format!("{name}: variable `{v}`[{i}] is not finite"));
        }
    }
    Ok(())
}

/// Every file under `dir`: no staging directory or temporary file left; each CSV, JSON and
/// NetCDF file checked as above. Returns the files checked.
pub fn check_written(dir: &Path) -> Result<Vec<PathBuf>, String> {
    let mut checked = Vec::new();
    for rel in tree(dir) {
        let p = dir.join(&rel);
        let file = rel
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        if file.starts_with(".lidarsim-staging") || file.ends_with(".tmp") {
            return Err(format!(
                "left a staging or temporary entry `{}`",
                rel.display()
            ));
        }
        if !p.is_file() {
            continue;
        }
        let shown = rel.display().to_string();
        let text = || {
            std::fs::read(&p)
                .map(|b| String::from_utf8_lossy(&b).into_owned())
                .map_err(|e| format!("{shown}: {e}"))
        };
        if file.ends_with(".csv") {
            check_csv_text(&shown, &text()?)?;
        } else if file.ends_with(".json") {
            check_json_text(&shown, &text()?)?;
        } else if file.ends_with(".nc") {
            check_netcdf(&p)?;
        }
        checked.push(rel);
    }
    Ok(checked)
}

/// The first word of `text` that is a non-finite number as printed (`NaN`, `inf`, `-inf`):
/// a summary on stdout shows what the files hold.
pub fn non_finite_word(text: &str) -> Option<String> {
    text.split(|c: char| c.is_whitespace() || ",;:()[]{}|=\"'".contains(c))
        .find(|w| !w.is_empty() && non_finite_text(w))
        .map(str::to_string)
}

/// A path as a command-line argument.
pub fn path_arg(p: &Path) -> String {
    p.to_string_lossy().into_owned()
}

/// A shipped scene's text (`scenes/…` or any file under the project root) with its relative
/// paths (`"../…"`: phase tables, line lists) made absolute, so that it can be written anywhere.
pub fn absolute_paths(scene_text: &str) -> String {
    scene_text.replace("\"../", &format!("\"{}/", project_root().display()))
}

/// The names of the entries of `dir` (not recursive), sorted.
pub fn file_names(dir: &Path) -> Vec<String> {
    let mut names: Vec<String> = std::fs::read_dir(dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    names
}

/// The records of a CSV file as lidarsim writes it (`#` comments, a header), by a standard
/// parser: (header, rows).
pub fn read_csv(path: &Path) -> (Vec<String>, Vec<Vec<String>>) {
    let mut r = csv::ReaderBuilder::new()
        .comment(Some(b'#'))
        .from_path(path)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let header = r.headers().unwrap().iter().map(String::from).collect();
    let rows = r
        .records()
        .map(|rec| rec.unwrap().iter().map(String::from).collect())
        .collect();
    (header, rows)
}

// ---------------------------------------------------------------------------------------------
// Shard files (README, "The shard file"), rebuilt by tests that damage them on purpose.

/// Bytes before a shard's header: magic, format, header length.
pub const SHARD_PREAMBLE: usize = 28;

/// FNV-1a 64, the shard checksum, written here from its definition (an independent copy).
pub fn fnv1a_64(bytes: &[u8]) -> u64 {
    bytes.iter().fold(0xcbf2_9ce4_8422_2325, |h, b| {
        (h ^ u64::from(*b)).wrapping_mul(0x0000_0100_0000_01b3)
    })
}

/// A shard file with its checksum (the last 8 bytes) made right again.
pub fn with_checksum(mut bytes: Vec<u8>) -> Vec<u8> {
    if bytes.len() >= 8 {
        let n = bytes.len() - 8;
        let sum = fnv1a_64(&bytes[..n]);
        bytes[n..].copy_from_slice(&sum.to_le_bytes());
    }
    bytes
}

/// The header of a shard file and where its body starts.
pub fn shard_header(bytes: &[u8]) -> Option<(serde_json::Value, usize)> {
    let len = u64::from_le_bytes(bytes.get(20..SHARD_PREAMBLE)?.try_into().ok()?) as usize;
    let json = bytes.get(SHARD_PREAMBLE..SHARD_PREAMBLE.checked_add(len)?)?;
    Some((serde_json::from_slice(json).ok()?, SHARD_PREAMBLE + len))
}

/// The shard with its header replaced by `h` and the checksum right (unchanged if it has no
/// readable header).
pub fn with_shard_header(bytes: &[u8], h: &serde_json::Value) -> Vec<u8> {
    let Some((_, body)) = shard_header(bytes) else {
        return bytes.to_vec();
    };
    let json = serde_json::to_vec(h).unwrap_or_default();
    let mut out = bytes[..20].to_vec();
    out.extend((json.len() as u64).to_le_bytes());
    out.extend(&json);
    out.extend(&bytes[body..]);
    with_checksum(out)
}

/// No CSV or NetCDF file under `dir` (recursively) holds `NaN` or `inf`. Every
/// field of every `*.csv` (parsed by the `csv` crate, `#` lines as comments) and every value of
/// every variable and attribute of every `*.nc` (read by the `netcdf3` crate) is checked.
/// Returns the files checked.
pub fn assert_no_non_finite(dir: &Path) -> Vec<PathBuf> {
    let mut checked = Vec::new();
    for p in tree(dir).into_iter().map(|rel| dir.join(rel)) {
        let ext = p.extension().and_then(|e| e.to_str()).unwrap_or("");
        if ext == "csv" {
            let mut r = csv::ReaderBuilder::new()
                .has_headers(false)
                .flexible(true)
                .comment(Some(b'#'))
                .from_path(&p)
                .unwrap();
            for (line, rec) in r.records().enumerate() {
                let rec = rec.unwrap();
                for field in rec.iter() {
                    assert!(
                        !non_finite_text(field),
                        "{} record {}: `{field}` in {rec:?}",
                        p.display(),
                        line + 1
                    );
                }
            }
            checked.push(p);
        } else if ext == "nc" {
            let mut r = netcdf3::FileReader::open(&p).unwrap();
            for (name, values) in r.read_all_vars().unwrap() {
                if let Some(v) = values.get_f64() {
                    assert!(
                        v.iter().all(|x| x.is_finite()),
                        "{}: variable {name} holds a non-finite value",
                        p.display()
                    );
                }
            }
            let (ds, _) = r.close();
            for a in ds.get_global_attrs() {
                if let Some(v) = a.get_f64() {
                    assert!(v.iter().all(|x| x.is_finite()), "{}", p.display());
                }
            }
            for var in ds.get_vars() {
                for a in var.get_attrs() {
                    if let Some(v) = a.get_f64() {
                        assert!(
                            v.iter().all(|x| x.is_finite()),
                            "{}: {}:{}",
                            p.display(),
                            var.name(),
                            a.name()
                        );
                    }
                }
            }
            checked.push(p);
        }
    }
    checked
}
